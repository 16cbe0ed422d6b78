"""Exact scenes for tests: ideal cameras and silhouettes worked out analytically."""

from __future__ import annotations

import contextlib
import subprocess
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from robocell.core_cy.plan import look_at
from robocell.core_cy.camera import Camera

WIDTH, HEIGHT, FOCAL = 640, 480, 600.0


def intrinsics(focal: float = FOCAL, width: int = WIDTH, height: int = HEIGHT) -> np.ndarray:
    return np.array([[focal, 0.0, (width - 1) / 2], [0.0, focal, (height - 1) / 2], [0.0, 0.0, 1.0]])


def sphere_silhouette(camera: Camera, centre, radius: float, shape=(HEIGHT, WIDTH)) -> np.ndarray:
    """Exact silhouette of a sphere: pixels whose ray through the pixel centre meets it."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    uv = np.stack([cols.ravel(), rows.ravel()], axis=1).astype(np.float64)
    rays = camera.pixel_rays(uv)
    to_centre = np.asarray(centre, dtype=np.float64) - camera.center
    along = rays @ to_centre
    miss_squared = to_centre @ to_centre - along**2
    hit = (miss_squared <= radius**2) & (along > 0)
    return np.where(hit, np.uint8(255), np.uint8(0)).reshape(shape)


def orthogonal_cameras(centre, distance: float, focal: float = FOCAL) -> list[Camera]:
    """Three cameras on the +x, +y and +z axes through ``centre``, looking at it."""
    centre = np.asarray(centre, dtype=np.float64)
    cameras = []
    for index, axis in enumerate(np.eye(3)):
        up = (0.0, 0.0, 1.0) if index < 2 else (0.0, 1.0, 0.0)
        cameras.append(Camera(K=intrinsics(focal), T_world_cam=look_at(centre + distance * axis, centre, up),
                              view=index))
    return cameras


@contextlib.contextmanager
def tmpfs(parent: Path, size: str) -> Iterator[Path]:
    """A tmpfs of ``size`` (``mount``'s words: ``256k``, ``24m``) mounted in a new folder of ``parent``,
    unmounted after; the test is skipped where none can be mounted (it needs root)."""
    mount_point = Path(parent) / f"disk-{uuid.uuid4().hex[:8]}"
    mount_point.mkdir()
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mount_point)],
                              capture_output=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f"cannot mount a tmpfs: {exc}")
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs: {done.stderr.decode().strip()}")
    try:
        yield mount_point
    finally:
        subprocess.run(["umount", "-l", str(mount_point)], capture_output=True, timeout=10)
