"""Outputs never destroy what clothsim did not write, every failure to write is one error line,
scene paths mean what they say, and GIF output streams.

Most cases run the real command line in a subprocess against real folders holding real files,
and compare those folders byte for byte afterwards.
"""

from __future__ import annotations

import errno
import os
import shutil
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO, SCENES, after_ctrl_c, ctrl_c_as_on_a_terminal, error_line, run_cli

FAST = ("--frames", "2", "--every", "1", "--size", "64x64")


# -- helpers -------------------------------------------------------------------------------------
def snapshot(folder: Path) -> dict[str, object]:
    """Every entry below ``folder``: file bytes, folder marker, permissions; hidden ones included."""
    tree: dict[str, object] = {}
    for path in sorted(folder.rglob("*")):
        rel = str(path.relative_to(folder))
        mode = stat.S_IMODE(path.lstat().st_mode)
        tree[rel] = ("dir", mode) if path.is_dir() else (path.read_bytes(), mode)
    return tree


def user_folder(folder: Path) -> Path:
    """A folder as a user leaves it: a file, a sub-folder with a file, a hidden file."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "keep.txt").write_bytes(b"do not lose me\n")
    (folder / "sub").mkdir()
    (folder / "sub" / "inner.txt").write_bytes(b"nested\x00bytes")
    (folder / ".hidden").write_bytes(b"")
    return folder



@pytest.fixture(scope="module")
def egl():
    pytest.importorskip("moderngl")
    from clothsim.errors import ClothsimError
    from clothsim.render.context import create_context

    try:
        create_context().release()
    except ClothsimError as exc:
        pytest.skip(f"no EGL here, so nothing can be rendered: {exc}")


@pytest.fixture
def full_disk(tmp_path):
    """A 64 KiB tmpfs with 4 KiB left, holding a user's keep.txt; skipped where mounting is not allowed."""
    if not sys.platform.startswith("linux") or os.geteuid() != 0 or not shutil.which("mount"):
        pytest.skip("a small tmpfs needs Linux and root; the in-process ENOSPC test covers the path")
    mount = tmp_path / "full"
    mount.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        (mount / "keep.txt").write_bytes(b"do not lose me\n")
        (mount / "filler").write_bytes(b"\x01" * (60 * 1024 - 4096))
        yield mount
    finally:
        if subprocess.run(["umount", str(mount)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(mount)], capture_output=True)


# -- a frames folder is written only when it holds nothing but earlier frames ---------------------
def test_dot_in_a_users_folder_deletes_nothing(tmp_path):
    folder = user_folder(tmp_path / "work")
    before = snapshot(folder)
    r = run_cli("render", "pinned2", *FAST, "-o", ".", cwd=folder)
    assert error_line(r) == ("clothsim: error: .: folder is not empty (3 files not written by clothsim); "
                             "choose another or empty it")
    assert snapshot(folder) == before


def test_dot_dot_follows_the_same_rule(tmp_path):
    folder = user_folder(tmp_path / "work")
    before = snapshot(folder)
    r = run_cli("render", "pinned2", *FAST, "-o", "..", cwd=folder / "sub")
    assert error_line(r) == ("clothsim: error: ..: folder is not empty (3 files not written by clothsim); "
                             "choose another or empty it")
    assert snapshot(folder) == before


def test_named_folder_with_a_users_files_is_refused(tmp_path):
    out2 = tmp_path / "out2"
    out2.mkdir()
    (out2 / "mine.txt").write_bytes(b"mine\n")
    (out2 / "notes").mkdir()
    (out2 / "frame_00000.png.bak").write_bytes(b"a backup that looks like a frame")
    (out2 / "frame_00001.png").write_bytes(b"an earlier frame")  # ours, but the folder is still refused
    before = snapshot(tmp_path)
    for spelling in ("out2", "out2/"):
        r = run_cli("render", "pinned2", *FAST, "-o", spelling, cwd=tmp_path)
        assert error_line(r) == ("clothsim: error: out2: folder is not empty (3 files not written by clothsim); "
                                 "choose another or empty it")
        assert snapshot(tmp_path) == before


@pytest.mark.parametrize("name", ["frame_0001.png", "frame_00001.PNG", "frame_000001.png", "frame_-0001.png"])
def test_only_the_exact_frame_pattern_counts_as_ours(tmp_path, name):
    out = tmp_path / "frames"
    out.mkdir()
    (out / name).write_bytes(b"user data")
    before = snapshot(tmp_path)
    r = run_cli("render", "pinned2", *FAST, "-o", str(out))
    assert error_line(r).endswith(": folder is not empty (1 file not written by clothsim); choose another or empty it")
    assert snapshot(tmp_path) == before


def test_folder_check_comes_before_any_work(tmp_path):
    # The scene is loaded (and simulated) only after the output passed: a bad scene is not reached.
    folder = user_folder(tmp_path / "work")
    r = run_cli("render", str(tmp_path / "no-such-scene.json"), *FAST, "-o", str(folder))
    assert "folder is not empty" in error_line(r)


def test_earlier_frames_are_replaced_and_stale_ones_removed(tmp_path, egl):
    out = tmp_path / "frames"
    out.mkdir()
    for i in range(5):
        (out / f"frame_{i:05d}.png").write_bytes(b"old frame %d" % i)
    (tmp_path / "beside.txt").write_bytes(b"next to the folder")
    r = run_cli("render", "pinned2", *FAST, "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    for p in out.iterdir():
        assert p.read_bytes().startswith(b"\x89PNG")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["beside.txt", "frames"]
    assert (tmp_path / "beside.txt").read_bytes() == b"next to the folder"


def test_empty_existing_folder_and_new_folder(tmp_path, egl):
    (tmp_path / "empty").mkdir()
    for out in ("empty", "new/deeper/"):
        r = run_cli("render", "pinned2", *FAST, "-o", out, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        assert sorted(p.name for p in (tmp_path / out).iterdir()) == [f"frame_0000{i}.png" for i in range(3)]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty", "new"]


# -- a file output replaces a regular file, atomically, and nothing else --------------------------
def test_existing_file_is_replaced_by_rename_keeping_its_permissions(tmp_path, egl):
    out = tmp_path / "cloth.png"
    out.write_bytes(b"old picture")
    out.chmod(0o640)
    inode = out.stat().st_ino
    r = run_cli("render", "pinned2", *FAST, "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert out.read_bytes().startswith(b"\x89PNG")
    assert out.stat().st_ino != inode  # a new file renamed over the old one, not the old one rewritten
    assert stat.S_IMODE(out.stat().st_mode) == 0o640
    assert [p.name for p in tmp_path.iterdir()] == ["cloth.png"]


def test_a_folder_named_like_a_file_is_never_replaced(tmp_path):
    user_folder(tmp_path / "x.png")
    (tmp_path / "d.npz").mkdir()
    before = snapshot(tmp_path)
    r = run_cli("render", "pinned2", *FAST, "-o", "x.png", cwd=tmp_path)
    assert error_line(r) == ("clothsim: error: x.png: is a folder, not a file; choose a file name "
                             "(or write x.png/ for numbered PNGs in that folder)")
    r = run_cli("simulate", "pinned2", "--frames", "1", "--out", "d.npz", cwd=tmp_path)
    assert error_line(r) == "clothsim: error: d.npz: is a folder, not a file; choose a file name"
    assert snapshot(tmp_path) == before


# -- outputs the system will not let us write ------------------------------------------------------
@pytest.mark.parametrize("args, line", [
    (("render", "pinned2", *FAST, "-o", "/proc/x.png"),
     "clothsim: error: /proc/x.png: cannot write in /proc: No such file or directory"),
    (("simulate", "pinned2", "--frames", "1", "--out", "/proc/s.npz"),
     "clothsim: error: /proc/s.npz: cannot write in /proc: No such file or directory"),
    (("render", "pinned2", *FAST, "-o", "/proc/frames/"),
     "clothsim: error: /proc/frames: cannot write in /proc: No such file or directory"),
])
def test_unwritable_places_give_one_line(args, line):
    if not os.path.isdir("/proc/self"):
        pytest.skip("needs a Linux /proc")
    assert error_line(run_cli(*args)) == line


def test_path_below_a_regular_file(tmp_path):
    (tmp_path / "afile").write_bytes(b"a regular file")
    before = snapshot(tmp_path)
    cases = [(("render", "pinned2", *FAST, "-o", "afile/x.png"), "afile/x.png: afile is a file, not a folder"),
             (("render", "pinned2", *FAST, "-o", "afile/deeper/x.gif"),
              "afile/deeper/x.gif: afile is a file, not a folder"),
             (("render", "pinned2", *FAST, "-o", "afile/frames/"), "afile/frames: afile is a file, not a folder"),
             (("simulate", "pinned2", "--frames", "1", "--out", "afile/s.npz"),
              "afile/s.npz: afile is a file, not a folder")]
    for args, line in cases:
        assert error_line(run_cli(*args, cwd=tmp_path)) == f"clothsim: error: {line}"
        assert snapshot(tmp_path) == before


def test_device_paths_are_refused_and_nothing_is_created_in_dev(tmp_path):
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    before = sorted(os.listdir("/dev"))
    assert error_line(run_cli("render", "pinned2", *FAST, "-o", "/dev/full")) == \
        "clothsim: error: /dev/full: exists and is not a folder (a frames folder needs a folder)"
    # A device under a file name (here through a link) is not a file to replace.
    link = tmp_path / "cloth.png"
    link.symlink_to("/dev/full")
    line = error_line(run_cli("render", "pinned2", *FAST, "-o", str(link)))
    assert line == f"clothsim: error: {link}: not a regular file (a device, pipe or socket is never replaced)"
    assert link.is_symlink() and [p.name for p in tmp_path.iterdir()] == ["cloth.png"]
    if os.stat("/dev").st_dev != os.stat("/").st_dev:
        assert error_line(run_cli("render", "pinned2", *FAST, "-o", "/dev/x.png")) == \
            "clothsim: error: /dev/x.png: will not write in /dev (a file system of device files)"
    assert sorted(os.listdir("/dev")) == before


def test_fifo_is_not_replaced(tmp_path):
    fifo = tmp_path / "pipe.gif"
    os.mkfifo(fifo)
    line = error_line(run_cli("render", "pinned2", *FAST, "-o", str(fifo)))
    assert line == f"clothsim: error: {fifo}: not a regular file (a device, pipe or socket is never replaced)"
    assert stat.S_ISFIFO(fifo.lstat().st_mode) and [p.name for p in tmp_path.iterdir()] == ["pipe.gif"]


@pytest.mark.parametrize("out", ["x.png", "x.gif", "x.mp4", "frames/", "s.npz"])
def test_full_disk_gives_one_line_and_leaves_nothing(full_disk, out, request):
    before = snapshot(full_disk)
    if not out.endswith(".npz"):
        request.getfixturevalue("egl")
    if out.endswith(".npz"):
        r = run_cli("simulate", "pinned2", "--frames", "1", "--out", str(full_disk / out))
    else:
        r = run_cli("render", "pinned2", "--frames", "6", "--every", "1", "--size", "256x256",
                    "-o", str(full_disk / out))
    line = error_line(r)
    assert line.startswith(f"clothsim: error: {full_disk / out.rstrip('/')}: "), line
    assert line.endswith("No space left on device"), line
    assert snapshot(full_disk) == before


def test_enospc_in_process_for_every_writer(tmp_path, monkeypatch):
    """The same path without a tmpfs: the writer's file system call fails with ENOSPC."""
    from clothsim import output
    from clothsim.errors import ClothsimError

    frame = np.zeros((16, 16, 3), np.uint8)
    user_folder(tmp_path)
    before = snapshot(tmp_path)

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(output, "write_png", full)
    for name in ("a.png", "frames/"):
        with pytest.raises(ClothsimError) as info:
            with output.open_output(tmp_path / name, 30.0) as sink:
                sink(frame)
        assert str(info.value) == f"{tmp_path / name.rstrip('/')}: cannot write: No space left on device"
        assert snapshot(tmp_path) == before
    monkeypatch.undo()

    class FullFile:
        def __init__(self, *args, **kwargs):
            pass

        def writelines(self, chunks):
            full()

        write = writelines

        def close(self):
            pass

    monkeypatch.setattr(output, "open", FullFile, raising=False)
    with pytest.raises(ClothsimError) as info:
        with output.open_output(tmp_path / "a.gif", 30.0) as sink:
            sink(frame)
            sink(frame + 1)
    assert str(info.value) == f"{tmp_path / 'a.gif'}: cannot write: No space left on device"
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("ctrl_c", ["raises", "ignored"])
@pytest.mark.parametrize("out", ["a.json", "frames/"])
def test_ctrl_c_while_an_output_is_moved_into_place_is_held_not_lost(tmp_path, monkeypatch, ctrl_c, out):
    """A Ctrl-C that arrives while a finished output is renamed into place lets the rename end
    and the output's lock go, then interrupts: it used to be dropped, and a sweep interrupted
    while it moved a file into its dataset ran on. Where Ctrl-C is ignored (a sweep's workers),
    it stays ignored."""
    import threading

    from clothsim import atomic

    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signal handlers are set from the main thread only")
    folder = out.endswith("/")
    name = "_commit_folder" if folder else "_commit_file"
    commit = getattr(atomic, name)

    def pressed_meanwhile(*args):
        os.kill(os.getpid(), signal.SIGINT)
        commit(*args)

    monkeypatch.setattr(atomic, name, pressed_meanwhile)
    dest = tmp_path / out.rstrip("/")
    handler = signal.default_int_handler if ctrl_c == "raises" else signal.SIG_IGN
    previous = signal.signal(signal.SIGINT, handler)

    def write() -> None:
        with atomic.atomic_output(dest, directory=folder) as tmp:
            (tmp / "frame_00000.png" if folder else tmp).write_text("new")

    try:
        if ctrl_c == "raises":
            with pytest.raises(KeyboardInterrupt):
                write()
        else:
            write()
        assert signal.getsignal(signal.SIGINT) is handler
    finally:
        signal.signal(signal.SIGINT, previous)
    assert (dest / "frame_00000.png" if folder else dest).read_text() == "new"
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == (
        ["frames", "frames/frame_00000.png"] if folder else ["a.json"])  # no temporary, no lock


def test_failing_ffmpeg_is_one_line(tmp_path, monkeypatch):
    import imageio_ffmpeg

    from clothsim import output
    from clothsim.errors import ClothsimError

    false = shutil.which("false")
    if false is None:
        pytest.skip("no false(1) to stand in for a failing ffmpeg")
    monkeypatch.setattr(imageio_ffmpeg, "get_ffmpeg_exe", lambda: false)
    with pytest.raises(ClothsimError) as info:
        with output.open_output(tmp_path / "v.mp4", 30.0) as sink:
            for _ in range(50):  # enough to fill the pipe once false(1) has gone
                sink(np.zeros((64, 64, 3), np.uint8))
    assert str(info.value) == f"{tmp_path / 'v.mp4'}: ffmpeg failed: exit status 1"
    assert list(tmp_path.iterdir()) == []


# -- Ctrl-C ----------------------------------------------------------------------------------------
def _interrupt_when(cwd: Path, out: str, started) -> subprocess.CompletedProcess:
    """Start a long render, wait until ``started(cwd)`` says it is writing, then Ctrl-C it.

    The signal goes to the whole process group, as a terminal's Ctrl-C does.
    """
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    env["PYTHONFAULTHANDLER"] = "1"  # a render that hangs instead of stopping shows where, on SIGABRT
    p = subprocess.Popen([sys.executable, "-m", "clothsim", "render", "pinned2", "--no-rest", "--frames", "1000000",
                          "--every", "1", "--size", "64x64", "-o", out], cwd=cwd, env=env, text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
                         preexec_fn=ctrl_c_as_on_a_terminal)
    try:
        deadline = time.monotonic() + 240
        while not started(cwd):
            assert p.poll() is None, p.communicate()
            assert time.monotonic() < deadline, "the render never started writing"
            time.sleep(0.05)
        time.sleep(0.3)
        os.killpg(p.pid, signal.SIGINT)
        stdout, stderr = after_ctrl_c(p, "render", 60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    return subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr)


def _temporaries(cwd: Path) -> list[Path]:
    return [p for p in cwd.rglob(".*") if p.name != ".hidden"]


def _no_process_writes(name: str) -> bool:
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            if name.encode() in cmdline.read_bytes():
                return False
        except OSError:
            pass
    return True


@pytest.mark.parametrize("out", ["a.gif", "a.mp4", "a.png"])
def test_ctrl_c_during_a_file_render(tmp_path, out, egl):
    user_folder(tmp_path)
    before = snapshot(tmp_path)
    seen: list[Path] = []

    def started(cwd):
        # GIF and MP4 grow as frames come; a PNG is written at the end, so its empty temporary will do.
        temps = [p for p in _temporaries(cwd) if p.is_file() and ".tmp" in p.name
                 and (p.stat().st_size > 0 or out.endswith(".png"))]
        seen.extend(temps)
        return bool(temps)

    r = _interrupt_when(tmp_path, out, started)
    assert r.returncode == 130, r.stderr
    assert r.stderr.splitlines() == ["clothsim: interrupted"]
    assert snapshot(tmp_path) == before
    if out.endswith(".mp4") and os.path.isdir("/proc/self"):
        assert _no_process_writes(seen[0].name), "ffmpeg outlived the interrupted render"


@pytest.mark.parametrize("existing", [False, True])
def test_ctrl_c_during_a_frames_folder_write(tmp_path, existing, egl):
    user_folder(tmp_path)
    if existing:
        (tmp_path / "frames").mkdir()
        for i in range(3):
            (tmp_path / "frames" / f"frame_{i:05d}.png").write_bytes(b"earlier render %d" % i)
    before = snapshot(tmp_path)

    def started(cwd):
        return any(p.is_dir() and any(p.glob("frame_*.png")) for p in _temporaries(cwd))

    r = _interrupt_when(tmp_path, "frames/", started)
    assert r.returncode == 130, r.stderr
    assert r.stderr.splitlines() == ["clothsim: interrupted"]
    assert snapshot(tmp_path) == before


# -- scene paths mean what they say ---------------------------------------------------------------
def test_a_missing_path_never_falls_back_to_a_bundled_scene(tmp_path):
    out = tmp_path / "s.npz"
    for scene in ("/nonexistent/dir/sphere.json", "sphere.json", "scenes/sphere.json", "nosuchscene"):
        line = error_line(run_cli("simulate", scene, "--frames", "1", "--out", str(out), cwd=tmp_path))
        assert line.startswith(f"clothsim: error: {scene}: no such scene file (bundled scenes: "), line
    from clothsim.scene import bundled_scene_names

    assert line.endswith("(bundled scenes: " + ", ".join(bundled_scene_names()) + ")")
    assert list(tmp_path.iterdir()) == []
    assert error_line(run_cli("simulate", "/nonexistent/dir/sphere.json", "--out", str(out))).endswith(
        "; the bundled scene is named without a path or .json: sphere")


def test_bare_names_and_real_paths_still_work(tmp_path):
    (tmp_path / "mine.json").write_bytes((SCENES / "pinned4.json").read_bytes())
    for scene, cwd in (("sphere", tmp_path), ("scenes/sphere.json", REPO), ("mine.json", tmp_path),
                       (str(tmp_path / "mine.json"), None)):
        r = run_cli("simulate", scene, "--frames", "1", "--out", str(tmp_path / "s.npz"), cwd=cwd)
        assert r.returncode == 0, (scene, r.stderr)


def test_a_scene_that_is_not_a_regular_file(tmp_path):
    if not os.path.exists("/dev/null"):
        pytest.skip("no /dev/null here")
    assert error_line(run_cli("simulate", "/dev/null", "--out", str(tmp_path / "s.npz"))) == \
        "clothsim: error: /dev/null: not a regular file"


# -- GIF output streams and looks as before --------------------------------------------------------
def _frames() -> list[np.ndarray]:
    """Gradients with a moving square, a repeated frame and a frame that changes a small patch."""
    h, w = 48, 64
    y, x = np.mgrid[0:h, 0:w]
    base = np.stack([x * 4, y * 5, (x + y) * 2], axis=-1).astype(np.uint8)
    frames = []
    for i in range(5):
        f = base.copy()
        f[10:20, 5 + 8 * i:15 + 8 * i] = (250, 30 + 40 * i, 20)
        frames.append(f)
    frames.insert(3, frames[2].copy())
    patched = frames[-1].copy()
    patched[40:44, 50:60] = (0, 0, 255)
    frames.append(patched)
    return frames


def _decode(path: Path) -> tuple[list[np.ndarray], list[int], object]:
    from PIL import Image

    shown, durations = [], []
    with Image.open(path) as im:
        loop = im.info.get("loop")
        for i in range(im.n_frames):
            im.seek(i)
            shown.append(np.asarray(im.convert("RGB")))
            durations.append(im.info.get("duration"))
    return shown, durations, loop


def test_gif_looks_as_pillows_own_writer_makes_it(tmp_path):
    from PIL import Image

    from clothsim import output

    frames = _frames()
    with output.open_output(tmp_path / "stream.gif", 30.0) as sink:
        for f in frames:
            sink(f)
    # What the previous writer did: every frame kept, then one save_all.
    quantised = [Image.fromarray(f, "RGB").quantize(colors=255, method=Image.Quantize.MEDIANCUT,
                                                    dither=Image.Dither.NONE) for f in frames]
    quantised[0].save(tmp_path / "pillow.gif", format="GIF", save_all=True, append_images=quantised[1:],
                      duration=30, loop=0, optimize=False, disposal=1)
    ours, theirs = _decode(tmp_path / "stream.gif"), _decode(tmp_path / "pillow.gif")
    assert len(ours[0]) == len(theirs[0]) == len(frames) - 1  # the repeated frame is merged into the one before
    for a, b in zip(ours[0], theirs[0]):
        np.testing.assert_array_equal(a, b)
    assert ours[1] == theirs[1] and ours[1][2] == 60
    assert ours[2] == theirs[2] == 0


def test_gif_is_written_while_frames_arrive(tmp_path):
    from clothsim import output

    sizes = []
    with output.open_output(tmp_path / "a.gif", 30.0) as sink:
        for i in range(8):
            f = np.full((32, 32, 3), 20 * i, np.uint8)
            sink(f)
            temps = [p for p in tmp_path.iterdir() if p.name.startswith(".a.")]
            assert len(temps) == 1
            sizes.append(temps[0].stat().st_size)
    # One frame waits for its final duration; every later frame has reached the file by then.
    assert all(b > a for a, b in zip(sizes[1:], sizes[2:])), sizes
    assert [p.name for p in tmp_path.iterdir()] == ["a.gif"]
