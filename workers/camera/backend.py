"""What the camera worker needs of a camera: :class:`Camera`, whose :meth:`~Camera.snapshot`
gives a :class:`Snapshot`, the picture with its real size and encoding.

The Axis camera (``workers.camera.axis``) and the simulated camera
(``workers.sim.camera``) implement it, so the worker cannot tell which one it
drives. A new camera is a new backend beside them, with its configuration model
in ``wire.backends``, and a line in :func:`workers.camera.worker.make_camera`.
"""

from __future__ import annotations

import abc
import struct
from dataclasses import dataclass

__all__ = ["Camera", "Snapshot", "jpeg_size"]

# Start-of-frame markers (baseline, extended, progressive, lossless...): they carry the size.
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


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


@dataclass(frozen=True)
class Snapshot:
    """One picture as the camera gave it: encoded ``data``, its size in pixels and its encoding."""

    data: bytes
    width: int
    height: int
    encoding: str = "image/jpeg"

    @classmethod
    def from_jpeg(cls, data: bytes) -> Snapshot:
        """The snapshot of a JPEG, its size read from its header.

        Raises
        ------
        ValueError
            If ``data`` is not a JPEG with a frame header.
        """
        size = jpeg_size(data)
        if size is None:
            raise ValueError("not a JPEG with a frame header")
        return cls(data, *size)


class Camera(abc.ABC):
    """A camera that takes one picture on request. Errors are ``wire.errors.CameraError``s that
    say why; use ``async with``."""

    @property
    @abc.abstractmethod
    def source(self) -> str:
        """Where the pictures come from, safe to show (no credentials)."""

    async def open(self) -> None:
        """Get ready to take pictures."""

    async def close(self) -> None:
        """Let go of the camera; idempotent."""

    @abc.abstractmethod
    async def snapshot(self) -> Snapshot:
        """Take one picture."""

    async def __aenter__(self) -> Camera:
        await self.open()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()
