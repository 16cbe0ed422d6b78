"""A job's plan: the steps a request starts with, and where a restarted daemon carries a job on."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from robocell.core_cy.plan import plan_flange_poses
from robocell.core_cy.views import candidate_views
from robocell.wire.config import CellConfig
from robocell.wire.messages import JobState, Lifecycle, ScanRequest

from .job import Checkpoint, Job
from .pick import ChooseGrasp, Gripper, PickMove
from .steps import KeepBackgrounds, Reconstruct, Step, View

__all__ = ["job_steps", "step_from_spec", "resume", "flange_poses", "next_view_candidates"]

_STEPS: dict[str, type[Step]] = {cls.kind: cls for cls in (View, Reconstruct, ChooseGrasp, PickMove, Gripper,
                                                            KeepBackgrounds)}


def step_from_spec(spec: dict[str, Any]) -> Step:
    """The step that :meth:`Step.spec` wrote.

    Raises
    ------
    ValueError
        An unknown kind of step, or fields it does not take.
    """
    fields = dict(spec)
    kind = fields.pop("kind", None)
    if kind not in _STEPS:
        raise ValueError(f"unknown step {kind!r} in a checkpoint: expected one of {', '.join(_STEPS)}")
    try:
        return _STEPS[kind](**fields)
    except TypeError as exc:
        raise ValueError(f"step {kind!r} in a checkpoint: {exc}") from None


def flange_poses(request: ScanRequest, config: CellConfig) -> list[np.ndarray]:
    """The flange poses of a request's views: its own, else its plan's (or ``[scan]``'s) around its target."""
    if request.flange_poses is not None:
        return [np.asarray(pose, dtype=np.float64) for pose in request.flange_poses]
    return plan_flange_poses(request.target, request.plan or config.scan.plan, config.T_flange_cam)


def next_view_candidates(job: Job, config: CellConfig) -> list[np.ndarray]:
    """The camera poses an adaptive scan may take its next view from: around its target at its plan's
    standoff, within the robot's workspace, away from the views taken."""
    request = job.request
    assert request.target is not None, "an adaptive scan has a target"
    standoff = (request.plan or config.scan.plan).standoff
    return candidate_views(request.target, standoff, config.T_flange_cam, config.robot.workspace,
                           taken=[picture.T_base_cam for picture in job.captures])


def job_steps(request: ScanRequest, poses: list[np.ndarray]) -> list[Step]:
    """The plan of a request: a view at each pose, a reconstruction, and its pick if it asks for one;
    for a request of ``kind: backgrounds``, a view at each pose and the keeping of its pictures."""
    steps: list[Step] = [View(view, pose) for view, pose in enumerate(poses)]
    if request.kind == "backgrounds":
        return [*steps, KeepBackgrounds()]
    steps.append(Reconstruct())
    if request.pick is None:
        return steps
    steps += [ChooseGrasp(), Gripper(False, "opening the gripper"),
              PickMove("above", "moving above the grasp"), PickMove("grasp", "approaching"),
              Gripper(True, "closing the gripper"), PickMove("lift", "lifting")]
    if request.pick.place is not None:
        steps += [PickMove("above place", "carrying it over"), PickMove("place", "putting it down"),
                  Gripper(False, "letting go", places=True), PickMove("away", "backing away")]
    return steps


def resume(job: Job, checkpoint: str | None, fresh: Callable[[], list[Step]]) -> tuple[str, Lifecycle, str | None] | None:
    """Set a restarted daemon's ``job`` to carry on from its ``checkpoint`` (JSON; None: from a
    ``fresh`` plan); or how it ends instead, as (message, lifecycle, error kind): cancelled if it
    was cancelling, failed if its pick had begun (the gripper may hold the object) or its plan
    cannot be read back."""
    try:
        point = Checkpoint.model_validate_json(checkpoint) if checkpoint else None
        job.plan = [step_from_spec(spec) for spec in point.plan] if point is not None else fresh()
    except ValueError as exc:  # a checkpoint of another version, or the configuration changed
        point = None
        if job.lifecycle is not Lifecycle.CANCELLING:
            return f"planning: {exc}", Lifecycle.FAILED, "PlanError"
    if job.lifecycle is Lifecycle.CANCELLING:
        return "cancelled by request (before the daemon restarted)", Lifecycle.CANCELLED, None
    if point is not None and point.began is not None and job.plan[point.began].activity is JobState.PICKING:
        return ("picking: the daemon stopped during the pick: the gripper may still hold the object; "
                "not picked again", Lifecycle.FAILED, "PickInterrupted")
    job.done = point.done if point is not None else 0
    return None
