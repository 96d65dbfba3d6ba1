"""What culling hidden triangles could give the displaced looks on llvmpipe:
``python tests/tools/culling_bound.py --scene sphere``.

llvmpipe shades every fragment it rasterises under multisampling, whatever its depth, so the
displaced looks pay for every layer of their puffed folds (docs/performance-rendering.md, "Displaced looks").
This measures what drawing only the triangles that can be seen would give, on draped states of a
scene (frames 65, 70, ... after 60 warm-up frames): a triangle counts as seen where its id wins the
depth test in an id pass without multisampling (the look's own vertex stage, a fragment stage that
writes ``gl_PrimitiveID``), at the image's size and at 4x its side (16 samples a pixel, close to
free culling). For each the script prints how many triangles are kept, how many pixels of the
4x multisampled image differ from the full drawing (an id pass samples pixel centres, the image
four other points a pixel, so a triangle seen only there is lost), the same with the kept set
grown by every triangle that shares a corner with a kept one, and the CPU milliseconds a frame
(every thread of the process) of Blinn-Phong, of the look drawn whole, of the look drawn from each
kept set, and of the id pass at the image's size, alternated round by round.

A measurement: it writes the kept triangles into the renderer's own index buffers (padded with
empty triangles) and puts the full ones back after each frame, with the renderer's own id pass
(render/seen.py, which is the "seen at the image's size" row) turned off.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from clothsim.render import mesh
from clothsim.render.pipeline import Snapshot
from clothsim.render.programs import LOOKS, read_source
from clothsim.render.renderer import Renderer
from clothsim.scene import load_scene
from clothsim.sim import Simulation

#: Ids of the sphere's triangles start here (the cloth's are its triangles' indices).
SPHERE = 0x800000

#: The id pass's fragment stage: the triangle's index in its draw call, the sphere's (the one
#: drawn with a translated model matrix) offset by SPHERE, as three 8-bit channels.
ID_FRAGMENT = """#version 330 core
uniform mat4 u_model;
out vec4 out_color;
void main() {
    bool sphere = u_model[3].x != 0.0 || u_model[3].y != 0.0 || u_model[3].z != 0.0;
    uint id = uint(gl_PrimitiveID) + (sphere ? 0x800000u : 0u);
    out_color = vec4(float(id & 255u), float((id >> 8) & 255u), float((id >> 16) & 255u), 255.0) / 255.0;
}
"""


def seen(image: np.ndarray) -> np.ndarray:
    """The ids an id pass's image shows (the background's colour, its corner, left out)."""
    img = image.astype(np.uint32)
    code = img[..., 0] | (img[..., 1] << 8) | (img[..., 2] << 16)
    return np.unique(code[code != code[0, 0]])


def with_neighbours(tris: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """``kept`` triangles of ``tris`` (3T,) and every triangle sharing a corner with one."""
    t = tris.reshape(-1, 3)
    corner = np.zeros(int(t.max()) + 1, dtype=bool)
    corner[t[kept].ravel()] = True
    return np.flatnonzero(corner[t].any(axis=1))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="sphere")
    p.add_argument("--looks", nargs="*", default=["displacement", "custom"])
    p.add_argument("--size", type=int, default=800)
    p.add_argument("--states", type=int, default=12)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--repeats", type=int, default=3, help="renders of each state a round (median over states)")
    args = p.parse_args(argv)
    scene = load_scene(args.scene)
    sim = Simulation(scene)
    sim.step(60)
    states = []
    for _ in range(args.states):
        sim.step(5)
        states.append(Snapshot.of(sim))

    n = args.size
    id_source = (read_source(LOOKS["displacement"][0]), ID_FRAGMENT)
    id_pass = {side: Renderer(side, side, samples=0, sources={"displacement": id_source}) for side in (n, 4 * n)}
    settings = id_pass[n].settings_for(scene)
    renderer = Renderer(n, n, samples=4)
    renderer._picks = False  # every triangle, or those this script chooses (not the renderer's own id pass)
    renderer.render(states[0], args.looks[0], settings)
    cloth = mesh.cloth_triangles(states[0].nw, states[0].nh).astype(np.uint32)
    has_sphere = bool(scene.spheres)
    if has_sphere:
        sphere_ibo = renderer._sphere(settings.sphere_resolution)[1]
        sphere = mesh.sphere_mesh(*settings.sphere_resolution)[1].astype(np.uint32)
    else:
        sphere_ibo, sphere = None, np.zeros(3, dtype=np.uint32)

    kept: dict[str, list[np.ndarray]] = {}
    for side, r in id_pass.items():
        kept[f"seen at {side}"] = [seen(r.render(s, "displacement", settings)) for s in states]
    for r in id_pass.values():
        if r is not id_pass[n]:
            r.release()

    def grown(ids: np.ndarray) -> np.ndarray:
        c, sp = ids[ids < SPHERE], ids[ids >= SPHERE] - SPHERE
        parts = [with_neighbours(cloth, c)]
        if has_sphere and sp.size:
            parts.append(with_neighbours(sphere, sp) + SPHERE)
        return np.concatenate(parts)

    kept[f"seen at {n}, and neighbours"] = [grown(ids) for ids in kept[f"seen at {n}"]]

    def draw_only(ids: np.ndarray) -> None:
        c, sp = ids[ids < SPHERE], ids[ids >= SPHERE] - SPHERE
        a = np.zeros_like(cloth).reshape(-1, 3)
        a[: c.size] = cloth.reshape(-1, 3)[c]
        with renderer.ctx:
            renderer._cloth.tri_ibo.write(a.tobytes())
            if sphere_ibo is not None:
                b = np.zeros_like(sphere).reshape(-1, 3)
                b[: sp.size] = sphere.reshape(-1, 3)[sp]
                sphere_ibo.write(b.tobytes())

    def draw_all() -> None:
        with renderer.ctx:
            renderer._cloth.tri_ibo.write(cloth.tobytes())
            if sphere_ibo is not None:
                sphere_ibo.write(sphere.tobytes())

    print(f"{args.scene}, {n} x {n}, 4x MSAA, {args.states} draped states; {cloth.size // 3} cloth triangles"
          + (f", {sphere.size // 3} sphere triangles" if has_sphere else ""))
    for name, sets in kept.items():
        nc = statistics.median(int((ids < SPHERE).sum()) for ids in sets)
        ns = statistics.median(int((ids >= SPHERE).sum()) for ids in sets)
        print(f"kept, {name}: {nc:.0f} cloth" + (f", {ns:.0f} sphere" if has_sphere else "") + " triangles (median)")
        for look in args.looks:
            differ = []
            for s, ids in zip(states, sets):
                whole = renderer.render(s, look, settings)
                draw_only(ids)
                part = renderer.render(s, look, settings)
                draw_all()
                differ.append(int((whole != part).any(axis=2).sum()))
            print(f"  {look}: pixels differing from the whole drawing, per state: {differ}")

    def cpu_ms(fn: Callable[[Any, int], None]) -> float:
        per_state = []
        for i, s in enumerate(states):
            fn(s, i)
            c0 = time.process_time()
            for _ in range(args.repeats):
                fn(s, i)
            per_state.append((time.process_time() - c0) / args.repeats)
        return 1e3 * statistics.median(per_state)

    def look_from(look: str, sets: list[np.ndarray]) -> Callable[[Any, int], None]:
        def fn(s: Any, i: int) -> None:
            draw_only(sets[i])
            renderer.render(s, look, settings)
            draw_all()
        return fn

    variants: dict[str, Callable[[Any, int], None]] = {"phong": lambda s, i: renderer.render(s, "phong", settings)}
    for look in args.looks:
        variants[f"{look}, whole"] = lambda s, i, look=look: renderer.render(s, look, settings)
        for name, sets in kept.items():
            variants[f"{look}, {name}"] = look_from(look, sets)
    variants[f"id pass at {n}"] = lambda s, i: id_pass[n].render(s, "displacement", settings)
    rows: dict[str, list[float]] = {k: [] for k in variants}
    for _ in range(args.rounds):
        for name, fn in variants.items():
            rows[name].append(cpu_ms(fn))
    phong = statistics.median(rows["phong"])
    print(f"CPU ms a frame (all threads), medians over states, {args.rounds} rounds alternated:")
    for name, values in rows.items():
        m = statistics.median(values)
        print(f"  {name:<44}{m:8.1f}   phong's rate x {phong / m:.2f}   rounds: "
              + ", ".join(f"{v:.1f}" for v in values))
    id_pass[n].release()
    renderer.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
