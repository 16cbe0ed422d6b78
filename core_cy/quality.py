"""How well a fitted superquadric explains the silhouettes it came from."""

from __future__ import annotations

import cv2
import numpy as np

from .camera import Camera
from .superquadric import Superquadric, inside_outside, surface_points

__all__ = ["silhouette_iou", "hull_iou", "union_hull_iou", "hull_covers", "projected_outline", "outline_distances",
           "radial_residual"]

_SUBPIXEL_BITS = 4


def silhouette_iou(model, camera: Camera, silhouette: np.ndarray, box=None) -> float:
    """Intersection over union of a model's projection and a silhouette.

    Each part is convex (shape exponents <= 2), so its projection is the
    convex hull of its projected surface points; a union's projection is the
    union of its parts'.

    Parameters
    ----------
    model : Superquadric or sequence of Superquadric
        One superquadric, or the parts of a union.
    camera : Camera
        The view's ideal pinhole camera.
    silhouette : (H, W) ndarray of uint8
        Nonzero = object.
    box : (4,) tuple of int, optional
        The silhouette's bounding box ``(x, y, w, h)``, if known.

    Returns
    -------
    float
        In [0, 1]; 0 if the model is behind the camera.
    """
    parts = [model] if isinstance(model, Superquadric) else list(model)
    return union_hull_iou([projected_outline(part, camera) for part in parts], silhouette, box)


def projected_outline(part: Superquadric, camera: Camera, surface: np.ndarray | None = None) -> np.ndarray:
    """Pixels (N, 2) of the part's surface points in front of the camera: their hull is its outline.
    ``surface``: the part's :func:`core_cy.superquadric.surface_points`, if already taken (for another view)."""
    uv, depth = camera.project(surface_points(part) if surface is None else surface)
    return uv[depth > 0]


def outline_distances(part: Superquadric, camera: Camera, samples: np.ndarray) -> np.ndarray:
    """(N,) signed distance (pixels) of each of ``samples`` ((N, 2) column, row) from the part's
    projected outline: positive inside it, negative outside; -inf for every sample if the part is
    behind the camera.

    >>> from .camera import Camera
    >>> camera = Camera(K=[[100, 0, 50], [0, 100, 50], [0, 0, 1]], T_world_cam=np.eye(4))
    >>> ball = Superquadric([0.1, 0.1, 0.1], [1, 1], np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1.0], [0, 0, 0, 1]]))
    >>> np.round(outline_distances(ball, camera, np.array([[50.0, 50.0], [70.0, 50.0]])), 0).tolist()
    [10.0, -10.0]
    """
    samples = np.asarray(samples, dtype=np.float64).reshape(-1, 2)
    uv = projected_outline(part, camera)
    if len(uv) < 3:
        return np.full(len(samples), -np.inf)
    hull = cv2.convexHull(uv.astype(np.float32))
    return np.array([cv2.pointPolygonTest(hull, (float(u), float(v)), True) for u, v in samples])


def hull_iou(uv: np.ndarray, silhouette: np.ndarray, box=None) -> float:
    """Intersection over union of the convex hull of pixel points and a silhouette.

    Parameters
    ----------
    uv : (N, 2) ndarray of float
        Pixel coordinates (column, row), to sub-pixel precision; fewer than
        three cover nothing.
    silhouette : (H, W) ndarray
        Nonzero = object.
    box : (4,) tuple of int, optional
        The silhouette's bounding box ``(x, y, w, h)`` (``cv2.boundingRect``), if known.

    Examples
    --------
    >>> square = np.zeros((10, 10), np.uint8); square[2:6, 2:6] = 1
    >>> hull_iou(np.array([[2.0, 2.0], [5.0, 2.0], [5.0, 5.0], [2.0, 5.0]]), square)
    1.0
    """
    return union_hull_iou([uv], silhouette, box)


def union_hull_iou(uvs, silhouette: np.ndarray, box=None) -> float:
    """:func:`hull_iou` of the union of several convex hulls (one per part).

    Examples
    --------
    >>> square = np.zeros((10, 10), np.uint8); square[2:6, 2:8] = 1
    >>> left = np.array([[2.0, 2.0], [5.0, 2.0], [5.0, 5.0], [2.0, 5.0]])
    >>> union_hull_iou([left, left + [2.0, 0.0]], square)
    1.0
    """
    object_pixels, covers, _ = hull_covers(uvs, silhouette, box)
    if object_pixels is None:
        return 0.0
    covered = np.any(np.stack(covers), axis=0) if covers else np.zeros_like(object_pixels)
    union = int(np.count_nonzero(object_pixels | covered))
    return int(np.count_nonzero(object_pixels & covered)) / union if union else 0.0


def hull_covers(uvs, silhouette: np.ndarray, box=None):
    """The silhouette and each convex hull's cover, as boolean masks of the box around them all.

    Returns ``(object_pixels, covers, origin)``: the silhouette within the box (None when
    the box is empty), one mask per hull (of the same box; a hull of fewer than three
    points covers nothing) and the box's top-left pixel ``(x0, y0)``.
    """
    height, width = silhouette.shape
    hulls = []
    limit = 4.0 * max(height, width)
    for uv in uvs:
        if len(uv) >= 3:
            # Clamp far off-image points: fillConvexPoly takes int32 coordinates.
            hulls.append(cv2.convexHull(np.clip(uv, -limit, limit).astype(np.float32)).reshape(-1, 2))
        else:
            hulls.append(None)
    # Only the box around all the shapes (within the image) can hold a pixel of any.
    x, y, w, h = cv2.boundingRect(silhouette) if box is None else box
    x0, y0, x1, y1 = (x, y, x + w, y + h) if w else (width, height, 0, 0)
    for hull in hulls:
        if hull is not None:
            low, high = np.floor(hull.min(axis=0)), np.ceil(hull.max(axis=0)) + 1
            x0, y0 = min(x0, max(0, int(low[0]))), min(y0, max(0, int(low[1])))
            x1, y1 = max(x1, min(width, int(high[0]))), max(y1, min(height, int(high[1])))
    if x1 <= x0 or y1 <= y0:
        return None, [], (x0, y0)
    covers = []
    for hull in hulls:
        covered = np.zeros((y1 - y0, x1 - x0), np.uint8)
        if hull is not None:
            fixed_point = np.round((hull - (x0, y0)) * (1 << _SUBPIXEL_BITS)).astype(np.int32)
            cv2.fillConvexPoly(covered, fixed_point, 1, shift=_SUBPIXEL_BITS)
        covers.append(covered.view(bool))
    return silhouette[y0:y1, x0:x1] != 0, covers, (x0, y0)


def radial_residual(superquadric: Superquadric, points) -> float:
    """RMS distance of the points from the surface, along the rays from its centre.

    A point at ``x`` (object frame) meets the surface at ``x F^(-e1/2)``, so its
    radial distance is ``|x| |1 - F^(-e1/2)|``: in the points' own units.

    Parameters
    ----------
    superquadric : Superquadric
    points : (N, 3) array_like
        World points.

    Examples
    --------
    >>> sphere = Superquadric([1.0, 1.0, 1.0], [1.0, 1.0], np.eye(4))
    >>> round(radial_residual(sphere, [[2.0, 0, 0], [0, 0.5, 0]]), 6)
    0.790569
    """
    points = np.asarray(points, dtype=np.float64)
    F = np.maximum(inside_outside(points, superquadric), 1e-300)
    distance = np.linalg.norm(points - superquadric.T_world_object[:3, 3], axis=1)
    radial = distance * np.abs(1.0 - F ** (-superquadric.shape[0] / 2.0))
    return float(np.sqrt(np.mean(radial**2)))
