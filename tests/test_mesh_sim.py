"""A cloth made from a triangle mesh, simulated: each point falls with gravity whatever its mass,
the springs move no centre of mass, Provot's limit holds on the structural springs, every
integrator and self-collision mode runs it, the same bits on any number of threads, and a
colliding, folding mesh cloth does not pass through itself in the contact mode."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from clothsim.cloth import STRUCTURAL
from clothsim.objshapes import sheet_obj, tube_obj
from clothsim.scene import scene_from_dict
from clothsim.sim import Simulation


def mesh_scene(tmp_path, obj: str, *, cloth: dict | None = None, simulation: dict | None = None, **objects):
    path = tmp_path / "cloth.obj"
    path.write_text(obj)
    body = {"mesh": {"path": str(path)}, "thickness": 0.01, "damping": 0.2, "density": 150.0, "ks": 5000.0}
    body.update(cloth or {})
    sim = {"self_collision": "off"}
    sim.update(simulation or {})
    return scene_from_dict({"cloth": body, "simulation": sim, **objects}, str(tmp_path / "scene.json"))


def skewed_sheet() -> str:
    """A sheet of triangles of unequal areas (the quads' columns of growing width): its points'
    masses differ."""
    lines = sheet_obj(1.0, 1.0, 7, 6, quads=False).splitlines()
    out = []
    for line in lines:
        if line.startswith("v "):
            _, x, y, z = line.split()
            x = float(x) ** 2  # columns grow towards x = 1
            out.append(f"v {x!r} {y} {z}")
        else:
            out.append(line)
    return "\n".join(out) + "\n"


def test_points_of_unequal_mass_fall_together(tmp_path):
    # no damping and no stretch: every point falls as the others, whatever its mass
    sim = Simulation(mesh_scene(tmp_path, skewed_sheet(), cloth={"damping": 0.0},
                                simulation={"max_stretch": None}))
    masses = sim.point_mass
    assert masses.max() > 2.0 * masses.min()
    start = sim.positions.copy()
    sim.step(3)
    drop = sim.positions - start
    assert np.ptp(drop[:, 1]) < 1e-12
    assert np.abs(drop[:, [0, 2]]).max() < 1e-12
    assert drop[0, 1] < -0.0005


def test_springs_move_no_centre_of_mass(tmp_path):
    # stretched, weightless, undamped: the springs pull the points inward, the mass-weighted
    # centre stays where it was
    scene = mesh_scene(tmp_path, skewed_sheet(), cloth={"damping": 0.0, "mesh": {"path": "cloth.obj", "scale": 1.0}},
                       simulation={"gravity": [0, 0, 0], "max_stretch": None})
    sim = Simulation(scene)
    sim.positions[:] = sim.positions * 1.05
    sim.last_positions[:] = sim.positions
    m = sim.point_mass
    before = (m[:, None] * sim.positions).sum(0) / m.sum()
    sim.step(5)
    after = (m[:, None] * sim.positions).sum(0) / m.sum()
    assert np.abs(sim.positions - sim.last_positions).max() > 1e-6  # it moved
    assert np.abs(after - before).max() < 1e-12


def test_mass_is_density_times_area(tmp_path):
    sim = Simulation(mesh_scene(tmp_path, skewed_sheet(), cloth={"density": 120.0}))
    assert sim.point_mass.sum() == pytest.approx(120.0 * 1.0 * 1.0, rel=1e-12)
    assert sim.mass == pytest.approx(sim.point_mass.mean(), rel=1e-12)


@pytest.mark.parametrize("integrator", ["verlet", "symplectic_euler", "implicit_euler", "xpbd"])
def test_every_integrator_hangs_a_skirt(tmp_path, integrator):
    # a tube pinned at its top ring hangs: it sags, by no more than the stretch Provot allows, and
    # the structural springs stay within the limit
    obj = tube_obj(0.3, 0.5, 16, 6)
    text = [ln for ln in obj.splitlines() if ln.startswith("v ")]
    top = [i for i, ln in enumerate(text) if float(ln.split()[2]) >= 0.5 - 1e-9]
    damping = "rate" if integrator == "verlet" else "spec"
    sim = Simulation(mesh_scene(tmp_path, obj, cloth={"pinned_vertices": top, "ks": 500.0},
                                simulation={"integrator": integrator, "damping_mode": damping}))
    start = sim.positions.copy()
    sim.step(20)
    pos = sim.positions
    assert np.isfinite(pos).all()
    assert np.array_equal(pos[sim.pinned], start[sim.pinned])
    sp = sim.springs
    structural = sp.kind == STRUCTURAL
    length = np.linalg.norm(pos[sp.i] - pos[sp.j], axis=1)
    # one Gauss-Seidel sweep of Provot's limit a substep: a later correction may stretch an earlier
    # spring again, by little
    assert (length[structural] <= 1.1 * sp.rest[structural] * 1.001).all()
    assert pos[:, 1].min() < start[:, 1].min() - 0.001  # it sagged
    assert pos[:, 1].min() > start[:, 1].min() - 0.1


def test_same_bits_on_one_and_two_threads(tmp_path):
    obj = tube_obj(0.3, 0.5, 16, 6)
    runs = []
    for threads in (1, 2):
        sim = Simulation(mesh_scene(tmp_path, obj, cloth={"pinned_vertices": [0, 1, 2]},
                                    simulation={"self_collision": "spec"}))
        previous = numba.get_num_threads()
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        try:
            sim.step(6)
        finally:
            numba.set_num_threads(previous)
        runs.append(sim.positions.copy())
    assert np.array_equal(runs[0], runs[1])


@pytest.mark.parametrize("mode", ["spec", "grid", "contact"])
def test_self_collision_modes_run(tmp_path, mode):
    sim = Simulation(mesh_scene(tmp_path, sheet_obj(0.6, 0.6, 12, 12), simulation={"self_collision": mode}))
    sim.step(4)
    assert np.isfinite(sim.positions).all()


def test_a_mesh_cloth_on_a_sphere_does_not_pass_through_it_or_itself(tmp_path):
    # a sheet falls on a ball and folds around it; in the contact mode it never crosses itself
    scene = mesh_scene(tmp_path, sheet_obj(0.8, 0.8, 16, 16),
                       cloth={"mesh": {"path": "cloth.obj", "translate": [-0.4, 0.62, -0.4]}},
                       simulation={"self_collision": "contact"},
                       sphere={"origin": [0.0, 0.3, 0.0], "radius": 0.25, "friction": 0.3},
                       plane={"point": [0, 0, 0], "normal": [0, 1, 0], "friction": 0.5})
    sim = Simulation(scene)
    for _ in range(40):
        sim.step(1)
        assert sim.crossings() == 0
        d = np.linalg.norm(sim.positions - np.array([0.0, 0.3, 0.0]), axis=1)
        assert d.min() >= 0.25 - 1e-5  # the ball puts a point back on its surface
    assert sim.positions[:, 1].min() < 0.3  # it draped below the ball's centre


def test_wind_and_moving_pins_drive_a_mesh_cloth(tmp_path):
    # a sheet hung by two vertices that move up, in a wind across it: the pins follow their
    # track exactly and the cloth is blown downwind
    obj = sheet_obj(0.5, 0.5, 10, 10)
    scene = mesh_scene(tmp_path, obj, cloth={"mesh": {"path": "cloth.obj", "rotation": [90, 0, 0],
                                                      "translate": [0, 1, 0]},
                                             "pinned_vertices": [0, 9], "pin_motion": {"velocity": [0, 0.5, 0]},
                                             "density": 1.0},  # light, as cloth in a wind is
                       simulation={"self_collision": "spec"}, wind={"velocity": [0, 0, 4]})
    sim = Simulation(scene)
    start = sim.positions.copy()
    sim.step(18)  # 0.2 s
    pins = sim.pinned
    assert np.allclose(sim.positions[pins] - start[pins], [0, 0.1, 0], atol=1e-12)
    assert np.ptp(start[:, 2]) < 1e-12  # the sheet stood across the wind
    assert sim.positions[~pins, 2].mean() > start[~pins, 2].mean() + 0.005


def test_the_blow_up_guard_knows_a_mesh_cloths_lightest_point(tmp_path):
    from clothsim.sim.guard import omega_max

    scene = mesh_scene(tmp_path, skewed_sheet())
    sim = Simulation(scene)
    sp = sim.springs
    k = np.where(sp.kind == 2, 0.2, 1.0) * scene.cloth.ks
    total = np.bincount(sp.i, k, sim.num_points) + np.bincount(sp.j, k, sim.num_points)
    assert omega_max(scene) == pytest.approx(np.sqrt(2.0 * (total / sim.point_mass).max()), rel=1e-12)


def renumbered(obj: str, seed: int) -> str:
    """``obj`` (v and vt lines one for one, faces ``v/vt``) with its vertices in a random order."""
    lines = obj.splitlines()
    verts = [ln for ln in lines if ln.startswith("v ")]
    uvs = [ln for ln in lines if ln.startswith("vt ")]
    order = np.random.default_rng(seed).permutation(len(verts))  # new vertex k is old order[k]
    new = np.argsort(order)
    faces = ["f " + " ".join(f"{new[int(c.split('/')[0]) - 1] + 1}/{new[int(c.split('/')[0]) - 1] + 1}"
                             for c in ln.split()[1:]) for ln in lines if ln.startswith("f ")]
    return "\n".join([verts[k] for k in order] + [uvs[k] for k in order] + faces) + "\n"


@pytest.mark.parametrize("shuffle", [False, True])
def test_streams_and_lists_give_each_spring_its_hooke_force(tmp_path, shuffle):
    # row by row, the springs fall on a few offsets (streams); renumbered at random, most do not
    # (lists): either way each point gets m/m_p (m_p g + the sum of its springs' Hooke forces)
    from clothsim.sim.passes.meshsprings import add_spring_forces
    from clothsim.sim.passes.springs import accumulate_forces

    obj = sheet_obj(1.0, 0.8, 12, 10, quads=False)
    sim = Simulation(mesh_scene(tmp_path, renumbered(obj, 3) if shuffle else obj))
    st = sim.plan.st
    streamed = int(np.count_nonzero(st.k))
    total = sim.springs.i.shape[0]
    assert st.mesh.si.shape[0] + streamed == total
    assert (streamed < 0.3 * total) if shuffle else (streamed > 0.9 * total)
    rng = np.random.default_rng(1)
    st.pos[:] += rng.normal(0.0, 0.01, st.pos.shape)
    accumulate_forces(st.pos, st.forces, (st.offsets, st.k, st.spring_rest, st.buf), st.mass, st.gravity)
    add_spring_forces(st.mesh, st.pos, st.forces)
    x = st.pos.T
    i, j = sim.springs.i, sim.springs.j
    e = x[j] - x[i]
    d = np.linalg.norm(e, axis=1)
    ks = np.where(sim.springs.kind == 2, 0.2, 1.0) * 5000.0
    f = (ks * (d - sim.springs.rest) / d)[:, None] * e
    want = sim.point_mass[:, None] * st.gravity[None, :]
    np.add.at(want, i, f)
    np.add.at(want, j, -f)
    want *= (sim.mass / sim.point_mass)[:, None]
    assert np.abs(st.forces.T - want).max() < 1e-9 * np.abs(want).max()


def test_implicit_euler_solves_with_each_points_own_mass(tmp_path):
    # one substep of backward Euler, linearised, from rest on a stretched sheet of unequal masses:
    # (M + dt^2 K) dv = dt F with M the points' own masses, solved here densely
    scene = mesh_scene(tmp_path, skewed_sheet(), cloth={"damping": 0.0},
                       simulation={"gravity": [0, -9.8, 0], "max_stretch": None, "integrator": "implicit_euler",
                                   "simulation_steps": 1, "frames_per_sec": 90})
    sim = Simulation(scene)
    rng = np.random.default_rng(2)
    sim.positions[:] = sim.positions * 1.03 + rng.normal(0.0, 0.003, sim.positions.shape)
    sim.last_positions[:] = sim.positions
    x0 = sim.positions.copy()
    m = sim.point_mass
    assert m.max() > 2.0 * m.min()
    n, dt = len(m), 1.0 / 90
    i, j, rest = sim.springs.i, sim.springs.j, sim.springs.rest
    ks = np.where(sim.springs.kind == 2, 0.2, 1.0) * 5000.0
    e = x0[j] - x0[i]
    length = np.linalg.norm(e, axis=1)
    d = e / length[:, None]
    force = m[:, None] * np.array([0.0, -9.8, 0.0])
    f = (ks * (length - rest))[:, None] * d
    np.add.at(force, i, f)
    np.add.at(force, j, -f)
    big_k = np.zeros((3 * n, 3 * n))
    for s in range(len(i)):
        t = max(0.0, 1.0 - rest[s] / length[s])
        block = ks[s] * ((1 - t) * np.outer(d[s], d[s]) + t * np.eye(3))
        a, b = 3 * i[s], 3 * j[s]
        big_k[a:a + 3, a:a + 3] += block
        big_k[b:b + 3, b:b + 3] += block
        big_k[a:a + 3, b:b + 3] -= block
        big_k[b:b + 3, a:a + 3] -= block
    dv = np.linalg.solve(np.diag(np.repeat(m, 3)) + dt * dt * big_k, dt * force.ravel())
    want = x0 + dt * dv.reshape(n, 3)
    sim.step(1)
    moved = np.abs(want - x0).max()
    assert np.abs(sim.positions - want).max() < 1e-6 * moved
