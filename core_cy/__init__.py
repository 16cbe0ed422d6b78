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
"""

from .camera import Camera
from .errors import CameraError, CoreError, FitError, GeometryError, ImageError, SilhouetteError
from .reconstruct import Options, Reconstruction, View, reconstruct
from .scoring import centre_error, volumetric_iou
from .segment import Segmentation
from .superquadric import Superquadric, fit_superquadric

__all__ = [
    "Camera", "View", "Options", "Reconstruction", "reconstruct", "Segmentation", "Superquadric",
    "fit_superquadric", "volumetric_iou", "centre_error", "CoreError", "CameraError", "ImageError",
    "SilhouetteError", "GeometryError", "FitError",
]
