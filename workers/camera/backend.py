"""What the camera worker needs of a camera: :class:`Camera`, whose :meth:`~Camera.snapshot`
gives a :class:`Snapshot`, the picture with its real size and encoding.

The Axis camera (``workers.camera.axis``) and the simulated camera
(``workers.sim.camera``) implement it, so the worker cannot tell which one it
drives. A new camera is a new backend beside them, with its configuration model
in ``wire.backends``, and a line in its ``BACKENDS``.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass


__all__ = ["Camera", "Snapshot"]


@dataclass(frozen=True)
class Snapshot:
    """One picture as the camera gave it: encoded ``data``, its size in pixels and its encoding."""

    data: bytes
    width: int
    height: int
    encoding: str = "image/jpeg"


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
