"""Image and animation writers: PNG, animated GIF, MP4 (H.264) and a directory of PNGs.

The format follows the output path: ``.png``, ``.gif``, ``.mp4``; a path with no suffix, an
existing directory or a trailing slash means a directory of numbered PNGs. Every writer goes
through :func:`~clothsim.atomic.atomic_output`, so a failed run leaves nothing behind.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Protocol

import numpy as np

from .atomic import atomic_output
from .errors import ClothsimError

FORMATS = ("png", "gif", "mp4", "dir")


def output_format(path: str | os.PathLike[str]) -> str:
    """``png``, ``gif``, ``mp4`` or ``dir`` for an output path; raises ClothsimError otherwise."""
    text = os.fspath(path)
    p = Path(text)
    if text.endswith(("/", os.sep)) or p.is_dir() or not p.suffix:
        return "dir"
    suffix = p.suffix.lower()
    if suffix in (".png", ".gif", ".mp4"):
        return suffix[1:]
    raise ClothsimError(f"{text}: unsupported output type {p.suffix!r} "
                        "(use .png, .gif, .mp4, or a directory for numbered PNGs)")


class FrameSink(Protocol):
    def __call__(self, frame: np.ndarray) -> None: ...


@contextlib.contextmanager
def open_output(path: str | os.PathLike[str], fps: float) -> Iterator[FrameSink]:
    """Yield a function that takes (H, W, 3) uint8 frames; the file appears only on success.

    A ``.png`` keeps the last frame it is given; the other formats keep every frame.
    """
    fmt = output_format(path)
    dest = Path(os.fspath(path).rstrip("/" + os.sep) or ".")
    if fmt == "dir":
        with atomic_output(dest, directory=True) as tmp:
            yield _DirSink(tmp)
        return
    with atomic_output(dest) as tmp:
        if fmt == "png":
            sink = _LastFrame()
            yield sink
            write_png(tmp, sink.require(dest))
        elif fmt == "gif":
            gif = _GifSink(fps)
            yield gif
            gif.save(tmp, dest)
        else:
            with _Mp4Sink(tmp, fps) as mp4:
                yield mp4
                mp4.require(dest)


def write_png(path: str | os.PathLike[str], image: np.ndarray) -> None:
    """Write one (H, W, 3) uint8 image as PNG."""
    from PIL import Image

    Image.fromarray(image, "RGB").save(path, format="PNG")


class _LastFrame:
    def __init__(self) -> None:
        self.frame: np.ndarray | None = None

    def __call__(self, frame: np.ndarray) -> None:
        self.frame = frame

    def require(self, dest: Path) -> np.ndarray:
        if self.frame is None:
            raise ClothsimError(f"{dest}: no frame was rendered")
        return self.frame


class _DirSink:
    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.count = 0

    def __call__(self, frame: np.ndarray) -> None:
        write_png(self.folder / f"frame_{self.count:05d}.png", frame)
        self.count += 1


class _GifSink:
    """Frames are quantised to a palette as they arrive (a few hundred KB each, not MB)."""

    def __init__(self, fps: float) -> None:
        # GIF delays are in 1/100 s and viewers slow anything under 2/100 s down to 1/10 s.
        self.duration_ms = max(20, int(round(100.0 / fps)) * 10)
        self.frames: list = []

    def __call__(self, frame: np.ndarray) -> None:
        from PIL import Image

        self.frames.append(Image.fromarray(frame, "RGB").quantize(colors=255, method=Image.Quantize.MEDIANCUT,
                                                                  dither=Image.Dither.NONE))

    def save(self, path: Path, dest: Path) -> None:
        if not self.frames:
            raise ClothsimError(f"{dest}: no frame was rendered")
        first, rest = self.frames[0], self.frames[1:]
        first.save(path, format="GIF", save_all=True, append_images=rest, duration=self.duration_ms,
                   loop=0, optimize=False, disposal=1)


class _Mp4Sink:
    """H.264 through the ffmpeg binary that imageio-ffmpeg ships."""

    def __init__(self, path: Path, fps: float) -> None:
        self.path = path
        self.fps = fps
        self.writer = None
        self.count = 0

    def __enter__(self) -> "_Mp4Sink":
        return self

    def __call__(self, frame: np.ndarray) -> None:
        if self.writer is None:
            import imageio_ffmpeg

            h, w = frame.shape[:2]
            if w % 2 or h % 2:
                raise ClothsimError(f"{self.path.name}: MP4 (yuv420p) needs an even width and height, got {w}x{h}")
            self.writer = imageio_ffmpeg.write_frames(
                str(self.path), (w, h), fps=self.fps, codec="libx264", pix_fmt_out="yuv420p",
                quality=8, macro_block_size=2, ffmpeg_log_level="error",
                output_params=["-f", "mp4", "-movflags", "+faststart"])
            self.writer.send(None)  # start the generator
        self.writer.send(np.ascontiguousarray(frame))
        self.count += 1

    def require(self, dest: Path) -> None:
        if self.count == 0:
            raise ClothsimError(f"{dest}: no frame was rendered")

    def __exit__(self, *exc: object) -> None:
        if self.writer is not None:
            self.writer.close()
