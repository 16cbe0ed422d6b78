"""Planning a scan: where the flange goes for each view, and whether it may go there.

Pure functions: poses in, poses out. Frames: the robot base frame (z up,
metres) is the world of the reconstruction; ``T_base_flange`` is the flange's
pose (flange-to-base), ``T_flange_cam`` the camera's pose on the flange
(camera-to-flange) from hand-eye calibration, so the camera sits at
``T_base_cam = T_base_flange @ T_flange_cam``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

__all__ = ["look_at", "plan_flange_poses", "workspace_violation", "camera_poses", "ViewPlan", "Workspace"]


class ViewPlan(Protocol):
    """Where to look from (``wire.messages.ViewPlan`` is one): one view per (elevation, azimuth)."""

    @property
    def standoff(self) -> float: ...
    @property
    def elevations_deg(self) -> Sequence[float]: ...
    @property
    def azimuths_deg(self) -> Sequence[float]: ...


class Workspace(Protocol):
    """Where the flange may go (``wire.backends.Workspace`` is one): a box, metres, and a tilt limit."""

    @property
    def min(self) -> Sequence[float]: ...
    @property
    def max(self) -> Sequence[float]: ...
    @property
    def max_tilt_deg(self) -> float: ...


def look_at(position, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-base pose of a camera at ``position`` aimed at ``target``, image "up" towards ``up``.

    OpenCV camera axes: z forward, y down, x right.

    Raises
    ------
    ValueError
        If position and target coincide, or the camera would look straight along ``up``.
    """
    # Plain floats: on 3-vectors NumPy's per-call overhead (np.cross above all) is most of the cost,
    # and a daemon plans every scan it is sent.
    px, py, pz = (float(v) for v in position)
    tx, ty, tz = (float(v) for v in target)
    ux, uy, uz = (float(v) for v in up)
    fx, fy, fz = tx - px, ty - py, tz - pz
    length = math.sqrt(fx * fx + fy * fy + fz * fz)
    if length < 1e-9:
        raise ValueError("the camera position and the target coincide")
    fx, fy, fz = fx / length, fy / length, fz / length
    rx, ry, rz = fy * uz - fz * uy, fz * ux - fx * uz, fx * uy - fy * ux  # forward x up
    length = math.sqrt(rx * rx + ry * ry + rz * rz)
    if length < 1e-9:
        raise ValueError("the camera would look straight along 'up'")
    rx, ry, rz = rx / length, ry / length, rz / length
    dx, dy, dz = fy * rz - fz * ry, fz * rx - fx * rz, fx * ry - fy * rx  # image down: forward x right
    return np.array([[rx, dx, fx, px], [ry, dy, fy, py], [rz, dz, fz, pz], [0.0, 0.0, 0.0, 1.0]])


def plan_flange_poses(target, plan: ViewPlan, T_flange_cam) -> list[np.ndarray]:
    """Flange poses that put the camera ``plan.standoff`` from ``target``, one per view.

    View k looks at the target from elevation ``plan.elevations_deg[k]`` above
    the horizontal and azimuth ``plan.azimuths_deg[k]`` about the base z axis.
    """
    tx, ty, tz = (float(v) for v in target)
    flange_from_cam = np.linalg.inv(np.asarray(T_flange_cam, dtype=np.float64))
    poses = []
    for elevation, azimuth in zip(plan.elevations_deg, plan.azimuths_deg):
        el, az = math.radians(elevation), math.radians(azimuth)
        reach = plan.standoff * math.cos(el)
        position = (tx + reach * math.cos(az), ty + reach * math.sin(az), tz + plan.standoff * math.sin(el))
        poses.append(look_at(position, (tx, ty, tz)) @ flange_from_cam)
    return poses


def camera_poses(flange_poses, T_flange_cam) -> list[np.ndarray]:
    """Camera-to-base poses of the camera for each flange pose."""
    hand_eye = np.asarray(T_flange_cam, dtype=np.float64)
    return [np.asarray(pose, dtype=np.float64) @ hand_eye for pose in flange_poses]


def workspace_violation(T_base_flange, workspace: Workspace) -> str | None:
    """Why the pose is outside the workspace, or None if it is inside.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> box = SimpleNamespace(min=[0.1, -0.7, 0.05], max=[1.0, 0.7, 1.0], max_tilt_deg=80)
    >>> pose = np.eye(4); pose[:3, 3] = [0.5, 0.0, 1.4]; pose[:3, :3] = np.diag([1, -1, -1])
    >>> workspace_violation(pose, box)
    'z = 1.4 m is above the workspace maximum 1 m'
    """
    pose = np.asarray(T_base_flange, dtype=np.float64)
    for axis, name in enumerate("xyz"):
        value = pose[axis, 3]
        if value < workspace.min[axis]:
            return f"{name} = {value:.4g} m is below the workspace minimum {workspace.min[axis]:g} m"
        if value > workspace.max[axis]:
            return f"{name} = {value:.4g} m is above the workspace maximum {workspace.max[axis]:g} m"
    # The flange's z axis points out of the tool; straight down is (0, 0, -1).
    tilt = math.degrees(math.acos(float(np.clip(-pose[2, 2], -1.0, 1.0))))
    if tilt > workspace.max_tilt_deg:
        return f"the flange is tilted {tilt:.1f} deg from straight down, more than the limit {workspace.max_tilt_deg:g} deg"
    return None
