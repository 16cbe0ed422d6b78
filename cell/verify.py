"""No reconstruction worker is trusted with the robot: its answer is checked against what the daemon holds.

A worker's answer (a model, grasps) comes from a process the daemon cannot
vouch for: any session the router lets into the pool can answer (issue 23: a
fake worker's model 8-10 times too big was stored, and its grasp drove the arm).
The daemon holds the pictures of the job and knows its cameras, its support
plane and its gripper, so it can check the answer cheaply before storing or
using it (:func:`check_answer`; :func:`verify_reconstruction` in one call):

- **The model agrees with the pictures.** Each picture is decoded at a quarter
  of its size (``cv2.IMREAD_REDUCED_COLOR_4``: the JPEG decoder scales as it
  decodes, so this costs a fraction of a full decode) and segmented as the job's
  segmentation says; the model (the union of its parts) is projected into each
  view, and the intersection over union of projection and silhouette must reach
  :data:`MIN_VIEW_IOU` in every view. The worker's own silhouettes are never
  used: they are what a fake worker would forge first.
- **Every grasp follows from the model and the gripper** (:func:`check_grasp`; the
  geometry of both checks is ``robocell.core_cy.model_check``):
  the pads' centre line meets the model, the width the grasp claims is no less
  than the model's between the pads and fits the opening, the open fingers and the palm
  do not cut the model, the contacts are antipodal within the friction cone, and
  no finger or palm corner lies below the support plane.

Everything here is a pure function of bytes and arrays: no I/O, no clock. The
daemon calls it before it stores a result; a result that fails is a failed
attempt, sent again elsewhere (``ReconstructorPool.refuse``).

When it runs. The daemon's silhouettes depend on its pictures alone, never on an
answer, so the daemon makes them once per job (:func:`job_evidence`, an
:class:`Evidence`), in a thread, from the moment it sends the pictures to the
first worker: they are ready, as a rule, before any answer comes, and every
attempt's answer is checked against the same evidence (:func:`check_answer`).
What is left on the job's path is the answer's own part: projecting the model
into each small silhouette, and the grasps (below). The check is the one it
was: the same silhouettes at the same scale, the same overlap, the same
threshold, the same grasp tests with the same samples; only when the silhouettes
are made changed, and how the grasp test evaluates the model (compiled, only
inside each part's box, where alone a point can be inside, and along each line
of samples under the pads only from its ends in to the model, as the widest
chord needs no more): on 600 grasps, honest and moved by up to 3 cm or given a
wrong width, of models of one part and of two, every verdict is the one of the
former code, at a sixth of its cost. On the 138 scans below
(``bench/probe_verify.py``), making the evidence costs 0.41 of the scan's
reconstruction on average (0.71 at worst) and the check of an answer 0.016
(0.066 at worst, an answer of many grasps).

Why the threshold (:data:`MIN_VIEW_IOU`, 0.3), re-measured with ``bench/probe_verify.py``
on the simulator's scans (``robocell sim scans``, the standard set and the grasp
set, 138 scans; each reconstructed by the real pipeline with the ``auto``
segmentation, as a worker does): the worst view of a correct reconstruction
scores 0.475 at this scale (an L of two boxes; 0.535 for a plate, 0.85 the
median), and a model 8 to 10 times too big scores 0.185 at most (0.04 the
median): none of the 138 honest fits is refused, and none of the 276 oversized
ones passes. A model 1.5 times too big still scores up to 0.71 (all 138 pass):
this check catches a model of something else, or far too big or small, not a
fit that is a little off. Of the honest answers' 856 grasps, all follow from
their models.

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
from robocell.core_cy.model_check import MIN_VIEW_IOU, grasp_problem, model_iou
from robocell.core_cy.segment import Segmentation, segment
from robocell.core_cy.superquadric import Superquadric as CoreSuperquadric
from robocell.wire.segmentation import core_segmentation
from robocell.wire.config import CellConfig
from robocell.wire.messages import Grasp, Reconstruction, ReconstructRequest, Superquadric

from .job import Picture

__all__ = ["Verdict", "Evidence", "MIN_VIEW_IOU", "REDUCTION", "job_evidence", "check_answer", "verify_answer",
           "verify_reconstruction", "check_model", "check_grasp", "reduced_silhouettes", "reduced_camera", "model_iou"]

#: The pictures are decoded at 1/REDUCTION of their size.
REDUCTION = 4


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


def check_model(parts: Sequence[CoreSuperquadric], cameras: Sequence[Camera], silhouettes: Sequence[np.ndarray],
                min_iou: float = MIN_VIEW_IOU) -> Verdict:
    """Whether the model's projection covers the daemon's own silhouette in every view."""
    ious = tuple(round(model_iou(parts, camera, s), 4) for camera, s in zip(cameras, silhouettes))
    worst = int(np.argmin(ious))
    if ious[worst] < min_iou:
        return Verdict(False, f"the model does not match the pictures: view {worst} overlaps its silhouette by "
                              f"{ious[worst]:.2f} (at least {min_iou:.2f} needed)", ious)
    return Verdict(True, f"the model matches the pictures (overlap {min(ious):.2f} or more in every view)", ious)


def check_grasp(grasp: Grasp, parts: Sequence[CoreSuperquadric], gripper: Gripper,
                support_plane: Sequence[float] | None) -> str | None:
    """Why a grasp of an answer does not follow from the model and the gripper, or None when it does
    (:func:`robocell.core_cy.model_check.grasp_problem`)."""
    return grasp_problem(np.asarray(grasp.T_world_grasp, dtype=np.float64), grasp.width, parts, gripper,
                         support_plane)


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
        silhouettes = reduced_silhouettes(jpegs, segmentation, cameras, support_plane)
    except (CoreError, ValueError) as exc:
        return Verdict(False, f"the answer cannot be checked: {exc}")
    return check_answer(result, Evidence(tuple(cameras), tuple(silhouettes), support_plane, gripper), min_iou=min_iou)


@dataclass(frozen=True)
class Evidence:
    """What the daemon holds of a job to check answers against, all of it its own: each picture's
    camera at 1/:data:`REDUCTION` scale and its silhouette there (:func:`reduced_silhouettes`), the
    support plane and the gripper (None: grasps are not checked); or, in ``problem``, why the
    pictures cannot serve (every answer is then refused, saying so).

    It depends on the pictures alone, not on any answer: the daemon makes it once per job, while the
    first worker reconstructs (:func:`job_evidence`), and checks every attempt's answer against it.
    """

    cameras: tuple[Camera, ...]
    silhouettes: tuple[np.ndarray, ...]
    support_plane: Sequence[float] | None
    gripper: Gripper | None
    problem: str | None = None


def check_answer(result: Reconstruction, evidence: Evidence, *, min_iou: float = MIN_VIEW_IOU) -> Verdict:
    """Whether a worker's answer agrees with the daemon's ``evidence``: its model with the silhouettes
    (:func:`check_model`), its grasps with the model and the gripper (:func:`check_grasp`)."""
    if evidence.problem is not None:
        return Verdict(False, f"the answer cannot be checked: {evidence.problem}")
    try:
        parts = [_core(part) for part in (getattr(result, "parts", None) or [result.superquadric])]
    except (CoreError, ValueError) as exc:
        return Verdict(False, f"the answer cannot be checked: {exc}")
    gripper, support_plane = evidence.gripper, evidence.support_plane
    verdict = check_model(parts, evidence.cameras, evidence.silhouettes, min_iou)
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


def job_evidence(request: ReconstructRequest, pictures: Sequence[Picture], config: CellConfig) -> Evidence:
    """The daemon's :class:`Evidence` of a job: its ``pictures`` (``job.captures``) segmented as
    ``request`` asks, with the cell's camera, support plane and gripper (grasps are checked when the
    request asked for them, ``request.gripper``). It never raises: a problem is kept in the evidence."""
    try:
        segmentation = core_segmentation(request.segmentation)
        cameras = tuple(reduced_camera(config.camera.K, picture.T_base_cam, config.camera.dist, view=view)
                        for view, picture in enumerate(pictures))
        gripper = None if request.gripper is None else Gripper.from_dict(request.gripper)
        silhouettes = reduced_silhouettes([picture.jpeg for picture in pictures], segmentation, cameras,
                                          request.support_plane)
    except (CoreError, ValueError) as exc:
        return Evidence((), (), request.support_plane, None, str(exc))
    return Evidence(cameras, tuple(silhouettes), request.support_plane, gripper)


def verify_answer(answer: Reconstruction, request: ReconstructRequest, pictures: Sequence[Picture],
                  config: CellConfig) -> Verdict:
    """:func:`check_answer` of a worker's answer to ``request`` against the :func:`job_evidence` of the
    job's ``pictures``: the daemon's check in one call (the daemon itself makes the evidence once per job)."""
    return check_answer(answer, job_evidence(request, pictures, config))
