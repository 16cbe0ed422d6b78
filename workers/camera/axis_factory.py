"""The Axis camera as ``wire.backends.BACKENDS`` names it."""

from __future__ import annotations

from robocell.wire.backends import AxisCameraConfig
from robocell.wire.config import CellConfig
from robocell.wire.transport import BaseTransport

from .axis import AxisCamera

__all__ = ["make_camera"]


def make_camera(config: CellConfig, transport: BaseTransport) -> AxisCamera:
    """The Axis camera of the ``[camera]`` section, not yet opened.

    Raises
    ------
    ConfigError
        If a setting cannot be used (a CA bundle that cannot be read, a user without a password).
    """
    camera = config.camera
    assert isinstance(camera, AxisCameraConfig), "named by [camera] backend = axis"
    return AxisCamera.from_config(camera)
