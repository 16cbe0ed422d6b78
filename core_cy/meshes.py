"""Pure functions on triangle meshes."""

from __future__ import annotations

import numpy as np

__all__ = ["vertex_normals"]


def vertex_normals(vertices, triangles) -> np.ndarray:
    """Area-weighted unit vertex normals, (V, 3), of a mesh of ``vertices`` (V, 3) and outward
    ``triangles`` (F, 3); a vertex on no triangle gets a zero normal.

    Examples
    --------
    >>> vertex_normals([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]).tolist()
    [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
        raise ValueError(f"need vertices (V, 3) and triangles (F, 3), got {vertices.shape} and {triangles.shape}")
    corners = vertices[triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])  # length: twice the area
    # Each face's normal summed into its three corners: bincount does the scattered sum at once
    # (np.add.at does it one element at a time).
    corner_of = triangles.ravel()
    face_thrice = np.repeat(face, 3, axis=0)
    normals = np.stack([np.bincount(corner_of, weights=face_thrice[:, axis], minlength=len(vertices))
                        for axis in range(3)], axis=1)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(length > 0, length, 1.0)
