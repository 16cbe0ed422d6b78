"""Shrink a sphere of points onto the silhouettes: an approximate visual hull.

Each point is ``centre + radius * direction`` and only ever moves along its own
direction, so the hull is one radius per direction. Views are applied in turn,
each shrinking the points that project outside its silhouette (DESIGN.md §1,
step 4); a support plane then pulls back the points below the table.
"""

from __future__ import annotations

import cv2
import numpy as np

from ._carve_cy import carve_view
from .camera import Camera  # noqa: F401  (the examples in the docstrings use it)
from .errors import GeometryError

__all__ = ["occupancy", "carve", "clip_to_plane", "check_support_plane", "lift_above_plane"]

# The edge is where the smoothed silhouette crosses one half; the blur makes
# bilinear interpolation find it between pixel centres, not on them.
_EDGE_LEVEL = 0.5
_EDGE_BLUR_SIGMA = 0.7


def occupancy(silhouette: np.ndarray, box=None) -> np.ndarray:
    """The silhouette as smooth float32 occupancy in [0, 1], for sub-pixel edges.

    Parameters
    ----------
    silhouette : (H, W) ndarray of uint8
        0 or 255.
    box : (4,) tuple of int, optional
        The silhouette's bounding box ``(x, y, w, h)`` (``cv2.boundingRect``),
        if known; only it is blurred.

    Returns
    -------
    (H, W) ndarray of float32
    """
    occupied = np.zeros(silhouette.shape, np.float32)
    x, y, w, h = cv2.boundingRect(silhouette) if box is None else box
    if not w:
        return occupied
    height, width = silhouette.shape
    x0, y0, x1, y1 = max(0, x - 2), max(0, y - 2), min(width, x + w + 2), min(height, y + h + 2)
    smooth = cv2.GaussianBlur(silhouette[y0:y1, x0:x1], (3, 3), _EDGE_BLUR_SIGMA, borderType=cv2.BORDER_REPLICATE)
    occupied[y0:y1, x0:x1] = smooth * np.float32(1.0 / 255.0)
    return occupied


def carve(directions, centre, radius: float, cameras, occupancies) -> tuple[np.ndarray, np.ndarray]:
    """Radii of the points after shrinking the sphere onto every view, and which points were seen.

    Parameters
    ----------
    directions : (N, 3) array_like
        Unit directions from the centre.
    centre : (3,) array_like
    radius : float
        Starting radius of every point, large enough to enclose the object.
    cameras : sequence of Camera
    occupancies : sequence of (H, W) ndarray of float32
        :func:`occupancy` of each view's silhouette, in the order of ``cameras``.

    Returns
    -------
    radii : (N,) ndarray of float64
        Radius of each point after carving; 0 where no view saw an edge
        between the point and the centre.
    observed : (N,) ndarray of bool
        Whether any view saw the point inside its image; a point no view saw
        keeps the starting radius, which says nothing about the object.

    Examples
    --------
    A disc of radius 50 px seen by a camera 1 unit away with f = 500 px is a
    sphere of radius 0.1 (seen from its centre's depth; the edge lies a
    little nearer, on the tangent cone):

    >>> camera = Camera(K=[[500, 0, 99.5], [0, 500, 99.5], [0, 0, 1]], T_world_cam=np.eye(4))
    >>> disc = np.zeros((200, 200), np.uint8)
    >>> _ = cv2.circle(disc, (100, 100), 50, 255, -1)
    >>> radii, observed = carve([[1.0, 0, 0], [0, 1.0, 0]], [0, 0, 1.0], 0.15, [camera], [occupancy(disc)])
    >>> bool(np.allclose(radii, 0.1, atol=0.003)), observed.tolist()
    (True, [True, True])
    """
    directions = np.ascontiguousarray(directions, dtype=np.float64)
    if directions.ndim != 2 or directions.shape[1] != 3:
        raise ValueError(f"directions must have shape (N, 3), got {directions.shape}")
    centre = np.ascontiguousarray(centre, dtype=np.float64)
    if centre.shape != (3,):
        raise ValueError(f"centre must have shape (3,), got {centre.shape}")
    if len(cameras) != len(occupancies):
        raise ValueError(f"got {len(cameras)} cameras but {len(occupancies)} occupancy images")
    radii = np.full(len(directions), float(radius))
    observed = np.zeros(len(directions), np.uint8)
    for camera, occupied in zip(cameras, occupancies):
        carve_view(directions, radii, observed, centre, camera.projection, occupied, _EDGE_LEVEL)
    return radii, observed.view(bool)


def check_support_plane(plane, centre, radius: float = 0.0) -> np.ndarray:
    """Validate a support plane ``[nx, ny, nz, d]`` and return it with a unit normal.

    A centre found from the silhouettes alone (the enclosing sphere's) of a flat object lying on the
    table may come out a little below it; ``radius``, the object's size, says how far below is still
    that and not a wrong plane: up to ``_BELOW_FRACTION`` of it (see :func:`lift_above_plane`).

    Raises
    ------
    GeometryError
        If the plane is malformed, or the object's centre lies clearly below it (the
        plane, or its side, is wrong: the object would be under the table).
    """
    plane = np.asarray(plane, dtype=np.float64)
    if plane.shape != (4,) or not np.all(np.isfinite(plane)):
        raise GeometryError(f"support_plane must be 4 finite numbers [nx, ny, nz, d], got {plane.tolist()}")
    norm = np.linalg.norm(plane[:3])
    if norm == 0:
        raise GeometryError("support_plane's normal [nx, ny, nz] is zero")
    plane = plane / norm
    height = plane[:3] @ np.asarray(centre, dtype=np.float64) + plane[3]
    if height <= -_BELOW_FRACTION * float(radius):
        raise GeometryError(
            f"the support plane puts the object under the table: its centre is {-height:.4g} "
            "below the plane (the object stands where n . x + d >= 0)"
        )
    return plane


#: A centre below the plane by less than this fraction of the object's radius is a flat object's
#: centre placed a little low by its silhouettes; an inverted or wrong plane puts it about a whole
#: radius below.
_BELOW_FRACTION = 0.25
#: How far above the plane, as a fraction of the radius, a centre at or below it is lifted: carving
#: looks out from the centre, and needs it on the object's side of the table.
_LIFT_FRACTION = 0.01


def lift_above_plane(centre, radius: float, plane) -> np.ndarray:
    """The centre, moved along the plane's unit normal to at least ``_LIFT_FRACTION * radius`` above it.

    >>> lift_above_plane([0.0, 0.0, -0.002], 0.1, np.array([0.0, 0.0, 1.0, 0.0])).round(6).tolist()
    [0.0, 0.0, 0.001]
    >>> lift_above_plane([0.0, 0.0, 0.05], 0.1, np.array([0.0, 0.0, 1.0, 0.0])).tolist()
    [0.0, 0.0, 0.05]
    """
    centre = np.asarray(centre, dtype=np.float64)
    height = plane[:3] @ centre + plane[3]
    floor = _LIFT_FRACTION * float(radius)
    return centre if height >= floor else centre + (floor - height) * plane[:3]


def clip_to_plane(directions, radii, centre, plane) -> np.ndarray:
    """Pull points below the support plane back onto it, along their directions.

    Parameters
    ----------
    directions : (N, 3) ndarray
    radii : (N,) ndarray
    centre : (3,) ndarray
        Must lie above the plane (see :func:`check_support_plane`).
    plane : (4,) ndarray
        ``[n, d]`` with unit normal n; the object is where ``n . x + d >= 0``.

    Returns
    -------
    (N,) ndarray of float64
        The radii, no point below the plane.
    """
    height = plane[:3] @ centre + plane[3]
    descent = -(directions @ plane[:3])  # how fast each direction goes down
    with np.errstate(divide="ignore"):
        limit = np.where(descent > 0, height / descent, np.inf)
    return np.minimum(radii, limit)
