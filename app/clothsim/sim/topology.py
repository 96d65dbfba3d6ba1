"""What a cloth is made of, grid or mesh: its rest positions, its springs and its points' masses.

A grid cloth (the spec's) has points on a regular grid, springs by the spec's offsets and one
mass for every point (width x height x density / N). A mesh cloth (``cloth.mesh``) has the OBJ's
welded vertices as points, springs from its edges, faces and neighbouring triangles
(:mod:`clothsim.clothmesh`), and each point a mass of a third of each adjacent triangle's area
times the density.
"""

from __future__ import annotations

import numpy as np

from ..cloth import STRUCTURAL, Springs, all_springs, grid_positions
from ..scene import ClothSpec


def rest_positions(cloth: ClothSpec, seed: int) -> np.ndarray:
    """The cloth's starting positions, (N, 3) float64 (a new array)."""
    if cloth.mesh is not None:
        return np.array(cloth.mesh.points, dtype=np.float64)
    return grid_positions(cloth, seed)


def cloth_springs(cloth: ClothSpec, positions: np.ndarray) -> Springs:
    """Every spring of the cloth, the three families, rest lengths measured from ``positions``."""
    if cloth.mesh is None:
        return all_springs(cloth.num_width_points, cloth.num_height_points, positions)
    m = cloth.mesh
    i = np.ascontiguousarray(m.spring_i, dtype=np.int32)
    j = np.ascontiguousarray(m.spring_j, dtype=np.int32)
    rest = np.linalg.norm(positions[i] - positions[j], axis=1)
    return Springs(i=i, j=j, rest=rest, kind=np.ascontiguousarray(m.spring_kind, dtype=np.int8))


def point_masses(cloth: ClothSpec) -> np.ndarray:
    """Each point's mass (kg), (N,) float64."""
    if cloth.mesh is None:
        return np.full(cloth.num_points, mean_mass(cloth))
    return cloth.density * np.asarray(cloth.mesh.point_area, dtype=np.float64)


def mean_mass(cloth: ClothSpec) -> float:
    """The mean mass of a point (kg): for a grid, every point's (the spec's formula)."""
    if cloth.mesh is None:
        return cloth.width * cloth.height * cloth.density / cloth.num_points
    return cloth.density * float(np.sum(cloth.mesh.point_area)) / cloth.num_points


def spacing(cloth: ClothSpec, springs: Springs) -> tuple[float, float]:
    """The spacing of the points along the cloth's two directions: the grid's (width / nw,
    height / nh, the spec's hash cell is three of each), or for a mesh the mean rest length of its
    structural springs, both ways."""
    if cloth.mesh is None:
        return cloth.width / cloth.num_width_points, cloth.height / cloth.num_height_points
    rest = springs.rest[springs.kind == STRUCTURAL]
    edge = float(rest.mean()) if rest.size else 1.0
    return edge, edge
