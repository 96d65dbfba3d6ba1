"""Outputs that appear whole or not at all, and never destroy what clothsim did not create.

A file output is written under a temporary name in the destination's own folder and renamed
onto the destination at the end (``os.replace``), so a reader sees either the old file or the
new one. Only a regular file is ever replaced: a folder, a device, a pipe or a socket at the
destination is an error, raised before any temporary file exists.

A frames folder (numbered ``frame_NNNNN.png`` files; another folder output, such as an OBJ
sequence, passes ``owned`` to name the files it writes) is written as follows:

* a folder that does not exist yet is built under a temporary name beside it and renamed
  into place at the end, so it appears complete or not at all;
* an existing folder is used only when it is empty or holds nothing but frame files of an
  earlier render. The new frames are written into a hidden temporary sub-folder of it (the
  same file system, so the final moves are renames that cannot run out of space; and nothing
  is created outside the folder the user named, which matters for ``-o .``). At the end each
  new frame is renamed onto its final name, replacing the old frame of that number, and only
  then are the old frames beyond the new count deleted. A reader never sees a half-written
  frame file; while those renames run it may see new frames next to old ones.

A folder output, and a file output whose writer asks for it (a USD stage: an export writes it
for as long as it simulates), is locked while it is written (:mod:`clothsim.locks`): a folder
that exists by ``.clothsim.lock`` inside it, anything else by a hidden lock file beside it. A
second writer stops with one line naming the holder before it writes anything. Once the lock
is held, temporary files and folders that a killed earlier writer of the same output left
behind are removed (no live writer can own them: it would hold the lock). Other file outputs
are not locked: two writers of one such file each write a temporary file, and the file ends as
the complete output of the last one (the lock file would also take the last block of a nearly
full disk, which such a writer may need).

A symbolic link at the destination is followed. Nothing is created on the file system mounted
at ``/dev``. A name longer than the file system allows is one error line, not a traceback.
Whatever fails, or is interrupted, the temporary file or folder is removed, and so are the
parent folders this module created for the output; what was there before is left as it was.
Ctrl-C is held off only for the final renames and that cleanup. Every ``OSError`` met on the
way becomes one :class:`ClothsimError` line naming the path.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import stat
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

from . import locks
from .errors import ClothsimError

_FRAME = re.compile(r"frame_(\d{5,})\.png")
# mkstemp/mkdtemp's random part: eight of these characters.
_RANDOM = "[a-z0-9_]{8}"
_FRAMES_TMP = re.compile(rf"\.clothsim-frames\.{_RANDOM}\.tmp")
_NAME_MAX = 255
_PATH_MAX = 4095
# Long destination names must still leave room for the temporary name's additions (NAME_MAX).
_STEM_MAX = 64


def frame_name(index: int) -> str:
    """The file name of frame ``index`` in a frames folder: ``frame_00012.png``."""
    return f"frame_{index:05d}.png"


def is_frame_name(name: str) -> bool:
    """True for exactly the names :func:`frame_name` produces."""
    m = _FRAME.fullmatch(name)
    return m is not None and name == frame_name(int(m[1]))


def os_error(label: str, exc: OSError, doing: str = "cannot write") -> ClothsimError:
    """A one-line ``LABEL: DOING: reason`` error for an ``OSError`` met while writing LABEL."""
    reason = " ".join((exc.strerror or str(exc) or type(exc).__name__).split())
    return ClothsimError(f"{label}: {doing}: {reason}" if doing else f"{label}: {reason}")


@contextlib.contextmanager
def os_errors(label: str, doing: str = "cannot write") -> Iterator[None]:
    """Re-raise an ``OSError`` from the block as a one-line :class:`ClothsimError` about LABEL."""
    try:
        yield
    except OSError as exc:
        raise os_error(label, exc, doing) from None


def check_name(path: str | os.PathLike[str], label: str | None = None) -> None:
    """Raise one line if a component of ``path`` is longer than a file name may be (255 bytes).

    The checks that follow (``is_dir``, ``stat``) would otherwise end in ``OSError: [Errno 36]``.
    """
    text = os.fspath(path)
    label = label if label is not None else text
    for part in text.split(os.sep):
        size = len(os.fsencode(part))
        if size > _NAME_MAX:
            raise ClothsimError(f"{_shortened(label)}: name too long ({size} bytes in one file or folder name; "
                                f"at most {_NAME_MAX})")
    if len(os.fsencode(text)) > _PATH_MAX:
        raise ClothsimError(f"{_shortened(label)}: path too long ({len(os.fsencode(text))} bytes; at most {_PATH_MAX})")


def _shortened(label: str) -> str:
    return label if len(label) <= 80 else f"{label[:40]}...{label[-20:]}"


def check_destination(dest: str | os.PathLike[str], *, directory: bool = False,
                      label: str | None = None, owned: Callable[[str], bool] = is_frame_name) -> None:
    """Fail fast: raise :class:`ClothsimError` if ``dest`` could not be written.

    Runs every check :func:`atomic_output` runs (what is at the destination, the frames-folder
    rule, parents that are files) and also proves that the nearest existing folder on the way
    to the destination is writable, by creating and removing an empty file there. Call it
    before any long computation whose result would go to ``dest``. ``owned`` is as for
    :func:`atomic_output`.
    """
    label = _label(Path(dest), label)
    dest, home = _inspect(Path(dest), directory, label, owned)
    locks.probe(_lock_file(dest, home), label)
    probe_in = _nearest_existing(home)
    with os_errors(label, f"cannot write in {probe_in}"):
        fd, probe = tempfile.mkstemp(prefix=".clothsim-", suffix=".probe", dir=probe_in)
        os.close(fd)
        os.unlink(probe)


@contextlib.contextmanager
def atomic_output(dest: str | os.PathLike[str], *, directory: bool = False, label: str | None = None,
                  block_writes: bool = True, owned: Callable[[str], bool] = is_frame_name,
                  lock: bool | None = None) -> Iterator[Path]:
    """Yield a temporary path for ``dest`` (a file, or a frames folder if ``directory``).

    If the block succeeds the temporary output is moved onto ``dest`` as the module docstring
    describes; if it raises (``KeyboardInterrupt`` included) it is removed and ``dest`` is left
    as it was. A file's temporary name keeps the destination's suffix, so that writers choosing
    a format by extension work. ``label`` is how errors name the destination (default: ``dest``).
    A symbolic link at ``dest`` is followed: the file or folder it points to is written.

    ``block_writes`` says the block does nothing but write the temporary output, so an
    ``OSError`` it raises is a write failure and is reported as one line; pass ``False`` when
    the block runs other work too and converts its own write errors.

    ``owned`` tells, for a folder output, the names of the files clothsim writes there (default:
    ``frame_NNNNN.png``): an existing folder holding anything else is refused, and such files
    left from an earlier run and not rewritten are deleted at the end.

    ``lock`` (default: for a folder output only) locks the output for the whole block: another
    writer holding it is one error line here, before anything is written. An output inside a
    folder this process has locked (a sweep's dataset) is covered by that lock.
    """
    wants_lock = directory if lock is None else lock
    label = _label(Path(dest), label)
    dest, home = _inspect(Path(dest), directory, label, owned)
    created = _make_parents(home, label)
    held: locks.OutputLock | None = None
    try:
        if wants_lock and not locks.covered(dest):
            held, dest, home = _lock(dest, home, directory, label, owned)
            with contextlib.suppress(OSError):
                _remove_stale(dest, home, directory)
        with os_errors(label, f"cannot write in {home}"):
            tmp = _make_temporary(dest, home, directory)
    except BaseException:
        if held is not None:
            held.release()
        _remove_folders(created)
        raise
    try:
        if block_writes:
            with os_errors(label):
                yield tmp
        else:
            yield tmp
    except BaseException:
        with _no_interrupts():
            _discard(tmp, held, created)
        raise
    # A Ctrl-C while the output moves into place takes effect once it is there and unlocked.
    with _no_interrupts():
        try:
            with os_errors(label):
                if directory:
                    _commit_folder(tmp, dest, home, owned)
                else:
                    _commit_file(tmp, dest)
        except BaseException:
            _discard(tmp, held, created)
            raise
        if held is not None:
            held.release()


def _discard(tmp: Path, held: locks.OutputLock | None, created: list[Path]) -> None:
    """Remove an unfinished output's temporary, release its lock and the folders made for it."""
    _remove(tmp)
    if held is not None:
        held.release()
    _remove_folders(created)


# -- locking -------------------------------------------------------------------------------------
def _lock_file(dest: Path, home: Path) -> Path:
    """Where the lock of ``dest`` lives: inside an existing output folder, else beside the output."""
    return dest / locks.LOCK_NAME if home == dest else dest.parent / locks.beside_name(dest.name)


def _lock(dest: Path, home: Path, directory: bool, label: str,
          owned: Callable[[str], bool]) -> tuple[locks.OutputLock, Path, Path]:
    """Lock ``dest``; return the lock and ``dest``/``home`` as found once it is held.

    A folder output that did not exist is locked beside it; if it appeared meanwhile (another
    writer finished it), its own lock inside is taken instead and the checks run again.
    """
    for _ in range(3):
        if home == dest:
            lock = locks.lock_inside(dest, label)
        else:
            lock = locks.lock_beside(dest, label)
        try:
            found, found_home = _inspect(dest, directory, label, owned)
        except BaseException:
            lock.release()
            raise
        if found_home == home:
            return lock, found, found_home
        lock.release()
        dest, home = found, found_home
    raise ClothsimError(f"{label}: keeps changing while being locked; is another program writing it?")


def _remove_stale(dest: Path, home: Path, directory: bool) -> None:
    """Remove the temporary outputs of earlier writers of ``dest`` that were killed.

    Called with the lock held: a live writer of this output would hold it. A destination name
    cut short in its temporary names (over 64 characters) is skipped, since the cut names could
    belong to another output.
    """
    if directory and home == dest:
        pattern = _FRAMES_TMP
    else:
        stem = dest.name if directory else dest.stem
        if len(stem) > _STEM_MAX:
            return
        suffix = "" if directory else dest.suffix
        pattern = re.compile(rf"\.{re.escape(stem)}\.{_RANDOM}\.tmp{re.escape(suffix)}")
    with os.scandir(home) as entries:
        stale = [Path(e.path) for e in entries if pattern.fullmatch(e.name)
                 and (e.is_dir(follow_symlinks=False) if directory else e.is_file(follow_symlinks=False))]
    for path in stale:
        _remove(path)


# -- checks --------------------------------------------------------------------------------------
def _label(dest: Path, label: str | None) -> str:
    return label if label is not None else str(dest)


def _inspect(dest: Path, directory: bool, label: str,
             owned: Callable[[str], bool] = is_frame_name) -> tuple[Path, Path]:
    """Check what is at ``dest`` and above it.

    Returns the path to write (``dest`` with a symbolic link followed) and the folder that will
    hold the temporary output: the destination itself for an existing frames folder, else its
    parent (which may not exist yet).
    """
    check_name(dest, label)
    try:
        if dest.is_symlink():
            dest = Path(os.path.realpath(dest))
    except OSError as exc:
        raise os_error(label, exc, "cannot check") from None
    try:
        st = dest.stat()
    except FileNotFoundError:
        st = None
    except NotADirectoryError:
        raise ClothsimError(f"{label}: {_file_ancestor(dest)} is a file, not a folder") from None
    except OSError as exc:
        raise os_error(label, exc, "cannot check") from None
    if directory:
        if st is not None and not stat.S_ISDIR(st.st_mode):
            raise ClothsimError(f"{label}: exists and is not a folder (a frames folder needs a folder)")
        if st is not None:
            _check_folder_is_ours(dest, label, owned)
            return dest, dest
    elif st is not None:
        if stat.S_ISDIR(st.st_mode):
            raise ClothsimError(f"{label}: is a folder, not a file; choose a file name")
        if not stat.S_ISREG(st.st_mode):
            raise ClothsimError(f"{label}: not a regular file (a device, pipe or socket is never replaced)")
    ancestor = _nearest_existing(dest.parent)
    try:
        is_folder = ancestor.is_dir()
    except OSError as exc:
        raise os_error(label, exc, "cannot check") from None
    if not is_folder:
        raise ClothsimError(f"{label}: {ancestor} is a file, not a folder")
    if _holds_devices(ancestor):
        raise ClothsimError(f"{label}: will not write in {ancestor} (a file system of device files)")
    return dest, dest.parent


def _holds_devices(folder: Path) -> bool:
    """True for a folder on the file system mounted at /dev (not /dev/shm or another mount).

    As root, anything can be created there; an output (or its temporary file) in /dev is a
    slip of the keyboard, not a place to keep images.
    """
    try:
        dev = os.stat("/dev").st_dev
        return dev != os.stat("/").st_dev and os.stat(folder).st_dev == dev
    except OSError:
        return False


def _nearest_existing(folder: Path) -> Path:
    """``folder`` or the nearest of its parents that exists (as anything)."""
    for candidate in (folder, *folder.parents):
        if os.path.lexists(candidate):
            return candidate
    return folder


def _file_ancestor(path: Path) -> Path:
    """The first component of ``path`` that exists and is not a folder (for error messages)."""
    for candidate in reversed(path.parents):
        if candidate.exists() and not candidate.is_dir():
            return candidate
    return path.parent


def _check_folder_is_ours(folder: Path, label: str, owned: Callable[[str], bool] = is_frame_name) -> None:
    with os_errors(label, "cannot read the folder"):
        with os.scandir(folder) as entries:
            foreign = sum(1 for e in entries if not _ours(e, owned))
    if foreign:
        files = "file" if foreign == 1 else "files"
        raise ClothsimError(f"{label}: folder is not empty ({foreign} {files} not written by clothsim); "
                            "choose another or empty it")


def _ours(entry: os.DirEntry[str], owned: Callable[[str], bool]) -> bool:
    """A file clothsim wrote in a frames folder: an output file, its lock, or a killed run's temporary folder."""
    if entry.name == locks.LOCK_NAME or owned(entry.name):
        return entry.is_file(follow_symlinks=False)
    return _FRAMES_TMP.fullmatch(entry.name) is not None and entry.is_dir(follow_symlinks=False)


# -- temporary output and commit -----------------------------------------------------------------
def _make_parents(home: Path, label: str) -> list[Path]:
    """Create ``home`` and its missing parents; return the folders created, outermost first."""
    missing = []
    for folder in (home, *home.parents):
        if folder.exists():
            break
        missing.append(folder)
    created: list[Path] = []
    try:
        with os_errors(label, "cannot create the folder"):
            for folder in reversed(missing):
                folder.mkdir()
                created.append(folder)
    except BaseException:
        _remove_folders(created)
        raise
    return created


def _make_temporary(dest: Path, home: Path, directory: bool) -> Path:
    if directory and home == dest:
        return Path(tempfile.mkdtemp(prefix=".clothsim-frames.", suffix=".tmp", dir=home))
    stem = (dest.name if directory else dest.stem)[:_STEM_MAX]
    if directory:
        return Path(tempfile.mkdtemp(prefix=f".{stem}.", suffix=".tmp", dir=home))
    fd, name = tempfile.mkstemp(prefix=f".{stem}.", suffix=f".tmp{dest.suffix}", dir=home)
    os.close(fd)
    return Path(name)


def _commit_file(tmp: Path, dest: Path) -> None:
    try:
        mode = stat.S_IMODE(dest.stat().st_mode)  # a replaced file keeps its permissions
    except FileNotFoundError:
        mode = 0o666 & ~_umask()
    os.chmod(tmp, mode)  # mkstemp creates files only the owner can read
    _fsync(tmp)
    os.replace(tmp, dest)
    _fsync_folder(dest.parent)


def _commit_folder(tmp: Path, dest: Path, home: Path, owned: Callable[[str], bool] = is_frame_name) -> None:
    names = sorted(os.listdir(tmp))
    for name in names:
        _fsync(tmp / name)
    if home == dest:  # an existing folder: move the frames in, then drop the old ones beyond them
        for name in names:
            os.replace(tmp / name, dest / name)
        new = set(names)
        with os.scandir(dest) as entries:
            stale = [e.name for e in entries
                     if e.name not in new and owned(e.name) and e.is_file(follow_symlinks=False)]
        for name in stale:
            (dest / name).unlink(missing_ok=True)
        os.rmdir(tmp)
        _fsync_folder(dest)
    else:
        os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp creates folders only the owner can enter
        os.rename(tmp, dest)
        _fsync_folder(dest.parent)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            path.unlink(missing_ok=True)


def _remove_folders(created: list[Path]) -> None:
    for folder in reversed(created):
        with contextlib.suppress(OSError):
            folder.rmdir()  # only if still empty: something else may have been put there meanwhile


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _fsync(path: Path) -> None:
    # Without it a crash soon after the rename can leave an empty file under the final name, and
    # some file systems (NFS, quotas) report a full disk only here.
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_folder(folder: Path) -> None:
    # Makes the rename itself durable; not every file system lets a folder be synced.
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def _no_interrupts() -> Iterator[None]:
    """Hold off Ctrl-C while moving outputs into place or cleaning up, then deliver it.

    A Ctrl-C during cleanup would otherwise leave the temporary output behind, and one during
    the final renames would leave a frames folder half old, half new. A Ctrl-C that arrives
    meanwhile is held and raised once these few file operations are done: it used to be
    ignored, and a sweep interrupted while it moved a file into its dataset then ran on.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous is None:  # installed outside Python: it could not be put back
        yield
        return
    held: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if held:
            # Delivered as if it arrived now, to whatever handled Ctrl-C before (ignored if
            # that ignored it, as in a sweep's workers).
            signal.raise_signal(signal.SIGINT)
