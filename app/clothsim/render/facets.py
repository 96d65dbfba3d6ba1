"""Drawable geometry of a triangle-mesh collider, shared by the renderer and the exporters.

Flat-shaded: every triangle gets its own three vertices with the face's normal, so a low-poly
shape reads as facets; uvs are a planar projection along y over the mesh's bounding box.
"""

from __future__ import annotations

import numpy as np

from ..meshcollider import MeshSpec


def mesh_collider_vertices(spec: MeshSpec, t: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (3T, 11) float32 (position, normal, tangent, uv) scaled and rotated but not
    translated, and indices (3T,) uint32, counter-clockwise seen from outside a closed mesh; a
    deforming mesh's shape at time ``t`` (s) when given."""
    local = spec.local_vertices() if t is None else spec.local_vertices_at(t)
    tris = spec.triangles
    a, b, c = (local[tris[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    tangent = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    corners = np.stack([a, b, c], axis=1)  # (T, 3, 3)
    lo = local.min(axis=0)
    size = max(float((local.max(axis=0) - lo).max()), 1e-12)
    uv = (corners[:, :, [0, 2]] - lo[[0, 2]]) / size
    verts = np.concatenate([corners, np.repeat(normal[:, None], 3, axis=1), np.repeat(tangent[:, None], 3, axis=1),
                            uv], axis=2).reshape(-1, 11).astype(np.float32)
    return np.ascontiguousarray(verts), np.arange(verts.shape[0], dtype=np.uint32)
