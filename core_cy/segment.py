"""Silhouettes: separate the object from the background in one image.

A silhouette here is a (H, W) uint8 array, 255 on the object and 0 elsewhere,
holding one filled region: the largest connected component of the raw
segmentation, holes filled, edges cleaned by morphology.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from .errors import CoreError, ImageError, SilhouetteError

__all__ = ["Segmentation", "AUTO", "RED_HSV", "segment", "segment_with_outline", "clean_silhouette",
           "silhouette_from_mask", "mask_with_outline"]

_OPEN_KERNEL = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))  # keeps square corners
_CLOSE_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
# The object is first looked for on every 4th pixel of every 4th row; the full-resolution work is done in
# its box, grown by this margin (px): more than the morphology's reach plus the coarse pass's step.
_COARSE = 4
_ROI_MARGIN = 12


@dataclass(frozen=True)
class Segmentation:
    """How to find the object in a colour image.

    Parameters
    ----------
    method : {"auto", "hsv", "threshold"}
        ``auto`` (the default): whatever stands on the support plane where the
        views converge, of any colour or print, its shadow left out; it works on
        all the views together (:func:`core_cy.auto_segment.auto_silhouettes`),
        and uses a view's ``background`` (a picture of the empty workspace from
        the same pose) when there is one. ``hsv`` and ``threshold`` work on one
        image at a time and take no background. ``hsv``: keep pixels whose HSV values lie in [lower, upper]; hue is
        0-179 as in OpenCV, and a hue range with lower > upper wraps around 0
        (red). ``threshold``: keep pixels whose grey value is above ``value``
        (below it with ``invert``, for a dark object on a bright background).
    lower, upper : (3,) tuple of int
        HSV bounds for ``hsv``. The default red keeps values from 20 up: a
        face turned from the light keeps its hue and saturation and loses only
        value (at 15 % ambient light a red face sits at V = 30), while grey
        walls and floors stay out by their low saturation.
    value : int
        Grey threshold 0-255 for ``threshold``.
    invert : bool
        With ``threshold``, the object is the dark part.

    Raises
    ------
    CoreError
        If the method is unknown or a bound is out of its range.
    """

    method: Literal["auto", "hsv", "threshold"] = "auto"
    lower: tuple[int, int, int] = (170, 90, 20)
    upper: tuple[int, int, int] = (10, 255, 255)
    value: int = 128
    invert: bool = False

    def __post_init__(self) -> None:
        if self.method not in ("auto", "hsv", "threshold"):
            raise CoreError(f"segmentation method must be 'auto', 'hsv' or 'threshold', got {self.method!r}")
        limits = (179, 255, 255)
        for name in ("lower", "upper"):
            bound = tuple(getattr(self, name))
            if len(bound) != 3 or not all(0 <= b <= m for b, m in zip(bound, limits)):
                raise CoreError(
                    f"segmentation {name} must be [h, s, v] with h in 0-179 and s, v in 0-255, "
                    f"got {list(bound)}"
                )
            object.__setattr__(self, name, tuple(int(b) for b in bound))
        if not 0 <= self.value <= 255:
            raise CoreError(f"segmentation value must be in 0-255, got {self.value}")


AUTO = Segmentation()
RED_HSV = Segmentation("hsv")


def _matches(image: np.ndarray, segmentation: Segmentation) -> np.ndarray:
    """Pixels of a BGR image that the segmentation takes for the object, 0 or 255."""
    if segmentation.method == "hsv":
        hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
        lower, upper = segmentation.lower, segmentation.upper
        if lower[0] <= upper[0]:
            return cv2.inRange(hsv, lower, upper)
        # the hue range wraps around 0
        return cv2.bitwise_or(cv2.inRange(hsv, lower, (179, *upper[1:])), cv2.inRange(hsv, (0, *lower[1:]), upper))
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    mode = cv2.THRESH_BINARY_INV if segmentation.invert else cv2.THRESH_BINARY
    return cv2.threshold(grey, segmentation.value, 255, mode)[1]


def _describe(segmentation: Segmentation) -> str:
    if segmentation.method == "hsv":
        return f"hsv lower={list(segmentation.lower)} upper={list(segmentation.upper)}"
    return f"grey {'<=' if segmentation.invert else '>'} {segmentation.value}"


def _grown(box, margin: int, shape) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of an OpenCV box (x, y, w, h) grown by ``margin``, within an image of ``shape``."""
    x, y, w, h = box
    height, width = shape[:2]
    return max(0, x - margin), max(0, y - margin), min(width, x + w + margin), min(height, y + h + margin)


def segment_with_outline(image: np.ndarray, segmentation: Segmentation = RED_HSV, *,
                         view: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`segment`, and the silhouette's outer contour, (M, 2) int32 pixel coordinates in order.

    The object is looked for first at a quarter of the resolution; the full
    image is segmented only within that box (grown by a margin), unless the
    region found there runs into the box's edge, in which case the whole
    image is segmented: the result is the same, for a fraction of the work.
    """
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ImageError("expected a (H, W, 3) uint8 BGR image", view=view)
    if segmentation.method == "auto":
        raise CoreError("the auto segmentation works on all the views together: "
                        "use core_cy.auto_segment.auto_silhouettes", view=view)
    what = _describe(segmentation)
    coarse = _matches(np.ascontiguousarray(image[_COARSE // 2::_COARSE, _COARSE // 2::_COARSE]), segmentation)
    if cv2.countNonZero(coarse):
        x, y, w, h = cv2.boundingRect(coarse)
        box = _grown((x * _COARSE, y * _COARSE, w * _COARSE, h * _COARSE), _ROI_MARGIN, image.shape)
        found = _cleaned(_opened(_matches(image[box[1]:box[3], box[0]:box[2]], segmentation)), image.shape, box)
        if found is not None:
            return _checked(*found, what=what, view=view)
    found = _cleaned(_opened(_matches(image, segmentation)), image.shape, (0, 0, image.shape[1], image.shape[0]))
    if found is None:
        raise SilhouetteError(f"the silhouette is empty: no pixel matches the {what}", view=view)
    return _checked(*found, what=what, view=view)


def segment(image: np.ndarray, segmentation: Segmentation = RED_HSV, *, view: int | None = None) -> np.ndarray:
    """Segment a colour image and return its cleaned silhouette.

    Parameters
    ----------
    image : (H, W, 3) ndarray of uint8
        BGR image, as OpenCV decodes it.
    segmentation : Segmentation
    view : int, optional
        Index of the view, to name it in errors.

    Returns
    -------
    (H, W) ndarray of uint8
        The silhouette, 0 or 255.

    Raises
    ------
    ImageError
        If the image is not (H, W, 3) uint8.
    SilhouetteError
        If nothing matches, or the silhouette touches all four borders.
    """
    return segment_with_outline(image, segmentation, view=view)[0]


def _opened(raw: np.ndarray) -> np.ndarray:
    return cv2.morphologyEx(raw, cv2.MORPH_OPEN, _OPEN_KERNEL)


def _cleaned(raw: np.ndarray, shape, box) -> tuple[np.ndarray, np.ndarray] | None:
    """The largest region of ``raw`` (the image's ``box``, x0, y0, x1, y1), holes filled, drawn into a
    whole image of ``shape``, and its outline; None if there is none, or it runs into an edge of the
    box that is not the image's (then the box cut it off)."""
    x0, y0, x1, y1 = box
    closed = cv2.morphologyEx(raw, cv2.MORPH_CLOSE, _CLOSE_KERNEL)
    contours, _ = cv2.findContours(closed, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE, offset=(x0, y0))
    if not contours:
        return None
    largest = max(contours, key=cv2.contourArea)
    x, y, w, h = cv2.boundingRect(largest)
    height, width = shape[:2]
    if (x == x0 > 0) or (y == y0 > 0) or (x + w == x1 < width) or (y + h == y1 < height):
        return None
    silhouette = np.zeros(shape[:2], np.uint8)
    cv2.drawContours(silhouette, [largest], -1, 255, thickness=cv2.FILLED)
    return silhouette, largest.reshape(-1, 2)


def _checked(silhouette: np.ndarray, outline: np.ndarray, *, what: str, view) -> tuple[np.ndarray, np.ndarray]:
    x, y, w, h = cv2.boundingRect(outline)
    height, width = silhouette.shape
    if x == 0 and y == 0 and x + w == width and y + h == height:
        raise SilhouetteError(
            f"the silhouette touches all four image borders ({what}): "
            "the object fills the view or the background was taken for the object",
            view=view,
        )
    return silhouette, outline


def mask_with_outline(mask: np.ndarray, *, view: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`silhouette_from_mask`, and the silhouette's outer contour (as :func:`segment_with_outline`)."""
    if not isinstance(mask, np.ndarray) or mask.dtype != np.uint8 or mask.ndim != 2:
        raise ImageError("expected a (H, W) uint8 mask", view=view)
    if not cv2.countNonZero(mask):
        raise SilhouetteError("the silhouette is empty: no pixel matches the mask", view=view)
    box = _grown(cv2.boundingRect(mask), _ROI_MARGIN, mask.shape)
    raw = np.where(mask[box[1]:box[3], box[0]:box[2]] > 0, np.uint8(255), np.uint8(0))
    found = _cleaned(raw, mask.shape, box)
    # The box holds every object pixel: the region cannot run into a cut.
    assert found is not None
    return _checked(*found, what="mask", view=view)


def silhouette_from_mask(mask: np.ndarray, *, view: int | None = None) -> np.ndarray:
    """Turn a supplied mask (any 8-bit image, nonzero = object) into a silhouette.

    Raises
    ------
    ImageError
        If the mask is not a 2-D uint8 array.
    SilhouetteError
        If the mask is empty or touches all four borders.
    """
    return mask_with_outline(mask, view=view)[0]


def clean_silhouette(raw: np.ndarray, *, view: int | None = None, what: str = "segmentation") -> np.ndarray:
    """Keep the largest region of a binary image and fill its holes.

    Parameters
    ----------
    raw : (H, W) ndarray of uint8
        Binary image, 0 or 255.
    view : int, optional
        Index of the view, to name it in errors.
    what : str
        What produced ``raw``, for the error message.

    Raises
    ------
    SilhouetteError
        If ``raw`` has no object pixel, or the region touches all four borders.

    Examples
    --------
    >>> raw = np.zeros((20, 20), np.uint8)
    >>> raw[4:12, 4:12] = 255; raw[7, 7] = 0  # a square with a hole
    >>> raw[17:19, 17:19] = 255               # and a speck
    >>> int(np.count_nonzero(clean_silhouette(raw)))
    64
    """
    found = _cleaned(raw, raw.shape, (0, 0, raw.shape[1], raw.shape[0]))
    if found is None:
        raise SilhouetteError(f"the silhouette is empty: no pixel matches the {what}", view=view)
    return _checked(*found, what=what, view=view)[0]
