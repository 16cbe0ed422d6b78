"""Whether a model agrees with silhouettes, and a grasp with a model and a gripper: the pure geometry
of the daemon's check of a reconstruction worker's answer (``robocell.cell.verify``).

- :func:`model_iou`: the intersection over union of a silhouette and the projection of a
  model (a union of superquadrics, each convex: its projection is the convex hull of its
  projected surface).
- :func:`grasp_problem`: why a grasp does not follow from the model and the gripper (the
  pads' centre line meets the model, the width the grasp claims is no less than the
  model's between the pads and fits the opening, the open fingers and the palm do not cut
  the model, no finger or palm corner lies below the support plane), or None.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from .camera import Camera
from ._grasp_cy import line_extents as _line_extents
from ._grasp_cy import union_inside as _union_inside
from .gripper import Gripper
from .superquadric import Superquadric, surface_points

__all__ = ["model_iou", "grasp_problem", "MODEL_SLACK", "MIN_VIEW_IOU"]

#: The least intersection over union of a model's projection and a view's silhouette for the model to be of
#: what that view saw: the worst view of a correct model scores about 0.5 (an L of two boxes, a plate), a
#: model of something else under 0.2 (measured in ``robocell.cell.verify``, which holds answers to it).
MIN_VIEW_IOU = 0.3

_SUBPIXEL_BITS = 4
# How far the grasp's claimed width may fall short of the model's width between the pads: a share of
# the width, and at least this many metres (the planner's width is the widest chord under the
# pads, sampled; ours is sampled too).
_WIDTH_SHARE, _WIDTH_FLOOR = 0.1, 0.002
# Samples along the closing line, across the finger and along it.
_LINE_SAMPLES = 241
_ACROSS_SAMPLES, _ALONG_SAMPLES = 5, 9
#: How much larger (where a grasp must meet the model) and smaller (where the gripper must keep
#: clear of it) the model is taken, as a share of its sizes: see :func:`grasp_problem`.
MODEL_SLACK = 0.15
# A corner of the gripper may lie this far (metres) below the support plane before it counts:
# rounding of the poses on the wire, no more (the planner keeps a clearance of centimetres).
_PLANE_SLACK = 1e-4


def model_iou(parts: Sequence[Superquadric], camera: Camera, silhouette: np.ndarray) -> float:
    """Intersection over union of a silhouette and the projection of the union of ``parts``
    (each convex: its projection is the convex hull of its projected surface)."""
    height, width = silhouette.shape
    covered = np.zeros((height, width), np.uint8)
    limit = 4.0 * max(height, width)
    for part in parts:
        uv, depth = camera.project(surface_points(part))
        uv = uv[depth > 0]
        if len(uv) < 3:
            continue
        hull = cv2.convexHull(np.clip(uv, -limit, limit).astype(np.float32)).reshape(-1, 2)
        cv2.fillConvexPoly(covered, np.round(hull * (1 << _SUBPIXEL_BITS)).astype(np.int32), 1,
                           shift=_SUBPIXEL_BITS)
    seen, projected = silhouette != 0, covered != 0
    union = int(np.count_nonzero(seen | projected))
    return int(np.count_nonzero(seen & projected)) / union if union else 0.0


class _Union:
    """The model's parts seen from a grasp's frame, for samples in that frame inside their union
    taken any number of times as large (``_grasp_cy``'s ``union_inside`` and ``line_extents``)."""

    def __init__(self, parts: Sequence[Superquadric], T_world_grasp: np.ndarray) -> None:
        T_part_grasp = np.array([np.linalg.inv(part.T_world_object) @ T_world_grasp for part in parts])
        self._kernel_args = (np.ascontiguousarray(T_part_grasp[:, :3, :3]),
                             np.ascontiguousarray(T_part_grasp[:, :3, 3]),
                             np.ascontiguousarray([part.size for part in parts], dtype=np.float64),
                             np.ascontiguousarray([part.shape for part in parts], dtype=np.float64))

    def any_inside(self, points: np.ndarray, factor: float) -> bool:
        """Whether any of ``points`` (N, 3) is inside."""
        return bool(_union_inside(points, *self._kernel_args, factor))

    def widest_chord(self, lines: np.ndarray, line_coordinate: np.ndarray, factor: float) -> float | None:
        """Over ``lines`` (C, L, 3) of samples, the longest stretch from a line's first sample inside
        to its last, measured in ``line_coordinate`` (L,); None where no sample is inside."""
        extents = np.empty((len(lines), 2), np.intp)
        _line_extents(lines, *self._kernel_args, factor, extents)
        met = extents[:, 0] >= 0
        if not met.any():
            return None
        return float((line_coordinate[extents[met, 1]] - line_coordinate[extents[met, 0]]).max())


@dataclass(frozen=True)
class _Samples:
    """Where :func:`grasp_problem` samples a gripper, in the grasp frame: under the pads (lines
    across the closing direction, a grid of across x along of them, each sampled at ``line``, its
    coordinate along the closing direction), where the open fingers are, and the palm."""

    pad_lines: np.ndarray
    line: np.ndarray
    fingers: np.ndarray
    palm: np.ndarray


@functools.lru_cache(maxsize=8)
def _samples(g: Gripper) -> _Samples:
    half_open = g.max_opening / 2
    t = np.linspace(-half_open - g.finger_thickness, half_open + g.finger_thickness, _LINE_SAMPLES)
    across = np.linspace(-g.finger_width / 2, g.finger_width / 2, _ACROSS_SAMPLES)
    X, Z, Y = np.meshgrid(across, np.linspace(g.tip - g.pad_length, g.tip, _ALONG_SAMPLES), t, indexing="ij")
    fingers = np.meshgrid(across, t[np.abs(t) >= half_open], np.linspace(g.palm, g.tip, _ALONG_SAMPLES),
                          indexing="ij")
    palm_x, palm_y = np.meshgrid(np.linspace(-g.palm_width / 2, g.palm_width / 2, _ACROSS_SAMPLES + 2),
                                 np.linspace(-half_open - g.finger_thickness, half_open + g.finger_thickness,
                                             _ACROSS_SAMPLES + 2), indexing="ij")
    palm = np.stack([palm_x.ravel(), palm_y.ravel(), np.full(palm_x.size, g.palm)], axis=1)
    pad_lines = np.ascontiguousarray(np.stack([X, Y, Z], axis=-1).reshape(-1, len(t), 3))
    return _Samples(pad_lines, t, np.ascontiguousarray(np.stack(fingers, axis=-1).reshape(-1, 3)), palm)


def grasp_problem(T_world_grasp: np.ndarray, width: float, parts: Sequence[Superquadric], gripper: Gripper,
                  support_plane: Sequence[float] | None) -> str | None:
    """Why a grasp does not follow from the model and the gripper, or None when it does.

    The checks, in the grasp frame (DESIGN.md §3: z the approach, y the closing
    direction, the origin between the pads): the width fits the opening; no finger or
    palm corner lies below the support plane; the model is between the pads (the
    contacts are on it); the claimed ``width`` is no less than the model's widest chord
    under the pads; no part of the model is where the open fingers or the palm are.

    The planner works on the model as the worker returned it but for what the fit
    cannot know (it sets a fit tilted by a few degrees upright; it keeps the palm clear
    of the hull), so the model is taken :data:`MODEL_SLACK` larger where the grasp must
    meet it and as much smaller where the gripper must keep clear of it: a grasp moved
    off the object, or too wide, or under the table is refused, the planner's own pass.
    """
    T = np.asarray(T_world_grasp, dtype=np.float64)
    R, origin = T[:3, :3], T[:3, 3]
    g = gripper
    if width > g.max_opening:
        return f"its width {width:.3f} m is more than the gripper opens ({g.max_opening:.3f} m)"
    if support_plane is not None:
        plane = np.asarray(support_plane, dtype=np.float64)
        plane = plane / np.linalg.norm(plane[:3])
        corners = g.corners() @ R.T + origin
        lowest = float((corners @ plane[:3] + plane[3]).min())
        if lowest < -_PLANE_SLACK:
            return f"a corner of the gripper would be {-lowest * 1000:.1f} mm below the support plane"
    grown, shrunk = 1 + MODEL_SLACK, 1 - MODEL_SLACK
    samples = _samples(g)
    # Under the pads: the contacts are where the model meets the pads' faces.
    union = _Union(parts, T)
    most = union.widest_chord(samples.pad_lines, samples.line, grown)
    if most is None:
        return "the model is not between its pads"
    least = union.widest_chord(samples.pad_lines, samples.line, shrunk) or 0.0
    slack = max(_WIDTH_SHARE * width, _WIDTH_FLOOR)
    # Only a width below the model's is refused: the gripper opens fully before it closes, so a
    # wider claim costs nothing, and the planner claims one where the model misses much of the
    # silhouettes (it plans on the visual hull's box there, which this check does not know).
    if width < least - slack:
        return f"its width {width:.3f} m is not the model's between the pads ({least:.3f}-{most:.3f} m)"
    if union.any_inside(samples.fingers, shrunk):
        return "the open fingers would cut the model"
    if union.any_inside(samples.palm, shrunk):
        return "the palm would cut the model"
    return None
