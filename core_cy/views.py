"""The geometry of a cell's job: where a pick's flange goes, which next views the robot may take,
and whether a reconstruction can be of what the cameras saw.

Pure functions: poses in, poses out (frames as in ``core_cy.plan``; metres).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .plan import Workspace, look_at, workspace_violation

__all__ = ["pick_poses", "candidate_views", "implausibility"]


def pick_poses(T_world_grasp, T_flange_grasp, *, approach: float, lift: float,
               place: Sequence[float] | None = None, half_turn: bool = False) -> dict[str, np.ndarray]:
    """The flange poses of a pick with this grasp, by name: ``above`` it (``approach`` back along
    its approach), at it (``grasp``), ``lift`` straight up; with a ``place`` (x, y), ``above
    place``, ``place`` (set down as it stood, the grasp moved across the table) and ``away``.

    ``half_turn``: the grasp turned half a turn about its approach (the gripper is symmetric).

    Examples
    --------
    >>> poses = pick_poses(np.eye(4), np.eye(4), approach=0.1, lift=0.2)
    >>> sorted(poses), poses["above"][:3, 3].tolist(), poses["lift"][:3, 3].tolist()
    (['above', 'grasp', 'lift'], [0.0, 0.0, -0.1], [0.0, 0.0, 0.2])
    """
    grasp = np.array(T_world_grasp, dtype=np.float64)
    if grasp.shape != (4, 4):
        raise ValueError(f"T_world_grasp must be 4x4, got shape {grasp.shape}")
    if half_turn:
        grasp[:3, :2] *= -1
    flange_from_grasp = np.linalg.inv(np.asarray(T_flange_grasp, dtype=np.float64))

    def back(T: np.ndarray, distance: float) -> np.ndarray:  # along the grasp's approach, away from it
        moved = T.copy()
        moved[:3, 3] -= distance * T[:3, 2]
        return moved

    def up(T: np.ndarray, distance: float) -> np.ndarray:
        moved = T.copy()
        moved[2, 3] += distance
        return moved

    grasps = {"above": back(grasp, approach), "grasp": grasp, "lift": up(grasp, lift)}
    if place is not None:
        spot = grasp.copy()
        spot[:2, 3] = place
        grasps |= {"above place": up(spot, lift), "place": spot, "away": back(spot, approach)}
    return {name: T @ flange_from_grasp for name, T in grasps.items()}


def candidate_views(target, standoff: float, T_flange_cam, workspace: Workspace, *,
                    elevations_deg: Sequence[float] = (30.0, 50.0, 70.0), n_azimuths: int = 12,
                    taken: Sequence[np.ndarray] = (), min_separation_deg: float = 15.0) -> list[np.ndarray]:
    """Flange poses the robot may take to look at ``target`` from ``standoff``: ``n_azimuths``
    around it at each elevation, inside ``workspace``, none within ``min_separation_deg`` of the
    viewing direction of a camera pose in ``taken`` (camera-to-base). In the order of elevation,
    then azimuth.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> box = SimpleNamespace(min=[-1, -1, 0], max=[1, 1, 1], max_tilt_deg=90)
    >>> len(candidate_views([0, 0, 0], 0.4, np.eye(4), box, elevations_deg=[45], n_azimuths=8))
    8
    """
    if standoff <= 0:
        raise ValueError(f"standoff must be positive, got {standoff}")
    centre = np.asarray(target, dtype=np.float64)
    if centre.shape != (3,):
        raise ValueError(f"target must be a point (3,), got shape {centre.shape}")
    flange_from_cam = np.linalg.inv(np.asarray(T_flange_cam, dtype=np.float64))
    seen = [_unit(np.asarray(T, dtype=np.float64)[:3, 3] - centre) for T in taken]
    limit = math.cos(math.radians(min_separation_deg))
    poses = []
    for elevation in elevations_deg:
        el = math.radians(elevation)
        for k in range(n_azimuths):
            az = 2 * math.pi * k / n_azimuths
            direction = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
            if any(float(direction @ d) > limit for d in seen):
                continue
            pose = look_at(centre + standoff * direction, centre) @ flange_from_cam
            if workspace_violation(pose, workspace) is None:
                poses.append(pose)
    return poses


def implausibility(T_world_object, size, cameras: Sequence[np.ndarray], K, resolution: tuple[int, int],
                   floor: tuple[Sequence[float], Sequence[float]]) -> str | None:
    """Why an object of half-sizes ``size`` at ``T_world_object`` cannot be what cameras at
    ``cameras`` (camera-to-world) saw, or None: its centre must be over the floor plan ``floor``
    ((x, y) min, max), in every picture, and no camera inside it."""
    T = np.asarray(T_world_object, dtype=np.float64)
    centre, half = T[:3, 3], np.asarray(size, dtype=np.float64)
    low, high = floor
    if not all(lo <= x <= hi for lo, x, hi in zip(low[:2], centre[:2], high[:2])):
        return f"its centre {np.round(centre, 3).tolist()} m is not over the workspace"
    K = np.asarray(K, dtype=np.float64)
    width, height = resolution
    for view, pose in enumerate(cameras):
        R, c = pose[:3, :3], pose[:3, 3]
        if np.all(np.abs(T[:3, :3].T @ (c - centre)) <= half):
            return f"camera {view} would be inside it (size {np.round(half, 3).tolist()} m)"
        x = K @ (R.T @ (centre - c))
        if x[2] <= 0 or not (0 <= x[0] / x[2] < width and 0 <= x[1] / x[2] < height):
            return f"its centre is outside the picture of view {view}"
    return None


def _unit(v: np.ndarray) -> np.ndarray:
    length = float(np.linalg.norm(v))
    return v / length if length > 0 else v
