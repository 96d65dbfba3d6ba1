"""Workers that write where the data lives: a run's files encoded in the worker and written
straight into OUT, so that only its manifest line travels back to the sweep.

OUT is a local folder every worker can reach (the local workers' own machine, or a file system
shared by a cluster's machines), or an fsspec URL (``memory://``, ``s3://bucket/prefix``; the
``remote`` extra, plus the file system's own package such as s3fs). On a local folder every file
appears as a local sweep's does (temporary name, then rename; a views folder renamed whole). On
an fsspec file system each file is written as one whole object (an object store's put replaces
an object at once, and readers see the old object or the new). Either way a run counts only once
the sweep's parent has written its manifest line, after the worker reported every file written.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
from typing import Any

import numpy as np

from ..errors import ClothsimError

__all__ = ["REMOTE_HINT", "is_url", "filesystem", "encode_run", "write_files"]

REMOTE_HINT = "pip install 'clothsim[remote]' (and the file system's package, e.g. s3fs for s3://)"


def is_url(out: str | os.PathLike[str]) -> bool:
    """Whether OUT names an fsspec file system (``proto://...``) rather than a local path."""
    text = os.fspath(out)
    return "://" in text and not text.startswith("file://")


def filesystem(url: str) -> tuple[Any, str]:
    """The fsspec file system of ``url`` and the path inside it, or one line naming the extra."""
    try:
        import fsspec
    except ImportError:
        raise ClothsimError(f"{url}: an fsspec URL needs fsspec, which is not installed: {REMOTE_HINT}") from None
    try:
        fs, path = fsspec.core.url_to_fs(url)
    except (ImportError, ValueError) as exc:
        raise ClothsimError(f"{url}: cannot open its file system ({' '.join(str(exc).split())}): "
                            f"{REMOTE_HINT}") from None
    return fs, path.rstrip("/")


def encode_run(run_id: str, arrays: dict[str, np.ndarray], views: dict[str, Any] | None,
               frames: list[int], video: np.ndarray | None, fps: float) -> list[tuple[str, bytes]]:
    """Every file of one run as (path relative to OUT, bytes): the views folder's files first,
    the run file last."""
    files: list[tuple[str, bytes]] = []
    if views is not None:
        files += [(f"runs/{run_id}/{name}", data) for name, data in encode_views(views, frames)]
    if video is not None:
        from ..output import open_output

        with tempfile.TemporaryDirectory(prefix="clothsim-video.") as tmp:
            path = os.path.join(tmp, f"{run_id}.mp4")
            with open_output(path, fps) as sink:
                for frame in video:
                    sink(frame)
            with open(path, "rb") as fh:
                files.append((f"runs/{run_id}.mp4", fh.read()))
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    files.append((f"runs/{run_id}.npz", buf.getvalue()))
    return files


def encode_views(views: dict[str, Any], frames: list[int]) -> list[tuple[str, bytes]]:
    """A run's views folder as (name, bytes): cameras.json, the RGB PNGs, channels.npz."""
    from PIL import Image

    out = [("cameras.json", (json.dumps(views["cameras"], indent=1) + "\n").encode("utf-8"))]
    rgb = views.get("rgb")
    if rgb is not None:
        for v in range(rgb.shape[0]):
            for t, frame in enumerate(frames):
                buf = io.BytesIO()
                Image.fromarray(rgb[v, t]).save(buf, format="PNG")
                out.append((f"rgb_v{v}_{frame:05d}.png", buf.getvalue()))
    arrays = {k: views[k] for k in ("depth", "normal", "mask", "flow") if k in views}
    if arrays:
        from .dataset import save_npz

        buf = io.BytesIO()
        save_npz(buf, arrays)
        out.append(("channels.npz", buf.getvalue()))
    return out


def write_files(out: str, files: list[tuple[str, bytes]]) -> None:
    """Write ``files`` into OUT: a local folder (each file atomically, a run's views folder
    renamed into place whole) or an fsspec URL (each file one whole object)."""
    if is_url(out):
        fs, root = filesystem(out)
        for rel, data in files:
            path = f"{root}/{rel}"
            fs.makedirs(path.rsplit("/", 1)[0], exist_ok=True)
            fs.pipe_file(path, data)
        return
    from pathlib import Path

    from ..atomic import atomic_output
    from .dataset import VIEW_FILE

    root = Path(out.removeprefix("file://"))
    folders: dict[str, list[tuple[str, bytes]]] = {}
    singles: list[tuple[str, bytes]] = []
    for rel, data in files:
        parts = rel.split("/")
        if len(parts) == 3:  # runs/<id>/<name>: a views folder
            folders.setdefault("/".join(parts[:2]), []).append((parts[2], data))
        else:
            singles.append((rel, data))
    # The sweep's parent holds OUT's lock for this whole sweep: a worker takes none of its own.
    for rel, members in folders.items():
        with atomic_output(root / rel, directory=True, lock=False, label=f"{out}/{rel}",
                           owned=lambda n: VIEW_FILE.fullmatch(n) is not None) as tmp:
            for name, data in members:
                (tmp / name).write_bytes(data)
    for rel, data in singles:
        with atomic_output(root / rel, lock=False, label=f"{out}/{rel}") as tmp:
            tmp.write_bytes(data)


def remote_dataset(url: str, definition: dict[str, Any]) -> Any:
    """A :class:`~.dataset.Dataset` at an fsspec URL (see :class:`RemoteDataset`)."""
    return RemoteDataset(url, definition)


from .dataset import DEFINITION, MANIFEST, Dataset, manifest_records  # noqa: E402 - the writer above runs in workers without it


class RemoteDataset(Dataset):
    """A dataset at an fsspec URL. The same definition, resume and refusals as a local folder,
    read and written through fsspec; only the runs' files come from the workers.

    An object store cannot append: the manifest is written whole, at most once a second while
    runs finish and once more at the end, so a sweep killed in between loses the lines of its
    last second's runs (their files are there; the next sweep checks and redoes them). Nothing
    stops two sweeps writing the same URL at once: an object store has no lock to take.
    """

    _FLUSH_SECONDS = 1.0

    def __init__(self, url: str, definition: dict[str, Any]) -> None:
        super().__init__(".", definition)
        self.label = url
        self.fs, self.root = filesystem(url)
        self._manifest: bytes | None = None
        self._dirty = False
        self._flushed = 0.0

    # -- files ----------------------------------------------------------------------------------
    def _path(self, rel: str) -> str:
        return f"{self.root}/{rel}"

    def _npz(self, rel: str) -> Any:
        return np.load(io.BytesIO(self._bytes(rel)), allow_pickle=False)

    def _bytes(self, rel: str) -> bytes:
        try:
            return self.fs.cat_file(self._path(rel))
        except FileNotFoundError:
            raise
        except Exception as exc:  # noqa: BLE001 - every file system has its own errors
            raise OSError(str(exc)) from None

    def _names(self, rel: str) -> list[str]:
        try:
            return [str(e).rstrip("/").rsplit("/", 1)[-1] for e in self.fs.ls(self._path(rel), detail=False)]
        except FileNotFoundError:
            return []

    def _size(self, rel: str) -> int:
        try:
            return int(self.fs.size(self._path(rel)) or 0) if self.fs.isfile(self._path(rel)) else -1
        except FileNotFoundError:
            return -1

    def has_definition(self) -> bool:
        return self._size(DEFINITION) > 0

    # -- the dataset's life ---------------------------------------------------------------------
    def open(self) -> None:
        """Refuse a URL that holds something else or another sweep; no lock (see the class)."""
        self.check()

    def check(self) -> None:
        try:
            exists = self.fs.exists(self.root)
            names = self._names("") if exists else []
        except Exception as exc:  # noqa: BLE001
            raise ClothsimError(f"{self.label}: cannot check: {' '.join(str(exc).split())}") from None
        if names:
            if DEFINITION not in names:
                raise ClothsimError(f"{self.label}: is not empty ({len(names)} "
                                    f"{'entry' if len(names) == 1 else 'entries'} not written by clothsim sweep); "
                                    "choose another or empty it")
            try:
                theirs = json.loads(self._bytes(DEFINITION).decode("utf-8"))
            except (OSError, ValueError, UnicodeDecodeError):
                theirs = None
            if not isinstance(theirs, dict) or theirs.get("format") != self.definition["format"]:
                raise ClothsimError(f"{self.label}: {DEFINITION} is not a clothsim sweep definition; choose another")
            if theirs != self.definition:
                from .dataset import _difference

                raise ClothsimError(f"{self.label}: holds a different sweep ({_difference(theirs, self.definition)}); "
                                    "re-run its own command to resume it, or choose another")
            self.resumed = True

    def close(self) -> None:
        self._flush(force=True)

    def start(self) -> None:
        if not self.resumed:
            self._put(DEFINITION, (json.dumps(self.definition, indent=1) + "\n").encode("utf-8"))
        if self.meta is not None:
            self.write_meta(self.meta)

    def write_meta(self, meta: dict[str, Any]) -> None:
        from .meta import META

        data = (json.dumps(meta, indent=1) + "\n").encode("utf-8")
        try:
            same = self._bytes(META) == data
        except OSError:
            same = False
        if not same:
            self._put(META, data)

    def records(self) -> dict[str, dict[str, Any]]:
        try:
            text = self._bytes(MANIFEST)
        except (FileNotFoundError, OSError):
            text = b""
        self._manifest = text
        return manifest_records(text.decode("utf-8", errors="replace"))

    def append(self, record: dict[str, Any]) -> None:
        if self._manifest is None:
            self.records()
        line = json.dumps(record, allow_nan=False, separators=(", ", ": ")) + "\n"
        text = self._manifest or b""
        if text and not text.endswith(b"\n"):
            text += b"\n"
        self._manifest = text + line.encode("utf-8")
        self._dirty = True
        self._flush()

    def _flush(self, force: bool = False) -> None:
        import time

        if not self._dirty or (not force and time.monotonic() - self._flushed < self._FLUSH_SECONDS):
            return
        self._put(MANIFEST, self._manifest or b"")
        self._dirty = False
        self._flushed = time.monotonic()

    def _put(self, rel: str, data: bytes) -> None:
        try:
            self.fs.makedirs(self.root, exist_ok=True)
            self.fs.pipe_file(self._path(rel), data)
        except Exception as exc:  # noqa: BLE001
            raise ClothsimError(f"{self.label}/{rel}: cannot write: {' '.join(str(exc).split())}") from None

    def write_run(self, run_id: str, arrays: dict[str, np.ndarray], video: np.ndarray | None, fps: float) -> str:
        raise AssertionError("the workers write a remote dataset's runs")  # pragma: no cover
