"""A clip being recorded from the frames the server draws, through the CLI's own writers.

The clip is written by :func:`clothsim.output.open_output` (the streaming GIF writer, or
ffmpeg for MP4) into the server's private temporary folder, atomically as every output is;
the page downloads it when it is finished.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from ..output import open_output

#: A clip stops by itself after this many frames (20 s at the course's 90 frames/s), so a
#: forgotten recording cannot fill the disk.
MAX_CLIP_FRAMES = 1800


class ClipRecorder:
    """Feeds images to a GIF or MP4 writer until :meth:`finish` or :meth:`abort`."""

    def __init__(self, path: Path, fps: float, max_frames: int = MAX_CLIP_FRAMES) -> None:
        self.path = path
        self.max_frames = max_frames
        self.frames = 0
        self._stack = contextlib.ExitStack()
        self._sink = self._stack.enter_context(open_output(path, fps))

    def add(self, image: np.ndarray) -> bool:
        """Append one (H, W, 3) uint8 image; True once the clip is as long as it may get."""
        self._sink(image)
        self.frames += 1
        return self.frames >= self.max_frames

    def finish(self) -> Path:
        """Close the writer (the file appears whole at :attr:`path`) and return the path."""
        self._stack.close()
        return self.path

    def abort(self) -> None:
        """Drop the clip: the writer removes its temporary file."""
        with contextlib.suppress(Exception):
            self._stack.__exit__(RuntimeError, RuntimeError("recording aborted"), None)
