"""``clothsim bench stability``: where each integrator blows up, and how well the explicit bound
dt < 2/omega_max (Gershgorin estimate, :mod:`clothsim.sim.guard`) predicts it.

Sweep ks (log-spaced 10..1e7), density (log-spaced 1..1000) and substeps per frame (powers of 2)
on a small pinned2-style cloth with the spec's damping, Provot's limit off (it hides the spring
instability by clamping stretch) and no contacts. A run is "blew up" when a position becomes
non-finite or the kinetic energy exceeds the guard's bound (4 x the work gravity has done + 2 J/kg);
otherwise "stable". The dynamics depend on ks and density only through ks/density, so the map's
x axis is ks/density and every density lands on it.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from ..atomic import atomic_output
from .plotting import add_study_options, save_grid_figure, study_sizes
from ..errors import ClothsimError, SimulationBlowUp
from ..scene import INTEGRATORS, Scene, load_scene


def base_scene(grid: int) -> Scene:
    """A ``grid`` x ``grid`` cloth pinned at two corners, no Provot, no self-collision."""
    scene = load_scene("pinned2")
    scene = scene.with_cloth(num_width_points=grid, num_height_points=grid, pinned=((0, 0), (grid - 1, 0)))
    return scene.with_simulation(max_stretch=None, self_collision="off")


def run_point(scene: Scene, frames: int) -> tuple[bool, str]:
    """(stable, reason) of one run of ``frames`` frames."""
    from ..sim import Simulation

    sim = Simulation(scene)
    try:
        sim.step(frames)
    except SimulationBlowUp as exc:
        return False, str(exc).split(": ", 1)[1].split(" (integrator=")[0]
    return True, ""


def sweep(integrators: tuple[str, ...], ks_values: list[float], densities: list[float], substeps: list[int],
          grid: int, end_time: float, log=print) -> list[dict]:  # noqa: ANN001
    """Every run of the sweep as dicts (integrator, ks, density, substeps, stable, reason, predicted)."""
    from ..sim.guard import stable_dt, substeps_for_dt

    base = base_scene(grid)
    frames = max(1, round(end_time * base.simulation.frames_per_sec))
    out = []
    for name in integrators:
        t0 = time.perf_counter()
        for ks in ks_values:
            for rho in densities:
                sc = base.with_cloth(ks=float(ks), density=float(rho))
                predicted = substeps_for_dt(sc, stable_dt(sc))
                for n in substeps:
                    ok, why = run_point(sc.with_simulation(integrator=name, simulation_steps=n), frames)
                    out.append({"integrator": name, "ks": float(ks), "density": float(rho), "substeps": n,
                                "stable": ok, "reason": why, "predicted_substeps": predicted})
        log(f"{name}: {sum(1 for r in out if r['integrator'] == name)} runs in {time.perf_counter() - t0:.1f} s")
    return out


def measured_edges(runs: list[dict], name: str) -> list[tuple[float, float, int | None, int]]:
    """Per (ks, density): smallest substep count from which every larger tested count was stable."""
    edges = []
    keys = sorted({(r["ks"], r["density"]) for r in runs if r["integrator"] == name})
    for ks, rho in keys:
        pts = sorted((r for r in runs if r["integrator"] == name and r["ks"] == ks and r["density"] == rho),
                     key=lambda r: r["substeps"])
        edge = None
        for r in reversed(pts):
            if not r["stable"]:
                break
            edge = r["substeps"]
        edges.append((ks, rho, edge, pts[0]["predicted_substeps"]))
    return edges


def summarise(runs: list[dict], integrators: tuple[str, ...], substeps: list[int]) -> dict:
    """Per integrator: counts, and for explicit ones how the bound compares with the measured edge."""
    from ..sim.guard import EXPLICIT_INTEGRATORS

    summary = {}
    for name in integrators:
        mine = [r for r in runs if r["integrator"] == name]
        s = {"runs": len(mine), "blew_up": sum(1 for r in mine if not r["stable"])}
        if name in EXPLICIT_INTEGRATORS:
            edges = [(m, p) for _, _, m, p in measured_edges(runs, name)]
            inside = [(m, p) for m, p in edges if m is not None and p <= max(substeps)]
            # The sweep resolves substeps only to powers of 2: compare on that grid.
            rounded = [(m, 2 ** math.ceil(math.log2(p))) for m, p in inside]
            s["points_compared"] = len(rounded)
            s["bound_exact"] = sum(1 for m, p in rounded if m == p)
            s["bound_conservative"] = sum(1 for m, p in rounded if m < p)
            s["bound_optimistic"] = sum(1 for m, p in rounded if m > p)
            ratios = [p / m for m, p in inside]
            s["median_predicted_over_measured"] = float(np.median(ratios)) if ratios else None
            stable_unpredicted = [r for r in mine if r["stable"] and r["substeps"] < r["predicted_substeps"]]
            s["stable_below_bound"] = len(stable_unpredicted)
            s["blew_up_above_bound"] = sum(1 for r in mine if not r["stable"]
                                           and r["substeps"] >= r["predicted_substeps"])
        summary[name] = s
    return summary


def plot_map(runs: list[dict], integrators: tuple[str, ...], grid: int, fps: float, dest: str) -> None:
    """Per integrator: stable/blew-up markers over (ks/density, substeps) with the explicit bound line."""
    import matplotlib

    from ..sim.guard import stable_dt

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(len(integrators), 2)
    rows = math.ceil(len(integrators) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.0 * cols, 3.8 * rows), squeeze=False)
    ratio = np.array([r["ks"] / r["density"] for r in runs])
    unit = base_scene(grid).with_cloth(ks=1.0, density=1.0)
    w1 = 2.0 / stable_dt(unit)  # omega_max at ks/density = 1; scales as sqrt(ks/density)
    xs = np.logspace(math.log10(ratio.min()) - 0.3, math.log10(ratio.max()) + 0.3, 200)
    bound = 1.0 / (fps * 2.0 / (w1 * np.sqrt(xs)))
    top = max(r["substeps"] for r in runs)
    for ax, name in zip(axes.flat, integrators):
        mine = [r for r in runs if r["integrator"] == name]
        ok = [r for r in mine if r["stable"]]
        bad = [r for r in mine if not r["stable"]]
        ax.scatter([r["ks"] / r["density"] for r in ok], [r["substeps"] for r in ok], marker="o", s=22,
                   facecolors="none", edgecolors="tab:green", label="stable")
        ax.scatter([r["ks"] / r["density"] for r in bad], [r["substeps"] for r in bad], marker="x", s=22,
                   color="tab:red", label="blew up")
        ax.plot(xs, bound, "k--", lw=1, label="explicit bound dt = 2/omega_max")
        ax.set_xscale("log")
        ax.set_yscale("log", base=2)
        ax.set_ylim(0.7, top * 1.5)
        ax.set_title(name)
        ax.set_xlabel("ks / density  (N/m per kg/m^2)")
        ax.set_ylabel("substeps per frame")
        ax.legend(fontsize=7, loc="upper left")
    save_grid_figure(fig, axes, len(integrators), dest)


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench stability``."""
    p = bench_sub.add_parser("stability", help="stability map over ks, density and substeps vs the explicit bound")
    p.add_argument("--quick", action="store_true", help="coarse sweep: 4 ks x 2 densities x substeps 1..16, 0.2 s")
    p.add_argument("--ks-count", type=int, default=None, help="log-spaced ks values in 10..1e7 (default 7)")
    p.add_argument("--density-count", type=int, default=None, help="log-spaced densities in 1..1000 (default 4)")
    p.add_argument("--max-substeps", type=int, default=None, help="largest substeps per frame (default 64)")
    p.add_argument("--grid", type=int, default=10, help="points per side (default 10)")
    p.add_argument("--end-time", type=float, default=None, help="simulated seconds per run (default 0.5)")
    add_study_options(p, "map", "stability_map.png", "runs and summary")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Sweep, print the summary, write the map (and JSON)."""
    from ..sim.guard import ENERGY_FACTOR, ENERGY_SLACK, EXPLICIT_INTEGRATORS

    n_ks, n_rho, max_sub, end_time = study_sizes(args, ks_count=(4, 7), density_count=(2, 4), max_substeps=(16, 64),
                                                 end_time=(0.2, 0.5))
    if n_ks < 1 or n_rho < 1 or max_sub < 1 or args.grid < 3 or not end_time > 0:
        raise ClothsimError("bench stability: counts and max-substeps must be >= 1, grid >= 3, end-time > 0")
    ks_values = list(np.logspace(1, 7, n_ks)) if n_ks > 1 else [5000.0]
    densities = list(np.logspace(0, 3, n_rho)) if n_rho > 1 else [150.0]
    substeps = [2**i for i in range(int(math.log2(max_sub)) + 1)]
    integrators = tuple(args.integrators or INTEGRATORS)
    print(f"{args.grid}x{args.grid} cloth pinned at 2 corners, spec damping, no Provot, {end_time:g} s per run; "
          f"blew up = non-finite or kinetic energy > {ENERGY_FACTOR:g} x gravity work + {ENERGY_SLACK:g} J/kg")
    runs = sweep(integrators, ks_values, densities, substeps, args.grid, end_time)
    summary = summarise(runs, integrators, substeps)
    print(f"{'integrator':<18}{'runs':>6}{'blew up':>9}   explicit bound vs measured edge (powers of 2)")
    for name in integrators:
        s = summary[name]
        line = f"{name:<18}{s['runs']:>6}{s['blew_up']:>9}   "
        if name in EXPLICIT_INTEGRATORS:
            med = s["median_predicted_over_measured"]
            line += (f"{s['points_compared']} edges: {s['bound_exact']} exact, {s['bound_conservative']} conservative, "
                     f"{s['bound_optimistic']} optimistic; predicted/measured substeps median "
                     f"{'-' if med is None else format(med, '.2f')}; {s['blew_up_above_bound']} blow-ups at or "
                     f"above the bound")
        else:
            line += "no step bound (implicit)"
        print(line)
    plot_map(runs, integrators, args.grid, base_scene(args.grid).simulation.frames_per_sec, args.png)
    print(f"wrote {args.png}")
    if args.json:
        with atomic_output(args.json) as tmp:
            tmp.write_text(json.dumps({"runs": runs, "summary": summary,
                                       "blow_up_bound": {"energy_factor": ENERGY_FACTOR,
                                                         "energy_slack_j_per_kg": ENERGY_SLACK},
                                       "grid": args.grid, "end_time": end_time}, indent=1))
        print(f"wrote {args.json}")
    return 0
