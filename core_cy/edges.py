"""Edge samples: points on a silhouette's outline, placed to a fraction of a pixel.

A segmentation decides pixel by pixel, and where the object's colour mixes
with the background's (anti-aliasing, lens blur, JPEG's coarse colour) its
decision moves the outline by up to a pixel or two, depending on the colours
and the thresholds. The edge itself is where the image is half-way between
the object's colour and the background's: each sample starts on the
segmented outline and moves, along the outline's normal, to that crossing in
the photograph (or, for a supplied mask, to the mask's own half-way line).
Samples on the image's border are dropped: there the object is cut off, not
outlined.
"""

from __future__ import annotations

import cv2
import numpy as np

from ._edges_cy import edge_crossings
from .camera import Camera
from .errors import SilhouetteError

__all__ = ["about_samples", "edge_samples", "samples_near", "silhouette_outline"]

# Half-length of the profile across the edge, px: the segmented outline lies within a pixel or two of
# the edge, and the colours at the profile's ends (its outer pixel) must be the object's and the background's.
_REACH_PX = 3.0
_STEP_PX = 0.25
# Below this difference between the object's and the background's colour (grey levels, the length
# of the BGR difference) the crossing is noise: the segmented outline is kept.
_MIN_CONTRAST = 24.0
# The outline's direction is taken over this many contour steps either side.
_TANGENT_SPAN = 3
# Samples this close to the image border (px) are dropped: the object may run on beyond it.
_BORDER_PX = 2
# A mask's edge is found on the mask blurred by this much (px), within its box grown by the margin.
_MASK_BLUR_PX = 1.2
_MASK_MARGIN = 8
# An image crossing this far (px) from a silhouette's edge placed on the image's step is another step.
_ON_EDGE_PX = 0.5
# A sample lies on the pixels whose centres lie this near (px): those either side of the edge it marks,
# the edge placed to within a pixel or two (_REACH_PX's profile).
_NEAR_PX = 2.0
# A run of pixels narrower than this (px) along an outline is its blur, the object's colour mixed with the
# background's (a dark object's rim on a light table is darker than the table), no stretch of the outline.
_BLUR_PX = 3


def silhouette_outline(silhouette: np.ndarray) -> np.ndarray:
    """The outer contour of a silhouette's largest region, (M, 2) int32 pixel coordinates, in order.

    Raises
    ------
    SilhouetteError
        If the silhouette is empty.
    """
    contours, _ = cv2.findContours(silhouette, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise SilhouetteError("the silhouette is empty")
    return max(contours, key=cv2.contourArea).reshape(-1, 2)


def edge_samples(outline: np.ndarray, silhouette: np.ndarray, image: np.ndarray | None = None, *,
                 count: int = 64, camera: Camera | None = None, on_edge: bool = False) -> np.ndarray:
    """Up to ``count`` points on the object's edge, spread evenly along its outline.

    Parameters
    ----------
    outline : (M, 2) ndarray of int
        The silhouette's outer contour, in order (:func:`silhouette_outline`).
    silhouette : (H, W) ndarray of uint8
        The silhouette the outline belongs to, 0 or 255.
    image : (H, W, 3) ndarray of uint8, optional
        The photograph it was segmented from; without it the samples are
        placed on the silhouette's own half-way line.
    count : int
        How many samples to take (fewer remain when some lie on the border).
    camera : Camera, optional
        With lens distortion, the samples are moved to where the ideal
        pinhole camera would see them.
    on_edge : bool
        The silhouette's edge already lies on the image's own colour step,
        placed with more than a single profile can know (``auto`` places it
        so, knowing the table's colour and the shadow beside the object): a crossing
        in the image over :data:`_ON_EDGE_PX` from the silhouette's own
        half-way line is another step (a print's, a shadow's, a seam's), and
        the silhouette's edge is kept there.

    Returns
    -------
    (N, 2) ndarray of float64
        Pixel coordinates (column, row) of the ideal pinhole image, N <= count.

    Examples
    --------
    A mask of pixels 30-69 by 20-59: its edge runs half-way between the
    outermost pixels inside and the first outside, x = 29.5 and 69.5,
    y = 19.5 and 59.5.

    >>> square = np.zeros((80, 100), np.uint8)
    >>> square[20:60, 30:70] = 255
    >>> points = edge_samples(silhouette_outline(square), square, count=8)
    >>> points[1::2].round(1).tolist()  # the others sit on corners, which blur into a curve
    [[29.5, 39.0], [49.0, 59.5], [69.5, 40.0], [50.0, 19.5]]
    """
    outline = np.asarray(outline)
    length = len(outline)
    if length < 2 * _TANGENT_SPAN + 1:
        return np.zeros((0, 2))
    picked = np.unique(np.linspace(0, length, count, endpoint=False).astype(np.intp))
    after, before = outline[(picked + _TANGENT_SPAN) % length], outline[picked - _TANGENT_SPAN]
    tangent = (after - before).astype(np.float64)
    # Across the outline; whether it points out or in does not matter: the crossing is found
    # between the colours at the profile's two ends, whichever is the object's.
    normals = np.column_stack([tangent[:, 1], -tangent[:, 0]])
    lengths = np.linalg.norm(normals, axis=1)
    points = outline[picked].astype(np.float64)
    height, width = silhouette.shape
    keep = ((lengths > 0) & (points[:, 0] >= _BORDER_PX) & (points[:, 1] >= _BORDER_PX)
            & (points[:, 0] <= width - 1 - _BORDER_PX) & (points[:, 1] <= height - 1 - _BORDER_PX))
    points, normals = points[keep], normals[keep] / lengths[keep, None]
    shift = np.zeros(len(points))
    found = np.zeros(len(points), np.uint8)
    if image is not None:
        edge_crossings(image, points, normals, _REACH_PX, _STEP_PX, _MIN_CONTRAST, shift, found)
    # Where the image gives no crossing, and everywhere when the silhouette's own edge is to judge it.
    missing = (found == 0) | on_edge
    if missing.any():
        # A mask knows its edge only to the pixel; blurred along the edge, a slanted staircase of
        # pixels averages to the line it steps along.
        x, y, w, h = cv2.boundingRect(outline)
        x0, y0 = max(0, x - _MASK_MARGIN), max(0, y - _MASK_MARGIN)
        x1, y1 = min(width, x + w + _MASK_MARGIN), min(height, y + h + _MASK_MARGIN)
        smooth = cv2.GaussianBlur(silhouette[y0:y1, x0:x1], (0, 0), _MASK_BLUR_PX, borderType=cv2.BORDER_REPLICATE)
        own, own_found = np.zeros(missing.sum()), np.zeros(missing.sum(), np.uint8)
        edge_crossings(smooth[:, :, None], np.ascontiguousarray(points[missing] - (x0, y0)),
                       np.ascontiguousarray(normals[missing]), _REACH_PX, _STEP_PX, 1.0, own, own_found)
        if on_edge:
            # The image's crossing is the more precise where it agrees with the silhouette's edge.
            elsewhere = (found == 0) | (np.abs(shift - own) > _ON_EDGE_PX)
            shift[elsewhere] = own[elsewhere]
        else:
            shift[missing] = own
    points += shift[:, None] * normals
    if camera is not None and camera.dist is not None and len(points):
        points = np.asarray(cv2.undistortPoints(points.reshape(-1, 1, 2), camera.K, camera.dist, P=camera.K),
                            dtype=np.float64).reshape(-1, 2)
    return points


def about_samples(samples: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: the pixels :func:`samples_near` looks at to judge each of ``samples``."""
    about = np.zeros(shape, np.uint8)
    radius = int(np.ceil(_NEAR_PX)) + _BLUR_PX  # the opening looks a blur's width farther
    for column, row in np.round(np.asarray(samples, dtype=np.float64).reshape(-1, 2)).astype(np.intp):
        cv2.circle(about, (int(column), int(row)), radius, 1, -1)
    return about > 0


def samples_near(samples: np.ndarray, pixels: np.ndarray, reach: float = _NEAR_PX) -> np.ndarray:
    """(N,) bool: whether ``pixels`` ((H, W) bool) reach within ``reach`` (px) of each sample ((N, 2)
    column, row, as :func:`edge_samples` gives them), where they are more than an edge's blur wide
    (:data:`_BLUR_PX`): a thin run along the outline is the edge itself.

    >>> pixels = np.zeros((40, 40), bool)
    >>> pixels[10:20, 10:20] = True  # a patch
    >>> pixels[30, 5:35] = True  # a one-pixel line
    >>> samples_near(np.array([[21.0, 15.0], [25.0, 15.0], [20.0, 30.5]]), pixels).tolist()
    [True, False, False]
    """
    samples = np.asarray(samples, dtype=np.float64).reshape(-1, 2)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (_BLUR_PX, _BLUR_PX))
    pixels = cv2.morphologyEx(pixels.astype(np.uint8), cv2.MORPH_OPEN, kernel) > 0
    span = int(np.ceil(reach)) + 1
    dy, dx = np.mgrid[-span:span + 1, -span:span + 1]
    near = np.zeros(len(samples), bool)
    height, width = pixels.shape
    base = np.round(samples).astype(np.intp)
    for ox, oy in zip(dx.ravel(), dy.ravel()):
        column, row = base[:, 0] + ox, base[:, 1] + oy
        inside = (column >= 0) & (row >= 0) & (column < width) & (row < height)
        close = inside & (np.hypot(column - samples[:, 0], row - samples[:, 1]) <= reach)
        near[close] |= pixels[row[close], column[close]]
    return near
