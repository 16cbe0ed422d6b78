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

__all__ = ["Segmentation", "RED_HSV", "segment", "clean_silhouette", "silhouette_from_mask"]

_OPEN_KERNEL = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))  # keeps square corners
_CLOSE_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))


@dataclass(frozen=True)
class Segmentation:
    """How to find the object in a colour image.

    Parameters
    ----------
    method : {"hsv", "threshold"}
        ``hsv``: keep pixels whose HSV values lie in [lower, upper]; hue is
        0-179 as in OpenCV, and a hue range with lower > upper wraps around 0
        (red). ``threshold``: keep pixels whose grey value is above ``value``
        (below it with ``invert``, for a dark object on a bright background).
    lower, upper : (3,) tuple of int
        HSV bounds for ``hsv``.
    value : int
        Grey threshold 0-255 for ``threshold``.
    invert : bool
        With ``threshold``, the object is the dark part.

    Raises
    ------
    CoreError
        If the method is unknown or a bound is out of its range.
    """

    method: Literal["hsv", "threshold"] = "hsv"
    lower: tuple[int, int, int] = (170, 90, 20)
    upper: tuple[int, int, int] = (10, 255, 255)
    value: int = 128
    invert: bool = False

    def __post_init__(self) -> None:
        if self.method not in ("hsv", "threshold"):
            raise CoreError(f"segmentation method must be 'hsv' or 'threshold', got {self.method!r}")
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


RED_HSV = Segmentation()


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
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ImageError("expected a (H, W, 3) uint8 BGR image", view=view)
    if segmentation.method == "hsv":
        hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
        lower, upper = segmentation.lower, segmentation.upper
        if lower[0] <= upper[0]:
            raw = cv2.inRange(hsv, lower, upper)
        else:  # the hue range wraps around 0
            raw = cv2.inRange(hsv, lower, (179, *upper[1:])) | cv2.inRange(hsv, (0, *lower[1:]), upper)
        what = f"hsv lower={list(lower)} upper={list(upper)}"
    else:
        grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        mode = cv2.THRESH_BINARY_INV if segmentation.invert else cv2.THRESH_BINARY
        _, raw = cv2.threshold(grey, segmentation.value, 255, mode)
        what = f"grey {'<=' if segmentation.invert else '>'} {segmentation.value}"
    raw = cv2.morphologyEx(raw, cv2.MORPH_OPEN, _OPEN_KERNEL)
    return clean_silhouette(raw, view=view, what=what)


def silhouette_from_mask(mask: np.ndarray, *, view: int | None = None) -> np.ndarray:
    """Turn a supplied mask (any 8-bit image, nonzero = object) into a silhouette.

    Raises
    ------
    ImageError
        If the mask is not a 2-D uint8 array.
    SilhouetteError
        If the mask is empty or touches all four borders.
    """
    if not isinstance(mask, np.ndarray) or mask.dtype != np.uint8 or mask.ndim != 2:
        raise ImageError("expected a (H, W) uint8 mask", view=view)
    return clean_silhouette(np.where(mask > 0, np.uint8(255), np.uint8(0)), view=view, what="mask")


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
    closed = cv2.morphologyEx(raw, cv2.MORPH_CLOSE, _CLOSE_KERNEL)
    contours, _ = cv2.findContours(closed, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        raise SilhouetteError(f"the silhouette is empty: no pixel matches the {what}", view=view)
    largest = max(contours, key=cv2.contourArea)
    silhouette = np.zeros_like(raw)
    cv2.drawContours(silhouette, [largest], -1, 255, thickness=cv2.FILLED)
    x, y, w, h = cv2.boundingRect(largest)
    height, width = raw.shape
    if x == 0 and y == 0 and x + w == width and y + h == height:
        raise SilhouetteError(
            f"the silhouette touches all four image borders ({what}): "
            "the object fills the view or the background was taken for the object",
            view=view,
        )
    return silhouette
