"""The cloth grid as struct-of-arrays: point positions, pins, springs of three families, and the
triangles and texture coordinates every mesh of it (renderer, exports, datasets) uses.

A cloth read from an OBJ (``cloth.mesh``, :mod:`clothsim.clothmesh`) has no grid: only
:func:`pinned_mask` and :func:`cloth_surface` here serve both kinds.

Index convention (the spec's row-major order): point ``(x_index, y_index)`` is
``y_index * num_width_points + x_index``. Springs are stored family by family and, inside a
family, direction by direction in row-major order of their second end point; that order is also
the order of the Gauss-Seidel passes (Provot), a choice the spec leaves open.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scene import HORIZONTAL, ClothSpec

STRUCTURAL = 0
SHEARING = 1
BENDING = 2
FAMILY_NAMES = ("structural", "shearing", "bending")

# (family, dx, dy): the spring joins point (x, y) to point (x - dx, y - dy); the spec's
# "left", "above", "upper left", "upper right", "two left", "two above".
SPRING_OFFSETS: tuple[tuple[int, int, int], ...] = (
    (STRUCTURAL, 1, 0),
    (STRUCTURAL, 0, 1),
    (SHEARING, 1, 1),
    (SHEARING, -1, 1),
    (BENDING, 2, 0),
    (BENDING, 0, 2),
)

# Bending springs are weaker: the spec suggests multiplying ks by 0.2.
BENDING_STIFFNESS_FACTOR = 0.2


@dataclass
class Springs:
    """Springs as parallel arrays; ``i``/``j`` are point indices, ``kind`` the family."""

    i: np.ndarray  # (S,) int32
    j: np.ndarray  # (S,) int32
    rest: np.ndarray  # (S,) float64
    kind: np.ndarray  # (S,) int8

    def __len__(self) -> int:
        return int(self.i.shape[0])

    def select(self, mask: np.ndarray) -> "Springs":
        """The springs where ``mask`` is true (copies, so the arrays are contiguous)."""
        return Springs(self.i[mask], self.j[mask], self.rest[mask], self.kind[mask])


def grid_positions(cloth: ClothSpec, seed: int) -> np.ndarray:
    """Initial positions, shape (N, 3), float64.

    Horizontal cloths lie in the plane y = 1 over x and z; vertical cloths span x and y with a
    uniform z jitter in [-1/1000, 1/1000] drawn from a generator seeded by ``seed``.
    """
    nw, nh = cloth.num_width_points, cloth.num_height_points
    u = np.linspace(0.0, cloth.width, nw)
    v = np.linspace(0.0, cloth.height, nh)
    uu, vv = np.meshgrid(u, v)  # (nh, nw): row y_index, column x_index
    pos = np.empty((nh * nw, 3), dtype=np.float64)
    pos[:, 0] = uu.ravel()
    if cloth.orientation == HORIZONTAL:
        pos[:, 1] = 1.0
        pos[:, 2] = vv.ravel()
    else:
        rng = np.random.default_rng(seed)
        pos[:, 1] = vv.ravel()
        pos[:, 2] = rng.uniform(-1.0 / 1000.0, 1.0 / 1000.0, size=nh * nw)
    return pos


def pinned_mask(cloth: ClothSpec) -> np.ndarray:
    """Boolean (N,) mask of pinned points (a mesh cloth's ``pinned_vertices`` through its weld)."""
    mask = np.zeros(cloth.num_points, dtype=np.bool_)
    if cloth.mesh is not None:
        mask[cloth.mesh.vertex_point[np.asarray(cloth.pinned_vertices, dtype=np.int64)]] = True
        return mask
    for x, y in cloth.pinned:
        mask[y * cloth.num_width_points + x] = True
    return mask


def all_springs(nw: int, nh: int, positions: np.ndarray) -> Springs:
    """Every spring of all three families, rest lengths measured from ``positions``."""
    idx = np.arange(nw * nh, dtype=np.int32).reshape(nh, nw)
    parts_i, parts_j, kinds = [], [], []
    for family, dx, dy in SPRING_OFFSETS:
        x0, x1 = max(dx, 0), nw + min(dx, 0)
        a = idx[dy:, x0:x1]  # the point (x, y)
        b = idx[: nh - dy, x0 - dx : x1 - dx]  # its partner (x - dx, y - dy)
        parts_i.append(b.ravel())
        parts_j.append(a.ravel())
        kinds.append(np.full(a.size, family, dtype=np.int8))
    i = np.concatenate(parts_i).astype(np.int32)
    j = np.concatenate(parts_j).astype(np.int32)
    rest = np.linalg.norm(positions[i] - positions[j], axis=1)
    return Springs(i=i, j=j, rest=rest, kind=np.concatenate(kinds))


def spring_blocks(nw: int, nh: int, structural: bool = True, shearing: bool = True,
                  bending: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Block descriptors of the enabled springs, in the order :func:`all_springs` lists them.

    Returns ``blocks`` (B, 6) int64 rows (dx, dy, x0, x1, first_spring, num_rows) and the family
    of each block. Row r of a block holds the springs from point (x - dx, r) to (x, r + dy) for
    x in [x0, x1), so both ends advance by one index per spring.
    """
    on = (structural, shearing, bending)
    rows, fams = [], []
    first = 0
    for family, dx, dy in SPRING_OFFSETS:
        if not on[family]:
            continue
        x0, x1 = max(dx, 0), nw + min(dx, 0)
        n_rows = nh - dy
        if x1 <= x0 or n_rows <= 0:
            continue
        rows.append((dx, dy, x0, x1, first, n_rows))
        fams.append(family)
        first += (x1 - x0) * n_rows
    return np.array(rows, dtype=np.int64).reshape(-1, 6), np.array(fams, dtype=np.int8)


def spring_streams(nw: int, nh: int, blocks: np.ndarray, spring_k: np.ndarray,
                   rest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The springs as whole-grid streams, the layout the force kernel runs on.

    Each block's springs join point ``a`` to point ``a + offset`` with one offset per block
    (``dy * nw + dx``), so a block is one stream over ``a``: ``k[g, a]`` and ``rest[g, a]`` hold
    the stiffness and rest length of the spring starting at ``a``, or 0 where the block has no
    spring there (a row's wrap-around pair); a zero stiffness makes no force. ``spring_k`` and
    ``rest`` are per spring, in block order. Returns
    ``(offsets (B,), k (B, N), rest (B, N), buffer (B, 3, N + max offset))``; the buffer holds the
    per-spring forces between the two passes of :func:`clothsim.sim.passes.springs.accumulate_forces`
    and must start zeroed.
    """
    n = nw * nh
    count = blocks.shape[0]
    offsets = blocks[:, 1] * nw + blocks[:, 0]
    k = np.zeros((count, n))
    rest_s = np.zeros((count, n))
    for g, (dx, dy, x0, x1, first, rows) in enumerate(blocks):
        length = x1 - x0
        r = np.arange(rows)[:, None]
        a = (r * nw + x0 - dx + np.arange(length)[None, :]).ravel()
        k[g, a] = spring_k[first : first + rows * length]
        rest_s[g, a] = rest[first : first + rows * length]
    width = n + (int(offsets.max()) if count else 0)
    return offsets.astype(np.int64), k, rest_s, np.zeros((count, 3, width))


def spring_count(nw: int, nh: int, structural: bool = True, shearing: bool = True, bending: bool = True) -> int:
    """Closed-form number of springs on an nw x nh grid with the given families enabled."""
    n = 0
    if structural:
        n += (nw - 1) * nh + nw * (nh - 1)
    if shearing:
        n += 2 * (nw - 1) * (nh - 1)
    if bending:
        n += max(nw - 2, 0) * nh + nw * max(nh - 2, 0)
    return n


def enabled_mask(kind: np.ndarray, structural: bool, shearing: bool, bending: bool) -> np.ndarray:
    """Mask of springs whose family is enabled."""
    on = np.array([structural, shearing, bending], dtype=np.bool_)
    return on[kind]


def cloth_triangles(nw: int, nh: int) -> np.ndarray:
    """Triangle indices (T*3,) uint32, two per grid quad.

    With A=(x,y), B=(x+1,y), C=(x,y+1), D=(x+1,y+1) the triangles are (A,C,B) and (B,C,D), so a
    horizontal cloth's front face (counter-clockwise) points up (+y).
    """
    idx = np.arange(nw * nh, dtype=np.uint32).reshape(nh, nw)
    a = idx[:-1, :-1].ravel()
    b = idx[:-1, 1:].ravel()
    c = idx[1:, :-1].ravel()
    d = idx[1:, 1:].ravel()
    tris = np.stack([a, c, b, b, c, d], axis=1)
    return np.ascontiguousarray(tris.ravel())


def cloth_uvs(nw: int, nh: int) -> np.ndarray:
    """Texture coordinates (N, 2) float32: u along x_index, v along y_index, both in [0, 1]."""
    u = np.linspace(0.0, 1.0, nw, dtype=np.float32)
    v = np.linspace(0.0, 1.0, nh, dtype=np.float32)
    uu, vv = np.meshgrid(u, v)
    return np.ascontiguousarray(np.stack([uu.ravel(), vv.ravel()], axis=1))


@dataclass(frozen=True)
class Surface:
    """What draws or exports a cloth of either kind: its triangles over the simulated points, and
    render vertices (a point split where a UV seam runs through it) with their texture coordinates."""

    triangles: np.ndarray  # (T, 3) int64 point indices
    uv_point: np.ndarray  # (R,) int64 render vertex -> point
    uvs: np.ndarray  # (R, 2) float32
    uv_triangles: np.ndarray  # (T, 3) int64, the same triangles over render vertices
    has_uvs: bool  # False: the uvs are a planar projection (clothsim.clothmesh)


def cloth_surface(cloth: ClothSpec) -> Surface:
    """The cloth's :class:`Surface`: a grid's two triangles a quad and its [0, 1] UVs (one render
    vertex a point), or a mesh cloth's triangles and render vertices as its OBJ gives them."""
    m = cloth.mesh
    if m is not None:
        return Surface(triangles=m.triangles, uv_point=m.uv_point, uvs=m.uvs, uv_triangles=m.uv_triangles,
                       has_uvs=m.has_uvs)
    nw, nh = cloth.num_width_points, cloth.num_height_points
    triangles = cloth_triangles(nw, nh).reshape(-1, 3).astype(np.int64)
    return Surface(triangles=triangles, uv_point=np.arange(nw * nh, dtype=np.int64), uvs=cloth_uvs(nw, nh),
                   uv_triangles=triangles, has_uvs=True)
