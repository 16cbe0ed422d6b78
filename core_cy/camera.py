"""Pinhole cameras with OpenCV distortion, posed in the world.

Poses are ``T_world_cam``: camera-to-world 4x4 rigid transforms, camera axes
as in OpenCV (x right, y down, z forward). The reconstruction works on ideal
pinhole images: a distorted silhouette is undistorted once with
:func:`undistort_mask`, after which :meth:`Camera.project` needs no
distortion model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .errors import CameraError
from .rigid import rigid_error

__all__ = ["Camera", "undistort_mask"]

# JSON round trips and real calibrations keep about 9 digits; a pose whose
# rotation is off by more than this is not a rotation.
_DISTORTION_LENGTHS = (4, 5, 8, 12, 14)
# Points on each edge and diagonal of the image where the distortion is checked.
_BORDER_SAMPLES = 33


def _matrix(value, shape: tuple[int, ...], name: str, view: int | None) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CameraError(f"{name} is not a numeric matrix", view=view) from exc
    if array.shape != shape:
        raise CameraError(f"{name} must have shape {shape}, got {array.shape}", view=view)
    if not np.all(np.isfinite(array)):
        raise CameraError(f"{name} contains NaN or infinity", view=view)
    return np.ascontiguousarray(array)


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated camera at a pose.

    Parameters
    ----------
    K : (3, 3) array_like
        Intrinsic matrix, pixels; ``K[2] == [0, 0, 1]``.
    T_world_cam : (4, 4) array_like
        Camera-to-world rigid transform.
    dist : (4|5|8|12|14,) array_like, optional
        OpenCV distortion coefficients; ``None`` or all zeros for none.
    view : int, optional
        Index of the view, used only to name it in errors.

    Raises
    ------
    CameraError
        If a matrix has the wrong shape, is not finite, K is not an
        upper-triangular intrinsic matrix with positive focal lengths, the
        pose is not a proper rigid transform, or dist moves a pixel of the
        image K implies by more than the image's half-diagonal (no lens does).

    Examples
    --------
    >>> cam = Camera(K=[[600, 0, 320], [0, 600, 240], [0, 0, 1]], T_world_cam=np.eye(4))
    >>> uv, depth = cam.project([[0.1, 0.0, 1.0]])
    >>> uv.round(3).tolist(), depth.tolist()
    ([[380.0, 240.0]], [1.0])
    """

    K: np.ndarray
    T_world_cam: np.ndarray
    dist: np.ndarray | None = None
    view: int | None = None
    # Derived in __post_init__: every stage projects through them.
    _centre: np.ndarray = field(init=False, repr=False)
    _projection: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        view = self.view
        K = _matrix(self.K, (3, 3), "K", view)
        # Plain comparisons: np.allclose costs more than the rest of the checks together.
        k = K.tolist()
        if (abs(k[2][0]) > 1e-8 or abs(k[2][1]) > 1e-8 or abs(k[2][2] - 1.0) > 1.001e-5 or k[1][0] != 0.0
                or k[0][0] <= 0 or k[1][1] <= 0):
            raise CameraError(
                "K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0", view=view
            )
        T = _matrix(self.T_world_cam, (4, 4), "T_world_cam", view)
        problem = rigid_error(T)
        if problem is not None:
            raise CameraError(f"T_world_cam {problem} (a singular, scaled or mirrored pose?)", view=view)
        dist = self.dist
        if dist is not None:
            dist = np.asarray(dist, dtype=np.float64).ravel()
            if dist.size not in _DISTORTION_LENGTHS:
                raise CameraError(
                    f"dist must have one of {_DISTORTION_LENGTHS} coefficients, got {dist.size}",
                    view=view,
                )
            if not np.all(np.isfinite(dist)):
                raise CameraError("dist contains NaN or infinity", view=view)
            dist = dist if np.any(dist) else None
            problem = None if dist is None else _distortion_error(K, dist)
            if problem is not None:
                raise CameraError(problem, view=view)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "T_world_cam", T)
        object.__setattr__(self, "dist", dist)
        R = T[:3, :3]
        centre = np.ascontiguousarray(T[:3, 3])
        projection = K @ np.hstack([R.T, -(R.T @ centre)[:, None]])
        for name, array in (("_centre", centre), ("_projection", projection)):
            array.flags.writeable = False
            object.__setattr__(self, name, array)

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in the world (read-only)."""
        return self._centre

    @property
    def projection(self) -> np.ndarray:
        """(3, 4) pinhole projection matrix ``K [R^T | -R^T c]`` (world to pixels; read-only)."""
        return self._projection

    @property
    def focal_length(self) -> float:
        """Geometric mean of fx and fy, pixels."""
        return float(np.sqrt(self.K[0, 0] * self.K[1, 1]))

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Project world points with the ideal pinhole model.

        Parameters
        ----------
        points : (N, 3) array_like
            World points.

        Returns
        -------
        uv : (N, 2) ndarray of float64
            Pixel coordinates (column, row); meaningless where depth <= 0.
        depth : (N,) ndarray of float64
            Distance along the optical axis; <= 0 behind the camera.
        """
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), got {points.shape}")
        homogeneous = points @ self._projection[:, :3].T + self._projection[:, 3]
        depth = homogeneous[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = homogeneous[:, :2] / depth[:, None]
        return uv, depth

    def pixel_rays(self, uv) -> np.ndarray:
        """World unit directions of the rays through pixels (ideal pinhole).

        Parameters
        ----------
        uv : (N, 2) array_like
            Pixel coordinates.

        Returns
        -------
        (N, 3) ndarray of float64
            Unit vectors from :attr:`center` through the pixels.
        """
        uv = np.asarray(uv, dtype=np.float64)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise ValueError(f"uv must have shape (N, 2), got {uv.shape}")
        homogeneous = np.hstack([uv, np.ones((len(uv), 1))])
        directions = np.linalg.solve(self.K, homogeneous.T).T @ self.T_world_cam[:3, :3].T
        return directions / np.linalg.norm(directions, axis=1, keepdims=True)


def undistort_mask(mask: np.ndarray, camera: Camera) -> np.ndarray:
    """Resample a silhouette as the ideal pinhole camera with the same K would see it.

    Parameters
    ----------
    mask : (H, W) ndarray of uint8
        Silhouette, nonzero = object, as the real (distorted) lens saw it.
    camera : Camera

    Returns
    -------
    (H, W) ndarray of uint8
        The undistorted silhouette, 0 or 255; ``mask`` itself if the camera
        has no distortion.

    Raises
    ------
    CameraError
        If the distortion sends pixels to infinity, or moves the whole
        silhouette out of the image: coefficients no lens has (the wrong
        order or units, say).
    """
    if camera.dist is None:
        return mask
    height, width = mask.shape
    map_x, map_y = cv2.initUndistortRectifyMap(
        camera.K, camera.dist, None, camera.K, (width, height), cv2.CV_32FC1
    )
    resampled = cv2.remap(mask, map_x, map_y, cv2.INTER_LINEAR, borderValue=0)
    silhouette = np.where(resampled >= 128, np.uint8(255), np.uint8(0))
    if not silhouette.any() and mask.any():
        raise CameraError(f"dist {_coefficients(camera.dist)} moves the whole silhouette out of the image",
                          view=camera.view)
    return silhouette


def _coefficients(dist: np.ndarray) -> str:
    return "[" + ", ".join(f"{value:g}" for value in dist) + "]"


def _distortion_error(K: np.ndarray, dist: np.ndarray) -> str | None:
    """What is wrong with ``dist`` as a lens's distortion, or None.

    Undistorting takes every pixel of the ideal image from where the lens put
    it. A real lens moves no pixel by more than the image's half-diagonal
    (strong barrel distortion pulls the corners in by a third or so); larger
    moves, and overflows, come from coefficients in the wrong order or units
    and leave nothing to undistort. The image is the one K implies: from
    (0, 0) to twice the principal point.
    """
    cx, cy = max(K[0, 2], 1.0), max(K[1, 2], 1.0)
    border = np.linspace(0.0, 1.0, _BORDER_SAMPLES)
    pixels = np.concatenate([  # the four edges and both diagonals, corners included
        np.column_stack([border * 2 * cx, np.zeros_like(border)]),
        np.column_stack([border * 2 * cx, np.full_like(border, 2 * cy)]),
        np.column_stack([np.zeros_like(border), border * 2 * cy]),
        np.column_stack([np.full_like(border, 2 * cx), border * 2 * cy]),
        np.column_stack([border * 2 * cx, border * 2 * cy]),
        np.column_stack([border * 2 * cx, (1 - border) * 2 * cy]),
    ])
    ideal = np.linalg.solve(K, np.column_stack([pixels, np.ones(len(pixels))]).T).T
    with np.errstate(all="ignore"):
        lens, _ = cv2.projectPoints(ideal, np.zeros(3), np.zeros(3), np.eye(3), dist)
        moved = np.linalg.norm(lens.reshape(-1, 2) - ideal[:, :2], axis=1)
        half_diagonal = float(np.max(np.linalg.norm(ideal[:, :2], axis=1)))
        worst = float(moved.max() / half_diagonal) if np.isfinite(moved).all() else np.inf
    if worst <= 1.0:
        return None
    how = "to infinity" if worst == np.inf else f"by up to {worst:.3g} times its half-diagonal"
    return (f"dist {_coefficients(dist)} moves pixels of the image {how}, which no lens does "
            f"(expected OpenCV's k1, k2, p1, p2[, k3, ...] for this K)")
