"""Pinhole cameras with OpenCV distortion, posed in the world.

Poses are ``T_world_cam``: camera-to-world 4x4 rigid transforms, camera axes
as in OpenCV (x right, y down, z forward). The reconstruction works on ideal
pinhole images: a distorted silhouette is undistorted once with
:func:`undistort_mask`, after which :meth:`Camera.project` needs no
distortion model.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .errors import CameraError

__all__ = ["Camera", "undistort_mask"]

# JSON round trips and real calibrations keep about 9 digits; a pose whose
# rotation is off by more than this is not a rotation.
_ROTATION_TOLERANCE = 1e-5
_DISTORTION_LENGTHS = (4, 5, 8, 12, 14)


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
        upper-triangular intrinsic matrix with positive focal lengths, or the
        pose is not a proper rigid transform.

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
        last = T[3].tolist()
        if abs(last[0]) > 1e-8 or abs(last[1]) > 1e-8 or abs(last[2]) > 1e-8 or abs(last[3] - 1.0) > 1.001e-5:
            raise CameraError("T_world_cam's last row must be [0, 0, 0, 1]", view=view)
        R = T[:3, :3]
        if np.abs(R.T @ R - np.eye(3)).max() > _ROTATION_TOLERANCE or np.linalg.det(R) < 0:
            raise CameraError(
                "T_world_cam's rotation is not orthonormal with determinant +1 "
                "(a singular, scaled or mirrored pose)",
                view=view,
            )
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
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "T_world_cam", T)
        object.__setattr__(self, "dist", dist)
        # Derived once: every stage projects through them.
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
    """
    if camera.dist is None:
        return mask
    height, width = mask.shape
    map_x, map_y = cv2.initUndistortRectifyMap(
        camera.K, camera.dist, None, camera.K, (width, height), cv2.CV_32FC1
    )
    resampled = cv2.remap(mask, map_x, map_y, cv2.INTER_LINEAR, borderValue=0)
    return np.where(resampled >= 128, np.uint8(255), np.uint8(0))
