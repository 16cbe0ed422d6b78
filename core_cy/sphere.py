"""The starting sphere: a centre and radius that enclose the object, and its points.

The centre x0 is the point closest (least squares) to the rays through the
silhouettes' centroids; the radius comes from each silhouette's extent seen
from x0's projection, at x0's depth, with a margin.
"""

from __future__ import annotations

import math
from functools import lru_cache

import cv2
import numpy as np

from .camera import Camera  # noqa: F401  (the examples in the docstrings use it)
from .errors import GeometryError

__all__ = ["CHECK_THE_POSES", "enclosing_sphere", "farthest_reach", "fibonacci_sphere"]

#: What the views' disagreement about where the object is asks of the user, where the silhouettes are theirs.
CHECK_THE_POSES = "check the poses' direction (camera-to-world) and units"

# Below this, the rays through the centroids are (nearly) parallel and their
# closest point runs off along them.
_MIN_RAY_SPREAD = 1e-6
# Consistent views put the centre inside every silhouette's bounding box; this much of the box's
# size beyond it is tolerated (noise, a concave object).
_BOX_SLACK = 0.1


def enclosing_sphere(silhouettes, cameras, *, margin: float = 1.25, known_boxes=None) -> tuple[np.ndarray, float]:
    """Estimate the object's centre and a radius that surely encloses it.

    Parameters
    ----------
    silhouettes : sequence of (H, W) ndarray of uint8
        One filled silhouette per view, nonzero = object, ideal pinhole images.
    cameras : sequence of Camera
        The views' cameras, in the same order.
    margin : float
        Factor applied to the largest extent seen in any view.
    known_boxes : sequence of (4,) tuple of int, optional
        Each silhouette's bounding box ``(x, y, w, h)``, if known.

    Returns
    -------
    centre : (3,) ndarray of float64
    radius : float

    Raises
    ------
    GeometryError
        If the centroid rays do not meet (parallel views), the centre lies
        behind a camera, or it projects outside a view's silhouette (the
        poses disagree with the pictures).
    """
    if len(silhouettes) != len(cameras) or len(cameras) < 2:
        raise GeometryError(f"need one silhouette per camera and at least 2 views, got "
                            f"{len(silhouettes)} silhouettes and {len(cameras)} cameras")
    normal_matrix = np.zeros((3, 3))
    normal_rhs = np.zeros(3)
    boxes = []
    for index, (silhouette, camera) in enumerate(zip(silhouettes, cameras)):
        x, y, w, h = box = cv2.boundingRect(silhouette) if known_boxes is None else tuple(known_boxes[index])
        # Moments of the box alone: the rest of the image is empty, and this is 10x faster.
        moments = cv2.moments(silhouette[y : y + h, x : x + w], binaryImage=True)
        centroid = np.array([[x + moments["m10"] / moments["m00"], y + moments["m01"] / moments["m00"]]])
        ray = camera.pixel_rays(centroid)[0]
        projector = np.eye(3) - np.outer(ray, ray)  # removes the component along the ray
        normal_matrix += projector
        normal_rhs += projector @ camera.center
        boxes.append(box)
    eigenvalues = np.linalg.eigvalsh(normal_matrix / len(cameras))
    if eigenvalues[0] < _MIN_RAY_SPREAD:
        raise GeometryError("the views look along parallel rays: their centroid rays do not meet")
    centre = np.linalg.solve(normal_matrix, normal_rhs)

    radius = 0.0
    for view, (camera, (x, y, w, h)) in enumerate(zip(cameras, boxes)):
        (centre_uv,), (depth,) = camera.project(centre[None])
        if depth <= 0:
            raise GeometryError("the object's estimated centre lies behind the camera", view=view)
        slack_x, slack_y = _BOX_SLACK * w, _BOX_SLACK * h
        if not (x - slack_x <= centre_uv[0] <= x + w + slack_x and y - slack_y <= centre_uv[1] <= y + h + slack_y):
            raise GeometryError(
                "the views disagree about where the object is: the centre seen by all views projects "
                f"outside this view's silhouette ({centre_uv[0]:.0f}, {centre_uv[1]:.0f} px; silhouette "
                f"x {x}-{x + w}, y {y}-{y + h}); {CHECK_THE_POSES}",
                view=view,
            )
        corners = np.array([[x, y], [x + w, y], [x, y + h], [x + w, y + h]], dtype=np.float64)
        extent_px = np.linalg.norm(corners - centre_uv, axis=1).max()
        radius = max(radius, extent_px * depth / camera.focal_length)
    return centre, margin * radius


def farthest_reach(centre, radius: float, cameras) -> float:
    """How far from ``centre`` the object may reach, given the radius of the sphere that encloses it as
    the views see it (:func:`enclosing_sphere`).

    That radius holds across each view's line of sight; along it a view sees nothing. Of two views whose
    lines of sight to the centre lie an angle phi apart, one sees any direction at phi / 2 or more from
    its line of sight, where a reach r shows as r sin(phi / 2) at least: the object reaches no farther
    than ``radius / sin(phi / 2)`` for the widest pair, and as far as it likes for views along one line.

    Parameters
    ----------
    centre : (3,) array_like
    radius : float
    cameras : sequence of Camera

    Returns
    -------
    float
        The reach; ``inf`` when every view looks along one line.

    Examples
    --------
    >>> def at(x, y, z):
    ...     T = np.eye(4)
    ...     T[:3, 3] = x, y, z
    ...     return Camera(K=np.eye(3), T_world_cam=T)
    >>> float(farthest_reach([0, 0, 0], 1.0, [at(0, 0, -1), at(0, 0, 1)]))  # opposite: every direction seen across
    1.0
    >>> round(float(farthest_reach([0, 0, 0], 1.0, [at(0, 0, -1), at(0, -1, 0)])), 3)  # a right angle apart
    1.414
    >>> farthest_reach([0, 0, 0], 1.0, [at(0, 0, -1), at(0, 0, -2)])
    inf
    """
    sights = np.asarray([camera.center for camera in cameras], dtype=np.float64) - np.asarray(centre, np.float64)
    sights /= np.linalg.norm(sights, axis=1, keepdims=True)
    widest = float(np.arccos(np.clip((sights @ sights.T).min(), -1.0, 1.0)))
    across = math.sin(widest / 2)
    return radius / across if across > 1e-9 else math.inf


@lru_cache(maxsize=8)
def _fibonacci_sphere(n: int) -> np.ndarray:
    golden_angle = np.pi * (3.0 - np.sqrt(5.0))
    k = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * k + 1.0) / n
    ring = np.sqrt(1.0 - z * z)
    directions = np.stack([ring * np.cos(golden_angle * k), ring * np.sin(golden_angle * k), z], axis=1)
    directions.flags.writeable = False
    return directions


def fibonacci_sphere(n: int) -> np.ndarray:
    """Evenly spread unit directions (a Fibonacci lattice).

    Parameters
    ----------
    n : int
        Number of directions, >= 4.

    Returns
    -------
    (n, 3) ndarray of float64
        Unit vectors, read-only (shared between calls).

    Examples
    --------
    >>> d = fibonacci_sphere(100)
    >>> d.shape, bool(np.allclose(np.linalg.norm(d, axis=1), 1)), bool(abs(d.mean(0)).max() < 0.02)
    ((100, 3), True, True)
    """
    if int(n) != n or n < 4:
        raise ValueError(f"n must be an integer >= 4, got {n!r}")
    return _fibonacci_sphere(int(n))
