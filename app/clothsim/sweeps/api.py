"""`clothsim.sweep`: many runs of one scene with parameters varied, into a contact sheet or a dataset.

Every run's scene is built and validated before any run starts (a bad field or value is one
:class:`~clothsim.ClothsimError` line and nothing is written). Runs execute through one
``concurrent.futures`` executor (local processes or a Dask cluster, :mod:`.engines`); results
come back to this process, which writes every file through :mod:`clothsim.atomic`.
"""

from __future__ import annotations

import concurrent.futures
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_output, check_destination, check_name
from ..errors import ClothsimError
from ..scene import Scene, load_scene, resolve_scene_path
from ..validate import check, integer
from . import dataset as ds
from . import meta as M
from . import params as P
from . import sheet as S
from .runner import Task, sample_frames

__all__ = ["sweep"]

DEFAULT_SIZE = (256, 256)


def _frames_list(frames: Any) -> list[int]:
    if isinstance(frames, str):
        try:
            items = [int(x) for x in frames.split(",")]
        except ValueError:
            raise ClothsimError(f"--frames: expected a count or a comma-separated list of frames, got {frames!r}") from None
    elif isinstance(frames, (list, tuple)):
        items = list(frames)
    else:
        items = [frames]
    if not items:
        raise ClothsimError("--frames: no frames")
    return [check(integer(ge=0), f, "--frames") for f in items]


def _base_scene(scene: Any) -> tuple[dict[str, Any], str]:
    """The base scene's JSON and the path errors name (a file, a bundled name, a dict or a Scene)."""
    if isinstance(scene, Scene):
        return P.scene_json(scene), scene.path
    if isinstance(scene, dict):
        return json.loads(json.dumps(scene)), "<scene>"
    load_scene(scene)  # the file's own errors first, exactly as simulate reports them
    path = resolve_scene_path(scene)
    return json.loads(path.read_text(encoding="utf-8")), str(path)


def _output_kind(out: str | os.PathLike[str]) -> str:
    text = os.fspath(out)
    if not text:
        raise ClothsimError("-o: output path is empty")
    from .store import is_url

    if is_url(text):
        if text.rstrip("/").lower().endswith(".png"):
            raise ClothsimError(f"{text}: a contact sheet is a local .png; a URL is for a dataset")
        return "dataset"
    check_name(text)
    p = Path(text)
    if p.suffix.lower() == ".png" and not text.endswith(("/", os.sep)):
        if p.is_dir():
            raise ClothsimError(f"{text}: is a folder, not a file; choose a file name")
        return "sheet"
    if text.endswith(("/", os.sep)) or not p.suffix or p.is_dir():
        return "dataset"
    raise ClothsimError(f"{text}: unsupported output type {p.suffix!r} "
                        "(use .png for a contact sheet, or a folder for a dataset)")


def sweep(scene: Any, grid_or_samples: dict[str, Any], out: str | os.PathLike[str], *,
          frames: int | list[int] = 90, every: int = 1, samples: int | None = None, seed: int | None = None,
          shader: str | None = None, size: tuple[int, int] | str | None = None, workers: int | None = None,
          scheduler: str | None = None, video: bool = False, views: int = 0,
          channels: str | list[str] | tuple[str, ...] | None = None,
          split: str | tuple[float, float, float] | None = None, split_seed: int = 0,
          write_in_workers: bool = False, progress: bool = False, report: bool = False) -> list[dict[str, Any]]:
    """Run ``scene`` once per parameter set and write ``out``; return one record per run.

    ``grid_or_samples`` maps dotted field paths to values: ``{"cloth.ks": [10, 5000],
    "cloth.density": "1,15,1000"}``. Without ``samples`` the runs are the full grid (cartesian
    product, last field fastest); with ``samples=N, seed=S`` N runs are drawn, and a field's
    values may also be ``"uniform:A:B"`` / ``"loguniform:A:B"``. ``out`` ending in ``.png`` is a
    contact sheet of each run's last frame (``frames`` may then be a list: one cell per frame)
    drawn at ``size`` as ``clothsim render`` draws it; a folder is a dataset (``manifest.jsonl``,
    ``runs/<id>.npz`` with positions sampled every ``every`` frames; ``video`` adds an mp4).
    Runs execute in ``workers`` local processes (default: one per core) or on the Dask cluster
    at ``scheduler``. Records have ``id``, ``params``, ``seed``, ``status`` (``done``/``failed``),
    ``error``, ``path``, ``frames``, ``seconds``, and ``skipped`` (True when an earlier sweep into
    the same dataset had finished the run); a run lost with a worker that died (local or Dask) is
    ``failed`` with ``lost`` True, is not written to the manifest, and is run by the next sweep.

    ``views=N`` (a dataset) draws every sampled frame from N fixed cameras (the scene's
    ``render.views``, or drawn around the cloth from the run's index and ``seed``) into
    ``runs/<id>/``: the ``channels`` asked for (default all of ``rgb, depth, normal, mask, flow``)
    and ``cameras.json``. ``split`` (train, valid, test fractions, default 0.8, 0.1, 0.1) and
    ``split_seed`` assign each run to a split in ``meta.json`` (see docs/datasets.md).

    ``write_in_workers`` has the workers write each run's files straight into ``out`` (a folder
    every worker reaches); only the manifest lines travel back. ``out`` may also be an fsspec
    URL (``memory://``, ``s3://bucket/prefix``), which the workers always write directly.

    A dataset folder is locked while the sweep runs: another sweep into it (or this one started
    again) raises :class:`~clothsim.ClothsimError` naming the holder, and writes nothing.
    """
    from ..render.channels import CHANNELS

    from ..render.settings import RenderSettings, parse_size

    start = time.perf_counter()
    kind = _output_kind(out)
    frame_list = _frames_list(frames)
    every = check(integer(ge=1), every, "--every")
    if kind == "dataset" and len(frame_list) > 1:
        raise ClothsimError("--frames: a list of frames is for a contact sheet (.png); a dataset takes one count")
    if kind == "sheet" and video:
        raise ClothsimError("--video: needs a dataset folder as OUT, not a .png")
    views = check(integer(ge=0, le=64), views, "--views")
    if kind == "sheet" and views:
        raise ClothsimError("--views: needs a dataset folder as OUT, not a .png")
    if channels is not None and not views:
        raise ClothsimError("--channels: goes with --views N")
    channel_list: list[str] = []
    if views:
        given = channels.split(",") if isinstance(channels, str) else list(channels or CHANNELS)
        given = [str(c).strip() for c in given if str(c).strip()]
        for c in given:
            if c not in CHANNELS:
                raise ClothsimError(f"--channels: unknown channel {c!r} (expected some of: {', '.join(CHANNELS)})")
        if not given:
            raise ClothsimError(f"--channels: none given (expected some of: {', '.join(CHANNELS)})")
        channel_list = [c for c in CHANNELS if c in given]
    fractions = M.parse_split(split)
    split_seed = check(integer(ge=0, le=2**63 - 1), split_seed, "--split-seed")
    if samples is not None:
        samples = check(integer(ge=1), samples, "--samples")
        seed = check(integer(ge=0, le=2**63 - 1), seed, "--seed") if seed is not None else None
    elif seed is not None:
        raise ClothsimError("--seed: goes with --samples N (a grid draws nothing)")
    if workers is not None:
        workers = check(integer(ge=1), workers, "--workers")
    if isinstance(size, str):
        try:
            size = parse_size(size)
        except ValueError as exc:
            raise ClothsimError(f"--size: {exc}") from None
    cell_size = tuple(size) if size is not None else DEFAULT_SIZE
    if not isinstance(grid_or_samples, dict):
        raise ClothsimError("grid_or_samples: expected a dict {field: values}")
    space = {str(f): P.parse_values(str(f), v) for f, v in grid_or_samples.items()}
    runs = P.expand(space, samples, seed)
    base, path = _base_scene(scene)

    # Every run's scene, built and validated before anything runs or is written.
    draws = kind == "sheet" or video or bool(views)
    scenes: dict[str, Scene] = {}
    settings: dict[str, Any] = {}
    overrides = {k: v for k, v in (("shader", shader), ("size", f"{cell_size[0]}x{cell_size[1]}")) if v is not None}
    for run in runs:
        label = f" ({run.id}: {P.params_text(run.params)})"
        sc = P.build_scene(base, run.params, path, label)
        scenes[run.id] = sc
        if draws:
            try:
                settings[run.id] = RenderSettings.from_scene(sc).with_overrides(
                    overrides, label=lambda f: {"shader": "--shader", "size": "--size"}.get(f.split("[")[0], f))
            except ClothsimError as exc:
                raise ClothsimError(f"{exc}{label}") from None
    last = max(frame_list)
    definition = {
        "scene": base, "scene_path": os.path.basename(path),
        "params": {f: [str(v) if isinstance(v, P.Distribution) else v for v in vs] for f, vs in space.items()},
        "samples": samples, "seed": seed, "frames": last, "every": every, "video": bool(video),
        "size": list(cell_size) if (video or views) else None, "shader": shader if (video or views) else None,
    }
    if views:
        # Only with views, so that a dataset written before they existed resumes as it was.
        listed = settings[runs[0].id].views
        definition.update(views=views, channels=channel_list,
                          cameras_from="render.views" if listed else "drawn")
        for run in runs:
            listed = settings[run.id].views
            if listed is not None and len(listed) < views:
                raise ClothsimError(f"--views {views}: render.views lists only {len(listed)} cameras ({run.id})")
    from .store import is_url, remote_dataset

    remote = kind == "dataset" and is_url(os.fspath(out))
    if write_in_workers and kind != "dataset":
        raise ClothsimError("--write-in-workers: needs a dataset folder as OUT, not a .png")
    direct = bool(write_in_workers) or remote
    data: ds.Dataset | None = None
    if kind == "dataset":
        data = remote_dataset(os.fspath(out), definition) if remote else ds.Dataset(out, definition)
        data.open()  # locked from here: close() below, however the sweep ends
    else:
        check_destination(out, label=os.fspath(out))
    if data is not None:
        first = scenes[runs[0].id]
        from ..render.channels import collider_ids

        description = M.describe(definition, runs, fractions, split_seed, collider_ids(first) if views else [],
                                 (first.cloth.num_width_points, first.cloth.num_height_points))
        description["frames_per_second"] = first.simulation.frames_per_sec
        if first.cloth.is_mesh:
            ds.describe_mesh_cloth(description, first.cloth)
        data.meta = description
        sampled = samples is not None
        data.splits = {r.id: M.split_of(r.id, r.params, sampled, fractions, split_seed) for r in runs}
    try:
        records, images, lost = _run_all(runs, scenes, settings, data, out, kind, frame_list, last, every, seed,
                                 cell_size, video, workers, scheduler, progress, views, tuple(channel_list),
                                 os.fspath(data.out.resolve()) if direct and not remote and data is not None
                                 else (os.fspath(out) if remote else None))
        if data is not None and data.has_definition():
            data.write_meta(data.meta)  # also when a resume had nothing left to run
    finally:
        if data is not None:
            data.close()
    ordered = [records[r.id] for r in runs]
    if kind == "sheet":
        fps = scenes[runs[0].id].simulation.frames_per_sec
        spec = S.plan(runs, space, frame_list, fps, samples is not None)
        picture = S.compose(spec, images, cell_size)
        from PIL import Image

        with atomic_output(out, label=os.fspath(out)) as tmp:
            Image.fromarray(picture).save(tmp, format="PNG", optimize=True)
    if report:
        _summary(ordered, time.perf_counter() - start, out, lost)
    return ordered


def _run_all(runs: list[P.Run], scenes: dict[str, Scene], settings: dict[str, Any], data: ds.Dataset | None,
             out: Any, kind: str, frame_list: list[int], last: int, every: int, seed: int | None,
             cell_size: tuple[int, int], video: bool, workers: int | None, scheduler: str | None,
             progress: bool, views: int = 0, channels: tuple[str, ...] = (),
             write_to: str | None = None) -> tuple[dict[str, dict[str, Any]], dict[tuple[str, int], np.ndarray | None], int]:
    """Run every run not finished yet; return the records by id, a contact sheet's cells, and the
    number of runs lost with a worker."""
    finished: dict[str, dict[str, Any]] = {}
    if data is not None:
        if data.resumed:
            n_samples = len(sample_frames(last, every))
            expected = {r.id: {"params": json.loads(json.dumps(r.params)), "samples": n_samples} for r in runs}
            finished = data.finished(expected)

    samples_msaa = {rid: s.samples for rid, s in settings.items()}
    tasks = [Task(id=r.id, scene=scenes[r.id], frames=last, every=every, positions=kind == "dataset",
                  cells=tuple(frame_list) if kind == "sheet" else (), video=bool(video),
                  settings=settings.get(r.id), size=cell_size, samples=samples_msaa.get(r.id, 4), threads=1,
                  views=views, channels=channels, view_seed=(seed or 0, r.index, 1), write_to=write_to)
             for r in runs if r.id not in finished]
    by_id = {r.id: r for r in runs}
    records: dict[str, dict[str, Any]] = {rid: {**rec, "skipped": True} for rid, rec in finished.items()}
    images: dict[tuple[str, int], np.ndarray | None] = {}
    lost = 0

    def finish(result: dict[str, Any]) -> None:
        run = by_id[result["id"]]
        record = {"id": run.id, "params": run.params, "seed": seed, "status": result["status"],
                  "error": result["error"], "path": None, "frames": last, "seconds": round(result["seconds"], 3)}
        if data is not None:
            if result["status"] == "done":
                if result.get("written"):  # the worker wrote the files into OUT itself
                    record["path"] = result["written"]
                else:
                    sc = scenes[run.id]
                    arrays = ds.run_arrays(result["positions"], result["nw"], result["nh"], result["pinned"], sc,
                                           sample_frames(last, every), P.scene_json(sc), result.get("surface"),
                                           result.get("rest"))
                    fps = sc.simulation.frames_per_sec / every
                    record["path"] = data.write_run(run.id, arrays, result["video"], fps)
                    if result.get("views") is not None:
                        data.write_views(run.id, result["views"], sample_frames(last, every))
            record["split"] = data.splits[run.id]
            if views:
                record["render_seconds"] = round(result.get("render_seconds", 0.0), 3)
            data.append(record)
        else:
            for f in frame_list:
                images[(run.id, f)] = result["cells"].get(f) if result["status"] == "done" else None
        records[run.id] = {**record, "skipped": False}

    if tasks:
        from .engines import open_executor
        from .runner import run as run_one

        bar = _bar(len(tasks), progress)
        n = min(workers or _workers_default(), len(tasks)) if scheduler is None else None
        try:
            with open_executor(n, scheduler) as executor:
                if data is not None:
                    data.start()  # once the workers are there: a cluster that cannot be reached writes nothing
                futures = {executor.submit(run_one, t): t for t in tasks}
                for future in concurrent.futures.as_completed(futures):
                    task = futures.pop(future)  # drop the result with it once written: memory stays flat
                    try:
                        result = future.result()
                        if result.get("write_failed"):
                            raise _WriteFailed(result["error"])
                    except Exception as exc:  # noqa: BLE001 - the run itself never raises (runner.run)
                        # A local worker that died (BrokenProcessPool), a Dask worker lost with the
                        # run (KilledWorker), a transfer that failed: the run has no result, which
                        # is not a property of its parameters. It is not recorded, so the same
                        # command runs it again.
                        lost += 1
                        records[task.id] = {"id": task.id, "params": by_id[task.id].params, "seed": seed,
                                            "status": "failed", "path": None, "frames": last, "seconds": 0.0,
                                            "error": _lost_reason(exc), "skipped": False, "lost": True}
                    else:
                        finish(result)
                    bar.update(1)
        finally:
            bar.close()
    return records, images, lost


class _WriteFailed(Exception):
    """A worker ran the run but could not write its files into OUT."""


def _lost_reason(exc: BaseException) -> str:
    if isinstance(exc, _WriteFailed):
        why = str(exc)
    elif isinstance(exc, concurrent.futures.process.BrokenProcessPool):
        why = "the worker process running it died"
    else:
        why = " ".join(f"{type(exc).__name__}: {exc}".split())
    return f"{why} (not recorded: the same command runs it again)"


def _workers_default() -> int:
    from .engines import default_workers

    return default_workers()


def _bar(total: int, show: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc="sweep", unit="run", disable=not (show and sys.stderr.isatty()),
                leave=False, file=sys.stderr)


def _summary(records: list[dict[str, Any]], seconds: float, out: Any, lost: int) -> None:
    done = sum(1 for r in records if r["status"] == "done" and not r["skipped"])
    failed = sum(1 for r in records if r["status"] == "failed" and not r["skipped"] and not r.get("lost"))
    skipped = sum(1 for r in records if r["skipped"])
    ran = done + failed
    rate = 60.0 * ran / seconds if seconds > 0 else 0.0
    lost_text = f", {lost} lost" if lost else ""
    print(f"sweep: {len(records)} runs: {done} done, {failed} failed{lost_text}, {skipped} skipped "
          f"in {seconds:.1f} s ({rate:.1f} runs/min); wrote {os.fspath(out)}", file=sys.stderr)
    for r in records:
        if r["status"] == "failed" and not r["skipped"]:
            print(f"sweep: {r['id']} {'lost' if r.get('lost') else 'failed'}: {r['error']}", file=sys.stderr)
    if lost:
        print(f"sweep: {lost} runs were lost with a worker that died; run the same command again to finish them",
              file=sys.stderr)
