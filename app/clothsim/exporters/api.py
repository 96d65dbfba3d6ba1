"""`clothsim.export`: simulate and write a USD stage or an OBJ sequence.

The output path picks the format: ``.usd``, ``.usda`` or ``.usdc`` is one USD stage (needs the
``usd`` extra, usd-core); a path with no suffix, a trailing slash, or an existing folder is a
folder of ``cloth_NNNNN.obj`` files plus ``colliders.obj``. Frames ``0, K, 2K, ...`` are exported,
and the last simulated frame N always (so the file's last frame is the state ``clothsim simulate
--frames N`` saves). With ``out_fps`` the clip is resampled to that frame rate instead
(:mod:`.timing`): frame numbers count frames at that rate, and a moment between two simulated
frames gets their linear interpolation. Outputs go through :func:`~clothsim.atomic.atomic_output`: they appear whole
or not at all, and an existing folder is written into only if it holds nothing but an earlier
sequence.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..atomic import atomic_output, check_destination, check_name
from ..errors import ClothsimError
from ..output import _destination
from ..scene import Scene, load_scene
from ..sim import Simulation
from ..sweeps.runner import sample_frames
from ..validate import check, integer
from . import obj, usd
from .geometry import ClothNormals, cloth_geometry, colliders
from .timing import Sample, blend, check_out_fps, exported_samples

__all__ = ["FORMATS", "check_export_output", "export", "export_format", "exported_frames"]

#: ``usd`` (one stage) or ``obj`` (a folder holding an OBJ sequence).
FORMATS = ("usd", "obj")


def export_format(path: str | os.PathLike[str]) -> str:
    """``usd`` or ``obj`` for an output path; one :class:`ClothsimError` line for anything else."""
    text = os.fspath(path)
    if not text:
        raise ClothsimError("output path is empty")
    check_name(text)
    p = Path(text)
    if text.endswith(("/", os.sep)) or not p.suffix:
        return "obj"
    if p.is_dir():
        if p.suffix in usd.SUFFIXES:
            raise ClothsimError(f"{text}: is a folder, not a file; choose a file name "
                                f"(or write {text}/ for an OBJ sequence in that folder)")
        return "obj"
    if p.suffix in usd.SUFFIXES:
        return "usd"
    raise ClothsimError(f"{text}: unsupported output type {p.suffix!r} "
                        "(use .usd, .usda, .usdc, or a folder for an OBJ sequence)")


def check_export_output(path: str | os.PathLike[str]) -> str:
    """Fail fast on an output that could not be written; return its format.

    Meant to run before any simulation: a bad suffix, a missing ``usd`` extra, a folder holding
    files clothsim did not write, a parent that is a file or a folder that cannot be written
    all end here with one line.
    """
    fmt = export_format(path)
    dest, label = _destination(path)
    if fmt == "usd":
        usd.import_pxr(label, dest.suffix)
    check_destination(dest, directory=fmt == "obj", label=label, owned=obj.is_sequence_name)
    return fmt


def exported_frames(start: int, frames: int, every: int) -> list[int]:
    """Frame numbers exported from ``start`` over ``frames`` frames: every ``every``-th, and the last
    (the sweep's sampling rule, shifted to start at ``start``)."""
    return [start + f for f in sample_frames(frames, every)]


def export(simulation_or_scene: Simulation | Scene | str | os.PathLike[str], out: str | os.PathLike[str],
           frames: int = 90, every: int = 1, *, out_fps: float | None = None, progress: bool = False) -> list[int]:
    """Simulate and write the cloth's animation to ``out``; return the frame numbers written.

    ``simulation_or_scene`` is a :class:`~clothsim.Simulation` (run on from its current frame and
    left at the last one; its frame numbers are the time codes), a :class:`~clothsim.Scene`, or a
    scene file / bundled scene name (both start at frame 0). ``frames`` frames are simulated and
    every ``every``-th frame is written, starting with the current one, plus the last frame.
    ``out`` ending in ``.usd``/``.usda``/``.usdc`` is a USD stage (needs ``usd-core``: ``pip
    install 'clothsim[usd]'``); a folder is an OBJ sequence (``cloth_00000.obj``, ...,
    ``colliders.obj``). ``out_fps`` (frames a second) resamples the clip to that rate: frame k
    is the moment k / out_fps s, positions interpolated linearly between simulated frames, every
    ``every``-th such frame written (default: the scene's frames_per_sec, no resampling). The
    returned numbers are the written frames at the output rate. ``progress`` shows a progress
    bar on a terminal.

    Raises :class:`~clothsim.ClothsimError` (one line) for a bad output, count or scene, a missing
    extra, or a simulation that blows up; nothing is written then.
    """
    frames = check(integer(ge=0), frames, "frames")
    every = check(integer(ge=1), every, "every")
    out_fps = check_out_fps(out_fps, "out_fps")
    fmt = check_export_output(out)
    if isinstance(simulation_or_scene, Simulation):
        sim = simulation_or_scene
    else:
        scene = simulation_or_scene if isinstance(simulation_or_scene, Scene) else load_scene(simulation_or_scene)
        sim = Simulation(scene)
    return _write(sim, fmt, out, frames, every, progress, out_fps)


def _write(sim: Simulation, fmt: str, out: str | os.PathLike[str], frames: int, every: int, progress: bool,
           out_fps: float | None = None, field: str = "out_fps") -> list[int]:
    from ..commands import progress as progress_bar

    dest, label = _destination(out)
    scene = sim.scene
    sim_fps = float(scene.simulation.frames_per_sec)
    samples = exported_samples(sim.frame, frames, every, sim_fps, out_fps, field)
    numbers = [s.code for s in samples]
    # Simulated frames whose state a sample needs (one between two frames needs both).
    needed = {s.frame for s in samples} | {s.last_frame for s in samples}
    pending = list(samples)
    interpolates = any(s.weight for s in samples)
    cloth = cloth_geometry(sim)
    normals = ClothNormals(cloth)
    shapes = colliders(scene)
    # Locked, a stage too: it is written for as long as the simulation runs.
    with atomic_output(dest, directory=fmt == "obj", label=label, owned=obj.is_sequence_name, lock=True) as tmp:
        if fmt == "usd":
            writer: obj.ObjSequenceWriter | usd.UsdStageWriter = usd.UsdStageWriter(
                tmp, label, cloth, shapes, usd.stage_doc(Path(scene.path).name))
        else:
            writer = obj.ObjSequenceWriter(tmp, cloth, shapes)
        before: tuple[np.ndarray, float] | None = None  # the last needed frame's state and time

        def emit(sample: Sample) -> None:
            if sample.weight == 0.0:  # on a simulated frame: its state as it is
                positions, seconds = sim.positions, sim.time
            else:
                assert before is not None
                positions = blend(before[0], sim.positions, sample.weight)
                seconds = before[1] + sample.weight * (sim.time - before[1])
            writer.frame(sample.code, positions.astype(np.float32), normals(positions), seconds)

        def reached() -> None:
            nonlocal before
            while pending and pending[0].last_frame == sim.frame:
                emit(pending.pop(0))
            if interpolates and sim.frame in needed:
                before = (sim.positions.copy(), sim.time)

        reached()
        with progress_bar(frames, "export", show=progress) as bar:
            for _ in range(frames):
                sim.step()
                bar.update()
                reached()
        writer.finish(numbers[0], numbers[-1], sim_fps if out_fps is None else float(out_fps))
    return numbers

