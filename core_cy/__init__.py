"""robocell's reconstruction core: silhouettes to a superquadric, pure functions on arrays.

No I/O: images come in as arrays or encoded bytes, results go out as arrays.
The stages (DESIGN.md §1), each in its own module:

    camera      pinhole cameras with OpenCV distortion, camera-to-world poses
    segment     silhouettes from colour (HSV), grey thresholds or supplied masks
    edges       points on each silhouette's edge, placed to a fraction of a pixel (kernel in Cython)
    sphere      the enclosing sphere from the silhouettes' centroid rays
    carve       shrinking the sphere's points onto the silhouettes (kernel in Cython)
    superquadric  the model, and the Jaklic fit to points that gives the starts (kernel in Cython)
    silhouette_fit  the superquadric whose outlines run through the edges (kernel in Cython)
    least_squares   Levenberg-Marquardt for both fits (kernel in Cython)
    quality     silhouette IoU and residual of a fit
    scoring     volumetric IoU of two superquadrics, for scoring against a truth
    reconstruct the whole pipeline, with timings per stage
    gripper     parallel-jaw grippers and the grasp frame
    grasp       ranked grasps of a superquadric, judged against the fit's own error (kernel in Cython)
    rigid       the one check of a rigid transform
    images      an image's size from its header, checked before decoding
    plan        where the camera looks from: flange poses around a target, the workspace check
    calibrate   chessboard calibration: intrinsics and hand-eye
"""

import importlib
from typing import Any

# The public names, and the module of each: imported on first use, so that a process that
# needs one small module (the rigid-pose check, say) does not pay for OpenCV and SciPy.
_WHERE = {
    "Camera": "camera", "View": "reconstruct", "Options": "reconstruct", "Reconstruction": "reconstruct",
    "reconstruct": "reconstruct", "Segmentation": "segment", "Superquadric": "superquadric",
    "fit_superquadric": "superquadric", "volumetric_iou": "scoring", "centre_error": "scoring",
    "Gripper": "gripper", "Grasp": "gripper", "plan_grasps": "grasp",
    "CoreError": "errors", "CameraError": "errors", "ImageError": "errors", "SilhouetteError": "errors",
    "GeometryError": "errors", "FitError": "errors", "CalibrationError": "errors", "GripperError": "errors",
}
__all__ = list(_WHERE)


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module 'core_cy' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
