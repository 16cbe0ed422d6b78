"""Encoded images (PNG, JPEG): their size from the header, before a pixel is decoded.

A few kilobytes of PNG can declare 20000x20000 pixels, which decoding would
allocate; reading the header first lets a hostile image be refused for the
price of its header. The header's size is also what the calibration is
checked against (:func:`check_calibrated_size`).
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from .errors import ImageError

if TYPE_CHECKING:
    from .camera import Camera

__all__ = ["MAX_IMAGE_PIXELS", "MAX_IMAGE_SIDE", "PRINCIPAL_POINT_TOLERANCE", "png_size", "jpeg_size", "image_size",
           "checked_size", "check_calibrated_size"]

#: An image may have at most this many pixels (an 8192x6144 sensor has 50.3 million).
#: Decoding takes 3 bytes a pixel and segmenting it about as much again, so one
#: image stays well under a gigabyte.
MAX_IMAGE_PIXELS = 50_000_000

#: How far from the image centre K's principal point may lie, as a fraction of the
#: image's width (for cx) and height (for cy). Real calibrations put it within a
#: few percent (the bunny's and DTU's 1-2 %); an image at half or double the
#: calibration's resolution, or cut from 4:3 to 16:9, puts it 17 % or more away.
#: (A resolution within a factor 1.25 of the calibration's is not caught.)
PRINCIPAL_POINT_TOLERANCE = 0.1

#: Pixels on a side of an image: OpenCV's remap, which undistorts, takes no more.
MAX_IMAGE_SIDE = 32_767

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# Start-of-frame markers (baseline, extended, progressive, lossless...): they carry the size.
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def png_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG's IHDR chunk, or None if ``data`` is not a PNG.

    Examples
    --------
    >>> import cv2, numpy as np
    >>> png_size(cv2.imencode(".png", np.zeros((48, 64), np.uint8))[1].tobytes())
    (64, 48)
    >>> png_size(b"not a png") is None
    True
    """
    # The signature, then the first chunk, which must be IHDR: length 13, type, width, height.
    if not data.startswith(_PNG_SIGNATURE) or data[12:16] != b"IHDR" or len(data) < 24:
        return None
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def jpeg_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a JPEG's frame header, or None if there is none.

    Examples
    --------
    >>> import cv2, numpy as np
    >>> jpeg_size(cv2.imencode(".jpg", np.zeros((48, 64, 3), np.uint8))[1].tobytes())
    (64, 48)
    >>> jpeg_size(b"not a jpeg") is None
    True
    """
    if not data.startswith(b"\xff\xd8"):
        return None
    at = 2
    while at + 4 <= len(data):
        if data[at] != 0xFF:
            return None
        marker = data[at + 1]
        if marker == 0xFF:  # fill byte
            at += 1
            continue
        (length,) = struct.unpack(">H", data[at + 2:at + 4])
        if marker in _SOF:
            if at + 9 > len(data):
                return None
            height, width = struct.unpack(">HH", data[at + 5:at + 9])
            return width, height
        at += 2 + length
    return None


def image_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) of a PNG or JPEG from its header; None for anything else."""
    return png_size(data) or jpeg_size(data)


def checked_size(data: bytes, *, what: str = "the image", view: int | None = None) -> tuple[int, int]:
    """(width, height) of a PNG or JPEG that may be decoded: at most :data:`MAX_IMAGE_PIXELS`,
    and :data:`MAX_IMAGE_SIDE` on a side.

    ``what`` names the image in the error ("the mask", "image 'view0.jpg'").

    Raises
    ------
    ImageError
        If ``data`` is neither PNG nor JPEG (or its header is cut off), declares
        no pixels, or more than the limits.

    Examples
    --------
    >>> import cv2, numpy as np
    >>> checked_size(cv2.imencode(".png", np.zeros((48, 64), np.uint8))[1].tobytes())
    (64, 48)
    >>> checked_size(b"\\x89PNG\\r\\n\\x1a\\n\\x00\\x00\\x00\\x0dIHDR\\x00\\x00N\\x20\\x00\\x00N\\x20", view=2)
    Traceback (most recent call last):
    ...
    robocell.core_cy.errors.ImageError: view 2: the image is 20000x20000 pixels (400.0 megapixels); at most 50 megapixels are decoded
    """
    size = image_size(data)
    if size is None:
        raise ImageError(f"{what} is not a decodable image: neither a PNG nor a JPEG with a frame header "
                         f"({len(data)} bytes)", view=view)
    width, height = size
    if width == 0 or height == 0:
        raise ImageError(f"{what} is not a decodable image: its header says {width}x{height} pixels", view=view)
    if width * height > MAX_IMAGE_PIXELS:
        raise ImageError(f"{what} is {width}x{height} pixels ({width * height / 1e6:.1f} megapixels); "
                         f"at most {MAX_IMAGE_PIXELS // 1_000_000} megapixels are decoded", view=view)
    if max(width, height) > MAX_IMAGE_SIDE:
        raise ImageError(f"{what} is {width}x{height} pixels; at most {MAX_IMAGE_SIDE} a side are decoded",
                         view=view)
    return width, height


def check_calibrated_size(camera: Camera, width: int, height: int, *, what: str = "the image") -> None:
    """Check that an image of ``width`` x ``height`` pixels is one ``camera``'s K was calibrated for.

    K does not record its image's size, but its principal point lies near the
    centre of that image: within :data:`PRINCIPAL_POINT_TOLERANCE` of the width
    and of the height. An image at another resolution, or of another camera,
    puts it elsewhere.

    Raises
    ------
    ImageError
        Naming the camera's view, the size found and the size K implies.

    Examples
    --------
    >>> import numpy as np
    >>> from core_cy.camera import Camera
    >>> camera = Camera(K=[[600, 0, 319.5], [0, 600, 239.5], [0, 0, 1]], T_world_cam=np.eye(4), view=1)
    >>> check_calibrated_size(camera, 640, 480)
    >>> check_calibrated_size(camera, 100, 100, what="mask 'mask1.png'")
    Traceback (most recent call last):
    ...
    robocell.core_cy.errors.ImageError: view 1: mask 'mask1.png' is 100x100 pixels, but K was calibrated for about 640x480: its principal point (319.5, 239.5) must lie within 10% of the image's width and height from the centre
    """
    cx, cy = camera.K[0, 2], camera.K[1, 2]
    if (abs(cx - (width - 1) / 2) <= PRINCIPAL_POINT_TOLERANCE * width
            and abs(cy - (height - 1) / 2) <= PRINCIPAL_POINT_TOLERANCE * height):
        return
    raise ImageError(
        f"{what} is {width}x{height} pixels, but K was calibrated for about {2 * cx + 1:.0f}x{2 * cy + 1:.0f}: "
        f"its principal point ({cx:g}, {cy:g}) must lie within {PRINCIPAL_POINT_TOLERANCE:.0%} of the image's "
        f"width and height from the centre", view=camera.view)
