"""A sweep's dataset folder: its definition, its manifest, one array file per run, and resume.

``OUT/sweep.json`` holds the sweep's definition (base scene, parameters, frames, ...), written
once when the folder is made; the same OUT with a different definition is refused.
``OUT/manifest.jsonl`` gets one JSON line per finished run, appended whole and synced as runs
finish. ``OUT/runs/<id>.npz`` (and ``<id>.mp4`` with video) appear atomically. On resume, the
last record of each run counts, and a ``done`` record counts only if its files are there and
read back whole; every other run is done again.

The folder is locked for the whole sweep (``OUT/.clothsim.lock``, see :mod:`clothsim.locks`): a
second sweep into it, the same command or another, stops with one line naming the holder and
writes nothing. A folder that does not exist is created when it is locked (and removed again if
the sweep ends before writing its definition). Once the lock is held, the temporary files of a
sweep that was killed while writing (``runs/.run_00001.XXXXXXXX.tmp.npz``) are removed.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from .. import locks
from ..atomic import atomic_output, check_destination, check_name, os_errors
from ..errors import ClothsimError

__all__ = ["DEFINITION", "MANIFEST", "RUNS", "Dataset", "NPZ_KEYS"]

DEFINITION = "sweep.json"
MANIFEST = "manifest.jsonl"
RUNS = "runs"
FORMAT = "clothsim-sweep/1"
NPZ_KEYS = ("positions", "faces", "uv", "pinned", "scene", "frames")
# Temporary names (clothsim.atomic) of the files a sweep writes: left behind only by a killed sweep.
_STALE_TOP = re.compile(r"\.sweep\.[a-z0-9_]{8}\.tmp\.json")
_STALE_RUN = re.compile(r"\.run_\d{5,}\.[a-z0-9_]{8}\.tmp(\.(npz|mp4))?")  # no suffix: a views folder
_STALE_META = re.compile(r"\.meta\.[a-z0-9_]{8}\.tmp\.json")
# The files of a run's views folder (runs/<id>/).
VIEW_FILE = re.compile(r"rgb_v\d+_\d{5,}\.png|channels\.npz|cameras\.json")
VIEW_ARRAYS = "channels.npz"
VIEW_CAMERAS = "cameras.json"


class Dataset:
    """The dataset folder ``out`` of a sweep with ``definition`` (a JSON-able dict)."""

    def __init__(self, out: str | os.PathLike[str], definition: dict[str, Any]) -> None:
        self.label = os.fspath(out)
        self.out = Path(out)
        self.definition = {"format": FORMAT, **definition}
        self.resumed = False
        self.meta: dict[str, Any] | None = None  # meta.json's contents, written by start()
        self.splits: dict[str, str] = {}  # run id -> its split
        self._lock: locks.OutputLock | None = None
        self._created: list[Path] = []

    # -- before any run ------------------------------------------------------------------------
    def open(self) -> None:
        """Check OUT, lock it (creating it if missing) and remove a killed sweep's temporary files.

        Refuses an OUT that is not a folder, holds someone else's files or another sweep, or is
        being written by another process. Call :meth:`close` at the end, however the sweep ends.
        """
        self._name_a_writer()  # a sweep writing it now is named first, whatever else is wrong
        try:
            self.check()  # before locking: nothing is created in a folder that is refused anyway
        except ClothsimError:
            self._name_a_writer()  # one that took the lock since, and wrote what the check refused
            raise
        try:
            self._take_lock()
            self.check()  # again, now that no other sweep can change it
            with os_errors(self.label, "cannot remove a killed sweep's temporary file"):
                self._remove_stale()
        except BaseException:
            self.close()
            raise

    def _name_a_writer(self) -> None:
        with os_errors(self.label, "cannot check"):
            if self.out.is_dir():
                locks.probe(self.out / locks.LOCK_NAME, self.label)

    def close(self) -> None:
        """Unlock OUT; if this sweep created it and wrote nothing, remove it again."""
        if self._lock is not None:
            self._lock.release()
            self._lock = None
        for folder in reversed(self._created):
            try:
                folder.rmdir()  # only if empty: the definition or a run is in it once started
            except OSError:
                break
        self._created = []

    def _take_lock(self) -> None:
        out, label = self.out, self.label
        with os_errors(label, "cannot create the folder"):
            if out.is_dir():
                self._lock = locks.lock_inside(out, label)
                return
            # Beside it while it is created: a frames folder or OBJ sequence being built under a
            # temporary name for the same path holds that lock until it is renamed into place.
            for folder in reversed([f for f in out.parents if not f.exists()]):
                folder.mkdir()
                self._created.append(folder)
            with locks.holding(locks.lock_beside(out, label)):
                if not out.exists():
                    out.mkdir()
                    self._created.append(out)
                self._lock = locks.lock_inside(out, label)

    def _remove_stale(self) -> None:
        for folder, pattern in ((self.out, _STALE_TOP), (self.out, _STALE_META), (self.out / RUNS, _STALE_RUN)):
            try:
                entries = list(os.scandir(folder))
            except FileNotFoundError:
                continue
            for entry in entries:
                if pattern.fullmatch(entry.name):
                    if entry.is_file(follow_symlinks=False):
                        os.unlink(entry.path)
                    elif entry.is_dir(follow_symlinks=False):
                        shutil.rmtree(entry.path)

    def check(self) -> None:
        """Refuse an OUT that is not a folder, holds someone else's files or another sweep."""
        out, label = self.out, self.label
        check_name(out, label)
        with os_errors(label, "cannot check"):
            if out.is_symlink():
                out = self.out = Path(os.path.realpath(out))
            exists = out.exists()
        if exists:
            if not out.is_dir():
                raise ClothsimError(f"{label}: exists and is not a folder (a dataset is a folder)")
            with os_errors(label, "cannot read the folder"):
                names = [n for n in os.listdir(out) if not locks.is_lock_name(n) and not _STALE_TOP.fullmatch(n)
                         and not _STALE_META.fullmatch(n)]
            if names:
                if DEFINITION not in names:
                    raise ClothsimError(f"{label}: folder is not empty ({len(names)} "
                                        f"{'file' if len(names) == 1 else 'files'} not written by clothsim sweep, "
                                        f"such as {sorted(names)[0]!r}); choose another or empty it")
                theirs = self._read_definition()
                if theirs != self.definition:
                    raise ClothsimError(f"{label}: holds a different sweep ({_difference(theirs, self.definition)}); "
                                        "re-run its own command to resume it, or choose another folder")
                self.resumed = True
        check_destination(out / DEFINITION, label=label)
        if self.resumed:
            check_destination(out / RUNS / "x.npz", label=label)

    def _read_definition(self) -> dict[str, Any]:
        path = self.out / DEFINITION
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise ClothsimError(f"{self.label}: {DEFINITION} is not a clothsim sweep definition "
                                f"({' '.join(str(exc).split())}); choose another folder") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ClothsimError(f"{self.label}: {DEFINITION} is not a clothsim sweep definition; choose another folder")
        return data

    def start(self) -> None:
        """Write the definition of a new dataset (the folder appears with it), and meta.json."""
        if not self.resumed:
            with atomic_output(self.out / DEFINITION, label=f"{self.label}/{DEFINITION}") as tmp:
                tmp.write_text(json.dumps(self.definition, indent=1) + "\n", encoding="utf-8")
        if self.meta is not None:
            self.write_meta(self.meta)

    # -- resume --------------------------------------------------------------------------------
    def records(self) -> dict[str, dict[str, Any]]:
        """The last complete manifest line of each run (a torn last line is ignored)."""
        path = self.out / MANIFEST
        if not path.exists():
            return {}
        with os_errors(self.label, "cannot read the manifest"):
            text = path.read_bytes().decode("utf-8", errors="replace")
        return manifest_records(text)

    def finished(self, expected: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
        """The records of runs that need not run again: ``expected`` maps id -> {params, samples,
        points}; a done run's files are read back and checked, a failed run is final."""
        out: dict[str, dict[str, Any]] = {}
        for run_id, record in self.records().items():
            want = expected.get(run_id)
            if want is None or record.get("params") != want["params"]:
                continue
            if record.get("status") == "failed":
                out[run_id] = record
            elif record.get("status") == "done" and self._complete(run_id, record, want):
                out[run_id] = record
        return out

    def _complete(self, run_id: str, record: dict[str, Any], want: dict[str, Any]) -> bool:
        try:
            with self._npz(f"{RUNS}/{run_id}.npz") as data:
                if set(NPZ_KEYS) - set(data.files):
                    return False
                arrays = {k: data[k] for k in NPZ_KEYS}  # reading checks every member's CRC
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile):
            return False
        positions = arrays["positions"]
        if positions.dtype != np.float32 or positions.shape[0] != want["samples"] or positions.shape[2:] != (3,):
            return False
        if self.definition.get("video") and self._size(f"{RUNS}/{run_id}.mp4") <= 0:
            return False
        if self.definition.get("views"):
            return self._views_complete(run_id, want["samples"])
        return True

    def _views_complete(self, run_id: str, samples: int) -> bool:
        """A run's views folder holds its cameras, every PNG and whole arrays."""
        folder = f"{RUNS}/{run_id}"
        views = int(self.definition["views"])
        channels = self.definition["channels"]
        try:
            cameras = json.loads(self._bytes(f"{folder}/{VIEW_CAMERAS}").decode("utf-8"))
            if not isinstance(cameras, list) or len(cameras) != views:
                return False
            if "rgb" in channels:
                pngs = [n for n in self._names(folder) if n.startswith("rgb_") and VIEW_FILE.fullmatch(n)]
                if len(pngs) != views * samples or any(self._size(f"{folder}/{n}") <= 0 for n in pngs):
                    return False
            arrays = [c for c in channels if c != "rgb"]
            if arrays:
                with self._npz(f"{folder}/{VIEW_ARRAYS}") as data:
                    for name in arrays:
                        a = data[name]  # reading checks the member's CRC
                        if a.shape[0] != views or a.shape[1] != samples - (1 if name == "flow" else 0):
                            return False
        except (OSError, ValueError, EOFError, KeyError, UnicodeDecodeError, zipfile.BadZipFile):
            return False
        return True

    # -- reading files (a remote dataset reads through fsspec instead) --------------------------
    def _npz(self, rel: str) -> Any:
        return np.load(self.out / rel, allow_pickle=False)

    def _bytes(self, rel: str) -> bytes:
        return (self.out / rel).read_bytes()

    def _names(self, rel: str) -> list[str]:
        return os.listdir(self.out / rel)

    def _size(self, rel: str) -> int:
        """The file's size, or -1 if it is not a file."""
        path = self.out / rel
        return path.stat().st_size if path.is_file() else -1

    def has_definition(self) -> bool:
        """Whether ``sweep.json`` has been written (the dataset has started)."""
        return (self.out / DEFINITION).is_file()

    # -- writing -------------------------------------------------------------------------------
    def write_meta(self, meta: dict[str, Any]) -> None:
        """Write ``meta.json`` (atomically; only when it changed, so a resume leaves it alone)."""
        from .meta import META

        path = self.out / META
        text = json.dumps(meta, indent=1) + "\n"
        with os_errors(self.label, "cannot read meta.json"):
            if path.is_file() and path.read_text(encoding="utf-8", errors="replace") == text:
                return
        with atomic_output(path, label=f"{self.label}/{META}") as tmp:
            tmp.write_text(text, encoding="utf-8")

    def write_views(self, run_id: str, views: dict[str, Any], frames: list[int]) -> None:
        """Write ``runs/<id>/`` (RGB PNGs, ``channels.npz``, ``cameras.json``) atomically: built
        under a temporary name and renamed into place whole."""
        from PIL import Image

        rel = f"{RUNS}/{run_id}"
        with atomic_output(self.out / rel, directory=True, label=f"{self.label}/{rel}",
                           owned=lambda n: VIEW_FILE.fullmatch(n) is not None) as tmp:
            (tmp / VIEW_CAMERAS).write_text(json.dumps(views["cameras"], indent=1) + "\n", encoding="utf-8")
            rgb = views.get("rgb")
            if rgb is not None:
                for v in range(rgb.shape[0]):
                    for t, frame in enumerate(frames):
                        Image.fromarray(rgb[v, t]).save(tmp / f"rgb_v{v}_{frame:05d}.png", format="PNG")
            arrays = {k: views[k] for k in ("depth", "normal", "mask", "flow") if k in views}
            if arrays:
                save_npz(tmp / VIEW_ARRAYS, arrays)

    def write_run(self, run_id: str, arrays: dict[str, np.ndarray], video: np.ndarray | None, fps: float) -> str:
        """Write ``runs/<id>.npz`` (and ``.mp4``) atomically; return the npz's relative path."""
        rel = f"{RUNS}/{run_id}.npz"
        with atomic_output(self.out / rel, label=f"{self.label}/{rel}") as tmp:
            # Straight into the temporary file (its name ends in .npz, so none is added): the
            # sweep's parent shares two cores with the workers, and a 9 MB copy through memory
            # per run is time they lose.
            np.savez(tmp, **arrays)
        if video is not None:
            from ..output import open_output

            with open_output(self.out / RUNS / f"{run_id}.mp4", fps) as sink:
                for frame in video:
                    sink(frame)
        return rel

    def append(self, record: dict[str, Any]) -> None:
        """Append one manifest line, whole, and sync it."""
        path = self.out / MANIFEST
        line = json.dumps(record, allow_nan=False, separators=(", ", ": ")) + "\n"
        with os_errors(f"{self.label}/{MANIFEST}"):
            with open(path, "ab") as fh:
                if fh.tell() > 0:
                    with open(path, "rb") as check:
                        check.seek(-1, os.SEEK_END)
                        if check.read(1) != b"\n":  # a line torn by a crash: end it first
                            fh.write(b"\n")
                fh.write(line.encode("utf-8"))
                fh.flush()
                os.fsync(fh.fileno())


def save_npz(file: Any, arrays: dict[str, np.ndarray], level: int = 1) -> None:
    """``np.savez_compressed`` at zlib ``level``: the same file format (``np.load`` reads it),
    but level 1 encodes a run's views in about 60 % of the default level's time for 8 % more
    bytes (4 views x 31 frames at 256x256: 1.4 s and 9.7 MB against 2.3 s and 9.0 MB)."""
    from numpy.lib import format as npy

    with zipfile.ZipFile(file, "w", zipfile.ZIP_DEFLATED, compresslevel=level) as zf:
        for name, value in arrays.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as fh:
                npy.write_array(fh, np.asanyarray(value), allow_pickle=False)


def run_arrays(positions: np.ndarray, nw: int, nh: int, pinned: np.ndarray, scene: Any, frames: list[int],
               scene_json: dict[str, Any], surface: Any = None, rest: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The members of a run file (``runs/<id>.npz``), MeshGraphNets' fields among them.

    A grid cloth's members are what they always were. A mesh cloth (``scene.cloth.is_mesh``)
    writes the same members from its ``surface`` (:func:`clothsim.cloth.cloth_surface`, computed
    here if not given): ``faces``/``cells`` its triangles, ``uv`` each point's texture
    coordinates (those of its first render vertex), ``mesh_pos`` by :func:`mesh_positions` from
    ``rest`` (the simulation's initial positions; else the mesh's points), and three more
    members that keep its UV seams: ``uv_vertex``, ``uv_faces`` and ``uv_point``.
    """
    from .meta import NODE_HANDLE, NODE_NORMAL

    pinned = np.asarray(pinned, dtype=bool)
    common = {
        "positions": positions,
        "pinned": pinned,
        "scene": np.array(json.dumps(scene_json)),
        "frames": np.array(frames, dtype=np.int64),
    }
    node_type = np.where(pinned, NODE_HANDLE, NODE_NORMAL).astype(np.int32)
    if not scene.cloth.is_mesh:
        from ..cloth import cloth_triangles, cloth_uvs  # not the renderer's module: no Numba here

        faces = cloth_triangles(nw, nh).astype(np.int32).reshape(-1, 3)
        uv = np.asarray(cloth_uvs(nw, nh), dtype=np.float32)
        return {
            "positions": positions,
            "faces": faces,
            "uv": uv,
            "pinned": pinned,
            "scene": common["scene"],
            "frames": common["frames"],
            # MeshGraphNets' names (world_pos is positions: meta.json says so)
            "mesh_pos": uv * np.array([scene.cloth.width, scene.cloth.height], dtype=np.float32),
            "node_type": node_type,
            "cells": faces,
        }
    if surface is None:
        from ..cloth import cloth_surface

        surface = cloth_surface(scene.cloth)
    if rest is None:
        rest = np.asarray(scene.cloth.mesh.points, dtype=np.float64)
    faces = np.ascontiguousarray(surface.triangles, dtype=np.int32).reshape(-1, 3)
    uv_point = np.asarray(surface.uv_point, dtype=np.int64)
    uvs = np.asarray(surface.uvs, dtype=np.float32)
    return {
        **common,
        "faces": faces,
        "uv": uvs[first_vertex(uv_point, len(rest))],
        "mesh_pos": mesh_positions(surface, rest),
        "node_type": node_type,
        "cells": faces,
        "uv_vertex": uvs,
        "uv_faces": np.ascontiguousarray(surface.uv_triangles, dtype=np.int32).reshape(-1, 3),
        "uv_point": uv_point.astype(np.int32),
    }


def first_vertex(uv_point: np.ndarray, points: int) -> np.ndarray:
    """(N,) the first render vertex of each point; one line if a point has none."""
    found, first = np.unique(np.asarray(uv_point, dtype=np.int64), return_index=True)
    if len(found) != points or (points and (found[0] != 0 or found[-1] != points - 1)):
        raise ClothsimError(f"cloth surface: {points - len(found)} of {points} points have no render vertex")
    return first


def uv_scale(surface: Any, rest: np.ndarray) -> float:
    """Metres per UV unit: the s minimising the sum over the surface's edges of
    (s |uv_a - uv_b| - |x_a - x_b|)^2, edges taken once each over render vertices (a seam's two
    sides are two edges) and x the rest positions of their points. 0 when every edge has zero UV length."""
    tris = np.asarray(surface.uv_triangles, dtype=np.int64).reshape(-1, 3)
    pairs = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    pairs = np.unique(np.sort(pairs, axis=1), axis=0)
    uvs = np.asarray(surface.uvs, dtype=np.float64)
    point = np.asarray(surface.uv_point, dtype=np.int64)
    x = np.asarray(rest, dtype=np.float64)
    d = np.linalg.norm(uvs[pairs[:, 0]] - uvs[pairs[:, 1]], axis=1)
    length = np.linalg.norm(x[point[pairs[:, 0]]] - x[point[pairs[:, 1]]], axis=1)
    dd = float(np.dot(d, d))
    return float(np.dot(d, length)) / dd if dd > 0.0 else 0.0


def mesh_positions(surface: Any, rest: np.ndarray) -> np.ndarray:
    """MeshGraphNets' ``mesh_pos`` of a mesh cloth: with UVs, (N, 2) float32, each point's UV
    (its first render vertex) times :func:`uv_scale`; without UVs (``surface.has_uvs`` false, or
    UVs of zero extent), (N, 3) float32, the rest positions."""
    rest = np.asarray(rest, dtype=np.float64)
    scale = uv_scale(surface, rest) if surface.has_uvs else 0.0
    if scale <= 0.0:
        return rest.astype(np.float32)
    uv = np.asarray(surface.uvs, dtype=np.float64)[first_vertex(surface.uv_point, len(rest))]
    return (uv * scale).astype(np.float32)


def describe_mesh_cloth(meta: dict[str, Any], cloth: Any) -> None:
    """Adapt ``meta.json``'s description (:func:`.meta.describe`, written for a grid) to a mesh
    cloth: ``cloth`` instead of ``grid``, and the run file's fields as :func:`run_arrays` writes
    them for a mesh."""
    from ..cloth import cloth_surface

    def _f(dtype: str, shape: str, units: str, doc: str) -> dict[str, Any]:  # meta.json's field entry
        return {"dtype": dtype, "shape": shape, "units": units, "doc": doc}

    surface = cloth_surface(cloth)
    mesh = cloth.mesh
    n, r, t = int(len(mesh.points)), int(len(surface.uvs)), int(len(surface.triangles))
    meta.pop("grid", None)
    source = getattr(mesh, "path", None) or getattr(mesh, "file", None)
    meta["cloth"] = {"kind": "mesh", "file": None if source is None else os.path.basename(os.fspath(source)),
                     "N": n, "render_vertices": r, "triangles": t, "has_uvs": bool(surface.has_uvs)}
    fields = meta["run_file"]["fields"]
    fields["positions"] = _f("float32", "(T, N, 3)", "m", "the cloth's points at the sampled frames, world space, "
                             "y up; point i is the mesh's vertex i (after welding, as the simulation numbers them)")
    fields["faces"] = _f("int32", "(F, 3)", "index", "the cloth's triangles over its points, counter-clockwise seen "
                         f"from the front (the side the normal points to); F = {t}")
    fields["cells"] = _f("int32", "(F, 3)", "index", "MeshGraphNets' name for faces (the same values)")
    fields["uv"] = _f("float32", "(N, 2)", "1", "each point's texture coordinates: those of its first render "
                      "vertex (uv_vertex[i] for the smallest i with uv_point[i] = the point)")
    if surface.has_uvs:
        fields["mesh_pos"] = _f("float32", "(N, 2)", "m", "MeshGraphNets' rest-state 2-D coordinates: uv times "
                                "the one scale s (m per UV unit) minimising the sum over the mesh's edges (over "
                                "render vertices, each once) of (s |uv_a - uv_b| - rest length)^2; rest lengths from "
                                "the initial positions")
    else:
        fields["mesh_pos"] = _f("float32", "(N, 3)", "m", "MeshGraphNets' rest-state coordinates: the mesh has no "
                                "UVs, so the initial (rest) positions")
    fields["uv_vertex"] = _f("float32", "(R, 2)", "1", "texture coordinates per render vertex (a point on a UV seam "
                             f"has one render vertex per side); R = {r}" + ("" if surface.has_uvs else
                                                                            "; a planar projection: no UVs"))
    fields["uv_faces"] = _f("int32", "(F, 3)", "index", "the same triangles as faces over render vertices")
    fields["uv_point"] = _f("int32", "(R,)", "index", "the point of each render vertex (uv_point[uv_faces] == faces)")


def _difference(theirs: dict[str, Any], ours: dict[str, Any]) -> str:
    keys = [k for k in sorted(set(theirs) | set(ours)) if theirs.get(k) != ours.get(k)]
    parts = []
    for k in keys[:3]:
        a, b = theirs.get(k), ours.get(k)
        if isinstance(a, (dict, list)) or isinstance(b, (dict, list)):
            parts.append(f"{k} differs")
        else:
            parts.append(f"{k} {json.dumps(a)} there, {json.dumps(b)} here")
    return "; ".join(parts) or "definition differs"


def manifest_records(text: str) -> dict[str, dict[str, Any]]:
    """The records of a manifest's text by run id, the last one of an id winning; a line that is
    not a JSON object with a string ``id`` (one cut short by a crash, say) is skipped."""
    found: dict[str, dict[str, Any]] = {}
    for line in text.splitlines():
        try:
            record = json.loads(line)
        except ValueError:
            continue
        if isinstance(record, dict) and isinstance(record.get("id"), str):
            found[record["id"]] = record
    return found
