"""Where the files a scene names (OBJ meshes, images) are found when the scene was uploaded.

A scene read from disk names its files by paths relative to its own folder, as the course's
files do, and they are opened there (the rules in :mod:`clothsim.meshcollider` and
:mod:`clothsim.render.settings`). A scene uploaded to ``clothsim serve`` comes from a client
the server must not trust with its file system, so its names resolve through
:class:`UploadedFiles` alone: to a file uploaded in the same request (matched by its base name,
so a scene written for ``meshes/chair.obj`` loads when ``chair.obj`` comes with it) or to an
asset bundled with the package (``torus.obj``). Any other name is refused with a one-line error
naming the field, before any path is opened, so the answer tells nothing about the server's
files. The uploaded bytes are written by the server under names it chooses, in its own private
folder, and read from there.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path, PurePosixPath

from . import validate as V
from .resources import data_dir

__all__ = ["MAX_IMAGE_PIXELS", "UploadedFiles", "base_name", "bundled_assets"]

#: Largest image an upload may bring (pixels): 4096 x 4096, far above what a cloth texture needs.
MAX_IMAGE_PIXELS = 4096 * 4096
_SAFE = re.compile(r"[^A-Za-z0-9._-]")
# Which bundled files each kind of reference may name.
_SUFFIXES = {"OBJ": (".obj",), "image": (".png", ".jpg", ".jpeg", ".bmp", ".gif", ".tif", ".tiff", ".webp")}


def base_name(name: str) -> str:
    """The last part of a name written with ``/`` or ``\\`` separators (``""`` for none)."""
    return PurePosixPath(str(name).replace("\\", "/")).name


def bundled_assets() -> dict[str, Path]:
    """The files shipped beside the bundled scenes that a scene may name (meshes), by name."""
    return {p.name: p for p in sorted(data_dir("scenes").iterdir()) if p.is_file() and p.suffix != ".json"}


class UploadedFiles:
    """The files that came with one uploaded scene, and the bundled assets; nothing else.

    ``files`` maps each uploaded file's base name to where the server stored it.
    """

    def __init__(self, files: Mapping[str, Path], bundled: Mapping[str, Path] | None = None) -> None:
        self.files = dict(files)
        self.bundled = bundled_assets() if bundled is None else dict(bundled)

    @classmethod
    def store(cls, folder: Path, uploads: Mapping[str, bytes]) -> "UploadedFiles":
        """Write ``uploads`` (base name -> bytes) into the new folder ``folder``, each under a name
        the server makes up (its index and a cleaned suffix), and return them."""
        folder.mkdir(mode=0o700)
        stored: dict[str, Path] = {}
        for i, (name, data) in enumerate(uploads.items()):
            suffix = _SAFE.sub("_", os.path.splitext(name)[1])[:16]
            path = folder / f"{i}{suffix}"
            path.write_bytes(data)
            stored[name] = path
        return cls(stored)

    def locate(self, name: str, at: V.At, kind: str) -> Path:
        """The stored file a scene's ``name`` refers to, or ``at``'s one-line error."""
        base = base_name(name)
        bundled = {n: p for n, p in self.bundled.items() if p.suffix.lower() in _SUFFIXES[kind]}
        path = self.files.get(base) or bundled.get(base)
        if path is None:
            uploaded = ", ".join(V.shown(n) for n in sorted(self.files)) or "none"
            ours = f"or a bundled one ({', '.join(sorted(bundled))})" if bundled else "(none is bundled)"
            raise at.fail(f"{V.shown(name)}: an uploaded scene may name only the {kind} files uploaded with it "
                          f"(uploaded: {uploaded}) {ours}; the server opens no other file")
        if kind == "image" and base in self.files:
            _check_image(path, base, at)
        return path


def _check_image(path: Path, name: str, at: V.At) -> None:
    # Decoded once here, so that a bad or huge image is refused with the upload, not at draw time.
    import struct

    from PIL import Image

    try:
        with Image.open(path) as im:
            width, height = im.size
            if width * height > MAX_IMAGE_PIXELS:
                raise at.fail(f"{V.shown(name)}: image is {width}x{height} pixels, more than an upload may bring "
                              f"({MAX_IMAGE_PIXELS} pixels, e.g. 4096x4096)")
            im.load()
    except (OSError, ValueError, SyntaxError, EOFError, struct.error, Image.DecompressionBombError) as exc:
        why = " ".join(str(exc).replace(str(path), name).split())[:120]
        raise at.fail(f"{V.shown(name)}: cannot read image: {why}") from None
