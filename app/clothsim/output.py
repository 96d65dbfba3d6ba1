"""Image and animation writers: PNG, animated GIF, MP4 (H.264) and a folder of numbered PNGs.

The format follows the output path: ``.png``, ``.gif``, ``.mp4``; a path with no suffix, a
trailing slash, or an existing folder (whose name is not one of those suffixes) means a folder of
``frame_NNNNN.png`` files. Every writer goes through :func:`~clothsim.atomic.atomic_output`, so a
failed or interrupted run leaves nothing behind and never touches files clothsim did not write;
see that module for the rules. Every failure to write is one :class:`ClothsimError` line.
"""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import tempfile
from collections.abc import Iterator
from fractions import Fraction
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from .atomic import atomic_output, check_destination, frame_name, os_errors
from .errors import ClothsimError

FORMATS = ("png", "gif", "mp4", "dir")
_SUFFIXES = (".png", ".gif", ".mp4")


def output_format(path: str | os.PathLike[str]) -> str:
    """``png``, ``gif``, ``mp4`` or ``dir`` for an output path; raises ClothsimError otherwise."""
    text = os.fspath(path)
    if not text:
        raise ClothsimError("output path is empty")
    p = Path(text)
    suffix = p.suffix.lower()
    if text.endswith(("/", os.sep)) or not p.suffix:
        return "dir"
    if p.is_dir():
        if suffix in _SUFFIXES:
            raise ClothsimError(f"{text}: is a folder, not a file; choose a file name "
                                f"(or write {text}/ for numbered PNGs in that folder)")
        return "dir"
    if suffix in _SUFFIXES:
        return suffix[1:]
    raise ClothsimError(f"{text}: unsupported output type {p.suffix!r} "
                        "(use .png, .gif, .mp4, or a folder for numbered PNGs)")


def check_output(path: str | os.PathLike[str]) -> str:
    """Fail fast on an output that could not be written; return its format (see output_format).

    Meant to run before any simulation work: a bad suffix, a frames folder holding files
    clothsim did not write, a folder or device where a file should go, a parent that is a
    file or an unwritable folder all end the run here with one line.
    """
    fmt = output_format(path)
    dest, label = _destination(path)
    check_destination(dest, directory=fmt == "dir", label=label)
    return fmt


class FrameSink(Protocol):
    """Takes one (H, W, 3) uint8 frame."""

    def __call__(self, frame: np.ndarray) -> None: ...


@contextlib.contextmanager
def open_output(path: str | os.PathLike[str], fps: float) -> Iterator[FrameSink]:
    """Yield a function that takes (H, W, 3) uint8 frames; the output appears only on success.

    A ``.png`` keeps the last frame it is given; a GIF or MP4 is written to its temporary file
    as the frames arrive (memory does not grow with the number of frames), and a folder gets
    one PNG per frame.
    """
    fmt = output_format(path)
    dest, label = _destination(path)
    with atomic_output(dest, directory=fmt == "dir", label=label, block_writes=False) as tmp:
        sink: _Sink
        if fmt == "dir":
            sink = _DirSink(tmp, label)
        elif fmt == "png":
            sink = _LastFrame(tmp, label)
        elif fmt == "gif":
            sink = _GifSink(tmp, fps, label)
        else:
            sink = _Mp4Sink(tmp, fps, label)
        try:
            yield sink
            sink.finish()
        except BaseException:
            sink.abort()
            raise


def write_png(path: str | os.PathLike[str], image: np.ndarray) -> None:
    """Write one (H, W, 3) uint8 image as PNG."""
    from PIL import Image

    Image.fromarray(image, "RGB").save(path, format="PNG")


def _destination(path: str | os.PathLike[str]) -> tuple[Path, str]:
    """The output path without trailing slashes, and how error lines name it."""
    text = os.fspath(path)
    stripped = text.rstrip("/" + os.sep)
    if not stripped and text:
        stripped = text[0]  # the root folder
    return Path(stripped), stripped


class _Sink:
    label: str

    def __call__(self, frame: np.ndarray) -> None:
        raise NotImplementedError

    def finish(self) -> None:
        """Complete the temporary output once every frame is in."""

    def abort(self) -> None:
        """Release what the sink holds; the temporary output is about to be removed."""


class _LastFrame(_Sink):
    def __init__(self, path: Path, label: str) -> None:
        self.path = path
        self.label = label
        self.frame: np.ndarray | None = None

    def __call__(self, frame: np.ndarray) -> None:
        self.frame = frame

    def finish(self) -> None:
        if self.frame is None:
            raise ClothsimError(f"{self.label}: no frame was rendered")
        with os_errors(self.label):
            write_png(self.path, self.frame)


class _DirSink(_Sink):
    def __init__(self, folder: Path, label: str) -> None:
        self.folder = folder
        self.label = label
        self.count = 0

    def __call__(self, frame: np.ndarray) -> None:
        with os_errors(self.label):
            write_png(self.folder / frame_name(self.count), frame)
        self.count += 1


# A GIF frame's delay is a 16-bit count of 1/100 s.
_GIF_MAX_DELAY_MS = 65535 * 10


class _GifSink(_Sink):
    """An animated GIF written frame by frame as the frames arrive.

    Pillow's multi-frame writer keeps every frame until the end (hundreds of MB for a long
    800x800 render), and the common wrappers around it do the same, so the frames are encoded
    one at a time with the GIF helpers Pillow publishes (``getheader``/``getdata``). The look is
    what ``save(save_all=True, optimize=False, disposal=1, loop=0)`` gives: every frame quantised
    to its own 255-colour palette (the first one's is the global palette), a later frame cropped
    to the box where its colours differ from the frame before and carrying its own palette, a
    frame identical to the one before merged into it by adding its duration, looping forever.
    Held in memory: the colours of the last distinct frame and one frame waiting for its final
    duration.
    """

    def __init__(self, path: Path, fps: float, label: str) -> None:
        # GIF delays are in 1/100 s and viewers slow anything under 2/100 s down to 1/10 s.
        self.duration_ms = max(20, int(round(100.0 / fps)) * 10)
        self.label = label
        with os_errors(label):
            self.file = open(path, "wb")  # noqa: SIM115 - closed in finish/abort
        self.shown: Any = None
        self.pending: tuple[Any, tuple[int, int, int, int] | None] | None = None
        self.pending_ms = 0
        self.count = 0

    def __call__(self, frame: np.ndarray) -> None:
        from PIL import Image, ImageChops

        image = Image.fromarray(frame, "RGB").quantize(colors=255, method=Image.Quantize.MEDIANCUT,
                                                       dither=Image.Dither.NONE)
        shown = image.convert("RGB")  # the colours a viewer shows, which is what is compared
        self.count += 1
        box = None
        if self.shown is not None:
            box = ImageChops.difference(shown, self.shown).getbbox()
            if box is None:
                self.pending_ms += self.duration_ms
                return
        self._write_pending()
        self.pending = (image, box)
        self.pending_ms = self.duration_ms
        self.shown = shown

    def _write_pending(self) -> None:
        from PIL import GifImagePlugin

        if self.pending is None:
            return
        image, box = self.pending
        first = min(self.pending_ms, _GIF_MAX_DELAY_MS)
        if box is None:
            chunks, _ = GifImagePlugin.getheader(image, info={"loop": 0, "duration": first})
            chunks += GifImagePlugin.getdata(image, (0, 0), duration=first, disposal=1)
            corner = (0, 0)
        else:
            if box != (0, 0, *image.size):
                image = image.crop(box)
            chunks = GifImagePlugin.getdata(image, box[:2], duration=first, disposal=1,
                                            include_color_table=True)
            corner = box[:2]
        # A delay longer than the format holds goes on in frames of one unchanged pixel.
        rest = self.pending_ms - first
        while rest > 0:
            part = min(rest, _GIF_MAX_DELAY_MS)
            chunks += GifImagePlugin.getdata(image.crop((0, 0, 1, 1)), corner, duration=part, disposal=1,
                                             include_color_table=True)
            rest -= part
        with os_errors(self.label):  # flushed so that a full disk shows at this frame, not at the end
            self.file.writelines(chunks)
            self.file.flush()
        self.pending = None

    def finish(self) -> None:
        if self.count == 0:
            self.abort()
            raise ClothsimError(f"{self.label}: no frame was rendered")
        self._write_pending()
        with os_errors(self.label):
            self.file.write(b";")
            self.file.close()

    def abort(self) -> None:
        with contextlib.suppress(OSError):
            self.file.close()


class _Mp4Sink(_Sink):
    """H.264 from the ffmpeg binary that imageio-ffmpeg ships, fed raw RGB frames on a pipe.

    ffmpeg is started here rather than through imageio-ffmpeg's writer because that writer
    neither reports ffmpeg's exit status nor keeps its messages off the terminal: a full disk
    would end in ffmpeg's own lines, or in a broken video renamed into place. Here ffmpeg's
    messages go to an anonymous temporary file, its exit status is checked, and a failure is
    one line quoting ffmpeg's last message. It runs in a session of its own so that Ctrl-C
    reaches only clothsim, which then stops it. The command line is the one imageio-ffmpeg
    builds for the same settings (libx264, yuv420p, quality 8 = CRF 10, faststart).
    """

    def __init__(self, path: Path, fps: float, label: str) -> None:
        self.path = path
        self.fps = fps
        self.label = label
        self.proc: subprocess.Popen[bytes] | None = None
        self.log: Any = None
        self.count = 0

    def _start(self, width: int, height: int) -> None:
        import imageio_ffmpeg

        try:
            exe = imageio_ffmpeg.get_ffmpeg_exe()
        except RuntimeError as exc:
            raise ClothsimError(f"{self.label}: cannot write MP4: {exc}") from None
        rate = Fraction(self.fps).limit_denominator()
        cmd = [exe, "-y", "-f", "rawvideo", "-vcodec", "rawvideo", "-s", f"{width}x{height}",
               "-pix_fmt", "rgb24", "-r", str(rate), "-i", "-", "-an", "-vcodec", "libx264",
               "-pix_fmt", "yuv420p", "-crf", "10", "-v", "error", "-f", "mp4", "-movflags", "+faststart",
               str(self.path)]
        with os_errors(self.label, "cannot start ffmpeg"):
            self.log = tempfile.TemporaryFile()
            self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                         stderr=self.log, start_new_session=True)

    def __call__(self, frame: np.ndarray) -> None:
        h, w = frame.shape[:2]
        if self.proc is None:
            if w % 2 or h % 2:
                raise ClothsimError(f"{self.label}: MP4 (yuv420p) needs an even width and height, got {w}x{h}")
            self._start(w, h)
        assert self.proc is not None and self.proc.stdin is not None
        try:
            self.proc.stdin.write(np.ascontiguousarray(frame, dtype=np.uint8).data)
        except OSError:  # ffmpeg has stopped reading: its exit status and message say why
            raise self._failure() from None
        self.count += 1

    def finish(self) -> None:
        if self.count == 0 or self.proc is None:
            raise ClothsimError(f"{self.label}: no frame was rendered")
        assert self.proc.stdin is not None
        with contextlib.suppress(OSError):
            self.proc.stdin.close()
        if self.proc.wait() != 0:
            raise self._failure()
        self._close_log()

    def abort(self) -> None:
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.kill()
            with contextlib.suppress(OSError):
                assert self.proc.stdin is not None
                self.proc.stdin.close()
            self.proc.wait()
        self._close_log()

    def _failure(self) -> ClothsimError:
        assert self.proc is not None
        if self.proc.poll() is None:
            self.proc.kill()
        status = self.proc.wait()
        message = ""
        if self.log is not None:
            self.log.seek(0)
            lines = [line.strip() for line in self.log.read().decode("utf-8", "replace").splitlines()]
            lines = [line for line in lines if line]
            if lines:
                # "[out#0/mp4 @ 0x55...] Error closing file: ..." names an ffmpeg internal, not a place
                message = re.sub(r"^\[[^\]]* @ 0x[0-9a-fA-F]+\]\s*", "", lines[-1]).replace(str(self.path), self.label)
        self._close_log()
        return ClothsimError(f"{self.label}: ffmpeg failed: {message or f'exit status {status}'}")

    def _close_log(self) -> None:
        if self.log is not None:
            self.log.close()
            self.log = None
