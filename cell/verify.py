"""No reconstruction worker is trusted with the robot: its answer is checked against what the daemon holds.

A worker's answer (a model, grasps) comes from a process the daemon cannot
vouch for: any session the router lets into the pool can answer (issue 23: a
fake worker's model 8-10 times too big was stored, and its grasp drove the arm).
The daemon holds the pictures of the job and knows its cameras, its support
plane and its gripper, so it can check the answer cheaply before storing or
using it (:func:`verify_reconstruction`):

- **The model agrees with the pictures.** Each picture is decoded at a quarter
  of its size (``cv2.IMREAD_REDUCED_COLOR_4``: the JPEG decoder scales as it
  decodes, so this costs a fraction of a full decode) and segmented as the job's
  segmentation says; the model (the union of its parts) is projected into each
  view, and the intersection over union of projection and silhouette must reach
  :data:`MIN_VIEW_IOU` in every view. The worker's own silhouettes are never
  used: they are what a fake worker would forge first.
- **Every grasp follows from the model and the gripper** (:func:`check_grasp`):
  the pads' centre line meets the model, the model's width between the pads is
  the width the grasp claims and fits the opening, the open fingers and the palm
  do not cut the model, the contacts are antipodal within the friction cone, and
  no finger or palm corner lies below the support plane.

Everything here is a pure function of bytes and arrays: no I/O, no clock. The
daemon calls it before it stores a result; a result that fails is a failed
attempt, sent again elsewhere (``ReconstructorPool.refuse``).

Why the threshold (:data:`MIN_VIEW_IOU`, 0.3): on the simulator's scans
(``robocell sim scans``, the standard set and the grasp set, 138 scans) the
worst view of a correct reconstruction scores 0.49 at this scale (an L of two
boxes, which one superquadric describes poorly; 0.70 for every other object,
0.87-0.92 on average), and a model 8 to 10 times too big scores 0.09 at most.
A model 1.5 times too big still scores up to 0.44: this check catches a model
of something else, or far too big or small, not a fit that is a little off.

A grasp that does not follow from the model is dropped from the answer
(:attr:`Verdict.grasps` lists those that do). The planner plans on the hull's
box as well as on the model where the model misses much of the silhouettes, so
an honest answer may hold a few grasps this check cannot derive; an answer none
of whose grasps follows from its model is refused as a whole.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from robocell.core_cy.auto_segment import auto_silhouettes
from robocell.core_cy.camera import Camera, undistort_mask
from robocell.core_cy.errors import CoreError
from robocell.core_cy.gripper import Gripper
from robocell.core_cy.segment import Segmentation, segment
from robocell.core_cy.superquadric import Superquadric as CoreSuperquadric
from robocell.core_cy.superquadric import inside_outside, surface_points
from robocell.wire.bundle import core_segmentation
from robocell.wire.config import CellConfig
from robocell.wire.messages import Grasp, Reconstruction, ReconstructRequest, Superquadric

from .job import Picture

__all__ = ["Verdict", "MIN_VIEW_IOU", "REDUCTION", "verify_answer", "verify_reconstruction", "check_model",
           "check_grasp", "reduced_silhouettes", "reduced_camera", "model_iou"]

#: The least intersection over union of the model's projection and the daemon's own silhouette,
#: in every view, at a quarter scale.
MIN_VIEW_IOU = 0.3
#: The pictures are decoded at 1/REDUCTION of their size.
REDUCTION = 4
_SUBPIXEL_BITS = 4
# How far the grasp's claimed width may be from the model's width between the pads: a share of
# the width, and at least this many metres (the planner's width is the widest chord under the
# pads, sampled; ours is sampled too).
_WIDTH_SHARE, _WIDTH_FLOOR = 0.1, 0.002
# Samples along the closing line, across the finger and along it.
_LINE_SAMPLES = 241
_ACROSS_SAMPLES, _ALONG_SAMPLES = 5, 9
#: How much larger (where a grasp must meet the model) and smaller (where the gripper must keep
#: clear of it) the model is taken, as a share of its sizes: see :func:`check_grasp`.
MODEL_SLACK = 0.15
# A corner of the gripper may lie this far (metres) below the support plane before it counts:
# rounding of the poses on the wire, no more (the planner keeps a clearance of centimetres).
_PLANE_SLACK = 1e-4


@dataclass(frozen=True)
class Verdict:
    """The check of one answer: ``ok``, and ``reason``, one line saying what is wrong (or what passed).

    ``ious`` are the model's per-view intersection over union with the daemon's silhouettes;
    ``grasps`` the indices of the answer's grasps that follow from the model (only these may be
    used), ``dropped`` why each other one does not.
    """

    ok: bool
    reason: str
    ious: tuple[float, ...] = ()
    grasps: tuple[int, ...] = ()
    dropped: tuple[str, ...] = ()


def _core(model: Superquadric) -> CoreSuperquadric:
    return CoreSuperquadric(np.asarray(model.size), np.asarray(model.shape), np.asarray(model.T_world_object))


def reduced_camera(K, T_world_cam, dist=None, *, view: int | None = None) -> Camera:
    """The camera of a picture decoded at 1/:data:`REDUCTION` of its size.

    A decoder that scales by ``r`` makes pixel ``u'`` of the small picture from pixels
    ``r u' .. r u' + r - 1`` of the large one, whose centre is ``r u' + (r - 1) / 2``.
    """
    scale = np.array([[1 / REDUCTION, 0, -(REDUCTION - 1) / (2 * REDUCTION)],
                      [0, 1 / REDUCTION, -(REDUCTION - 1) / (2 * REDUCTION)], [0, 0, 1]])
    return Camera(K=scale @ np.asarray(K, dtype=np.float64), T_world_cam=T_world_cam, dist=dist, view=view)


def _decoded_reduced(jpeg: bytes, view: int) -> np.ndarray:
    image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_REDUCED_COLOR_4)
    if image is None:
        raise CoreError(f"view {view}: the picture cannot be decoded")
    return image


def _segmented(jpeg: bytes, segmentation: Segmentation, view: int) -> np.ndarray:
    """The silhouette at 1/:data:`REDUCTION` scale; for an object too small to survive the small
    picture's clean-up, segmented at full size and reduced."""
    small = _decoded_reduced(jpeg, view)
    try:
        return segment(small, segmentation, view=view)
    except CoreError:
        full = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
        if full is None:
            raise
        silhouette = segment(full, segmentation, view=view)
        reduced = cv2.resize(silhouette, (small.shape[1], small.shape[0]), interpolation=cv2.INTER_AREA)
        return np.where(reduced >= 128, 255, 0).astype(np.uint8)


def _auto_full_size(jpegs: Sequence[bytes], cameras: Sequence[Camera], support_plane: Sequence[float] | None,
                    shapes: Sequence[tuple[int, ...]]) -> list[np.ndarray]:
    """The auto segmentation of the full pictures, reduced to ``shapes``."""
    unscale = np.linalg.inv(reduced_camera(np.eye(3), np.eye(4)).K)
    full = [Camera(K=unscale @ camera.K, T_world_cam=camera.T_world_cam, dist=camera.dist, view=camera.view)
            for camera in cameras]
    images = []
    for view, jpeg in enumerate(jpegs):
        image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            raise CoreError(f"view {view}: the picture cannot be decoded")
        images.append(image)
    reduced = []
    for (silhouette, _), shape in zip(auto_silhouettes(images, full, support_plane=support_plane), shapes):
        small = cv2.resize(silhouette, (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
        reduced.append(np.where(small >= 128, 255, 0).astype(np.uint8))
    return reduced


def reduced_silhouettes(jpegs: Sequence[bytes], segmentation: Segmentation,
                        cameras: Sequence[Camera], support_plane: Sequence[float] | None = None) -> list[np.ndarray]:
    """Each picture decoded at 1/:data:`REDUCTION` of its size, segmented, and undistorted to the
    ideal pinhole ``cameras`` (:func:`reduced_camera`) where they have a distortion.

    Raises
    ------
    CoreError
        Naming the view whose picture cannot be decoded or holds no object.
    """
    if segmentation.method == "auto":  # the cell's default; it sees all the views at once
        images = [_decoded_reduced(jpeg, view) for view, jpeg in enumerate(jpegs)]
        try:
            found = [silhouette for silhouette, _ in auto_silhouettes(images, cameras, support_plane=support_plane)]
        except CoreError:  # too little of it left in the small pictures (low views, a thin object)
            found = _auto_full_size(jpegs, cameras, support_plane, [image.shape for image in images])
    silhouettes = []
    for view, (jpeg, camera) in enumerate(zip(jpegs, cameras)):
        silhouette = found[view] if segmentation.method == "auto" else _segmented(jpeg, segmentation, view)
        silhouettes.append(silhouette if camera.dist is None else undistort_mask(silhouette, camera))
    return silhouettes


def model_iou(parts: Sequence[CoreSuperquadric], camera: Camera, silhouette: np.ndarray) -> float:
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


def check_model(parts: Sequence[CoreSuperquadric], cameras: Sequence[Camera], silhouettes: Sequence[np.ndarray],
                min_iou: float = MIN_VIEW_IOU) -> Verdict:
    """Whether the model's projection covers the daemon's own silhouette in every view."""
    ious = tuple(round(model_iou(parts, camera, s), 4) for camera, s in zip(cameras, silhouettes))
    worst = int(np.argmin(ious))
    if ious[worst] < min_iou:
        return Verdict(False, f"the model does not match the pictures: view {worst} overlaps its silhouette by "
                              f"{ious[worst]:.2f} (at least {min_iou:.2f} needed)", ious)
    return Verdict(True, f"the model matches the pictures (overlap {min(ious):.2f} or more in every view)", ious)


def _inside(parts: Sequence[CoreSuperquadric], points: np.ndarray) -> np.ndarray:
    """(N,) True where a point is inside the union of the parts."""
    inside = np.zeros(len(points), bool)
    for part in parts:
        inside |= inside_outside(points, part) < 1.0
    return inside


def _scaled(parts: Sequence[CoreSuperquadric], factor: float) -> list[CoreSuperquadric]:
    return [CoreSuperquadric(part.size * factor, part.shape, part.T_world_object) for part in parts]


def check_grasp(grasp: Grasp, parts: Sequence[CoreSuperquadric], gripper: Gripper,
                support_plane: Sequence[float] | None) -> str | None:
    """Why a grasp does not follow from the model and the gripper, or None when it does.

    The checks, in the grasp frame (DESIGN.md §3: z the approach, y the closing
    direction, the origin between the pads): the width fits the opening; no finger or
    palm corner lies below the support plane; the model is between the pads (the
    contacts are on it); the model's widest chord under the pads is the claimed
    ``width``; no part of the model is where the open fingers or the palm are.

    The planner works on the model as the worker returned it but for what the fit
    cannot know (it sets a fit tilted by a few degrees upright; it keeps the palm clear
    of the hull), so the model is taken :data:`MODEL_SLACK` larger where the grasp must
    meet it and as much smaller where the gripper must keep clear of it: a grasp moved
    off the object, or too wide, or under the table is refused, the planner's own pass.
    """
    T = np.asarray(grasp.T_world_grasp, dtype=np.float64)
    R, origin = T[:3, :3], T[:3, 3]
    g = gripper
    half_open = g.max_opening / 2
    if grasp.width > g.max_opening:
        return f"its width {grasp.width:.3f} m is more than the gripper opens ({g.max_opening:.3f} m)"
    if support_plane is not None:
        plane = np.asarray(support_plane, dtype=np.float64)
        plane = plane / np.linalg.norm(plane[:3])
        corners = g.corners() @ R.T + origin
        lowest = float((corners @ plane[:3] + plane[3]).min())
        if lowest < -_PLANE_SLACK:
            return f"a corner of the gripper would be {-lowest * 1000:.1f} mm below the support plane"
    grown, shrunk = _scaled(parts, 1 + MODEL_SLACK), _scaled(parts, 1 - MODEL_SLACK)

    def inside(model, x, y, z) -> np.ndarray:
        local = np.stack(np.broadcast_arrays(x, y, z), axis=-1)
        return _inside(model, local.reshape(-1, 3) @ R.T + origin).reshape(local.shape[:-1])

    # Under the pads: the contacts are where the model meets the pads' faces.
    t = np.linspace(-half_open - g.finger_thickness, half_open + g.finger_thickness, _LINE_SAMPLES)
    across = np.linspace(-g.finger_width / 2, g.finger_width / 2, _ACROSS_SAMPLES)
    X, Y, Z = np.meshgrid(across, t, np.linspace(g.tip - g.pad_length, g.tip, _ALONG_SAMPLES), indexing="ij")
    met = inside(grown, X, Y, Z)
    if not met.any():
        return "the model is not between its pads"

    def widest(mask: np.ndarray) -> float:
        # The chord of each (across, along) column of samples: from its lowest inside sample to its highest.
        chords = np.where(mask, Y, -np.inf).max(axis=1) - np.where(mask, Y, np.inf).min(axis=1)
        return float(chords[np.isfinite(chords)].max(initial=0.0))

    most, least = widest(met), widest(inside(shrunk, X, Y, Z))
    slack = max(_WIDTH_SHARE * grasp.width, _WIDTH_FLOOR)
    if not least - slack <= grasp.width <= most + slack:
        return f"its width {grasp.width:.3f} m is not the model's between the pads ({least:.3f}-{most:.3f} m)"
    X, Y, Z = np.meshgrid(across, t, np.linspace(g.palm, g.tip, _ALONG_SAMPLES), indexing="ij")
    if (inside(shrunk, X, Y, Z) & (np.abs(Y) >= half_open)).any():
        return "the open fingers would cut the model"
    palm_x, palm_y = np.meshgrid(np.linspace(-g.palm_width / 2, g.palm_width / 2, _ACROSS_SAMPLES + 2),
                                 np.linspace(-half_open - g.finger_thickness, half_open + g.finger_thickness,
                                             _ACROSS_SAMPLES + 2), indexing="ij")
    if inside(shrunk, palm_x, palm_y, g.palm).any():
        return "the palm would cut the model"
    return None


def verify_reconstruction(result: Reconstruction, jpegs: Sequence[bytes], cameras: Sequence[Camera],
                          segmentation: Segmentation, support_plane: Sequence[float] | None,
                          gripper: Gripper | None, *, min_iou: float = MIN_VIEW_IOU) -> Verdict:
    """Whether a worker's answer agrees with the job's pictures and its grasps with the gripper.

    Parameters
    ----------
    result : Reconstruction
        The worker's answer (its model, as ``superquadric`` and, where the answer has
        them, ``parts``; its grasps).
    jpegs : sequence of bytes
        The pictures the daemon itself took, one per view, in order.
    cameras : sequence of Camera
        Each picture's camera at 1/:data:`REDUCTION` scale (:func:`reduced_camera`).
    segmentation : Segmentation
        How the job's pictures are segmented (the request's, or the default).
    support_plane : (4,) sequence of float, optional
    gripper : Gripper, optional
        The cell's gripper; None: the grasps are not checked (the job asked for none).

    Returns
    -------
    Verdict
        ``ok`` False, with a one-line ``reason``, for an answer the daemon must refuse.

    Examples
    --------
    See ``tests/test_verify.py``: a correct reconstruction passes, a model 8 times too
    big is refused, and so is a grasp moved off the model.
    """
    if len(jpegs) != len(cameras):
        return Verdict(False, f"{len(jpegs)} pictures but {len(cameras)} cameras")
    try:
        parts = [_core(part) for part in (getattr(result, "parts", None) or [result.superquadric])]
        silhouettes = reduced_silhouettes(jpegs, segmentation, cameras, support_plane)
    except (CoreError, ValueError) as exc:
        return Verdict(False, f"the answer cannot be checked: {exc}")
    verdict = check_model(parts, cameras, silhouettes, min_iou)
    if not verdict.ok or gripper is None or not result.grasps:
        return verdict
    kept, dropped = [], []
    for index, grasp in enumerate(result.grasps):
        problem = check_grasp(grasp, parts, gripper, support_plane)
        if problem is None:
            kept.append(index)
        else:
            dropped.append(f"grasp {index}: {problem}")
    if not kept:
        return Verdict(False, f"no grasp of the answer follows from its model ({dropped[0]})", verdict.ious,
                       (), tuple(dropped))
    told = f"; {len(dropped)} of its {len(result.grasps)} grasps dropped ({dropped[0]})" if dropped else ""
    return Verdict(True, f"{verdict.reason}; {len(kept)} grasps follow from it{told}", verdict.ious, tuple(kept),
                   tuple(dropped))


def verify_answer(answer: Reconstruction, request: ReconstructRequest, pictures: Sequence[Picture],
                  config: CellConfig) -> Verdict:
    """:func:`verify_reconstruction` of a worker's answer to ``request``, with the job's ``pictures``
    (the daemon's own, ``job.captures``) and the cell's camera, support plane and gripper: the
    daemon's one call, before it stores a result. Grasps are checked when the request asked for
    them (``request.gripper``)."""
    try:
        segmentation = core_segmentation(request.segmentation)
        cameras = [reduced_camera(config.camera.K, picture.T_base_cam, config.camera.dist, view=view)
                   for view, picture in enumerate(pictures)]
        gripper = None if request.gripper is None else Gripper.from_dict(request.gripper)
    except (CoreError, ValueError) as exc:
        return Verdict(False, f"the answer cannot be checked: {exc}")
    return verify_reconstruction(answer, [picture.jpeg for picture in pictures], cameras, segmentation,
                                 request.support_plane, gripper)
