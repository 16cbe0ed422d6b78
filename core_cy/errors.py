"""Errors raised by core_cy for input the algorithm cannot use.

Every error is a ``ValueError``, so callers that only care about "bad input"
can catch that; the tree lets them be more specific::

    CoreError (ValueError)
    ├── CameraError        a matrix is malformed: K, dist, or a non-rigid pose
    ├── ImageError         an image cannot be decoded or has the wrong shape
    ├── SilhouetteError    a view's silhouette is empty or fills the image
    ├── GeometryError      the views do not constrain the object (rays, support plane)
    ├── FitError           the superquadric fit cannot run on these points
    ├── CalibrationError   calibration images or robot poses cannot give a calibration
    └── GripperError       a gripper description is missing a value or has an absurd one

Errors about one view carry its index in ``view`` and name it in the message.
"""

from __future__ import annotations

__all__ = [
    "CoreError",
    "CameraError",
    "ImageError",
    "SilhouetteError",
    "GeometryError",
    "FitError",
    "CalibrationError",
    "GripperError",
]


class CoreError(ValueError):
    """Base class of the reconstruction core's errors."""

    def __init__(self, message: str, *, view: int | None = None) -> None:
        self.view = view
        super().__init__(f"view {view}: {message}" if view is not None else message)


class CameraError(CoreError):
    """A camera matrix, distortion vector or pose is malformed."""


class ImageError(CoreError):
    """An image cannot be decoded, or has a shape the core cannot use."""


class SilhouetteError(CoreError):
    """A view's silhouette is empty, or covers the image so no edge is seen."""


class GeometryError(CoreError):
    """The views or the support plane leave the object's position undefined."""


class FitError(CoreError):
    """The superquadric fit cannot run on the given points."""


class CalibrationError(CoreError):
    """Calibration images or robot poses cannot give a calibration: too few usable images,
    poses that do not match the images, or poses that are not rigid motions."""


class GripperError(CoreError):
    """A gripper description is missing a field, or a field's value is absurd."""
