"""The steps of a pick (``cell.steps``): choose a grasp the robot can reach, open, approach, close,
lift, and with a place carry it over and set it down."""

from __future__ import annotations

import logging

from typing import Any

import numpy as np

from robocell.core_cy.plan import workspace_violation
from robocell.core_cy.views import pick_poses as _pick_poses
from robocell.wire import keys
from robocell.wire.config import CellConfig
from robocell.wire.messages import GripReply, GripRequest, JobState, MoveReply, MoveRequest, PickOutcome, PickRequest

from .job import Job
from .steps import Cell, Step, StepFailed, parse_reply

__all__ = ["ChooseGrasp", "PickMove", "Gripper", "PLACE_POSES", "pick_poses"]


class ChooseGrasp(Step):
    """The best of the result's grasps whose every pose the robot may take; the poses of the pick.

    Fails before any motion: with no grasp at all ("no grasp holds this object"), or when the
    robot may reach none (naming the limit the best one breaks). It begins the pick: a restart
    that finds it begun does not pick again (``cell.handle``: the gripper may hold the object).
    """

    kind = "choose_grasp"
    activity = JobState.PICKING

    def describe(self) -> str:
        return "choosing a grasp"

    async def run(self, job: Job, cell: Cell) -> None:
        assert job.result is not None, "the reconstruction leaves the result"
        pick = job.request.pick
        assert pick is not None, "a pick's steps come with a pick request"
        if not job.result.grasps:
            raise StepFailed("no grasp holds this object", kind="NoGrasp")
        first_problem = None
        workspace = cell.config.robot.workspace
        for index, grasp in enumerate(job.result.grasps):
            # The gripper is symmetric under a half turn about its approach: take the turn the wrist prefers.
            for turned in (False, True):
                poses = pick_poses(np.asarray(grasp.T_world_grasp), pick, cell.config, half_turn=turned)
                problem = next(((name, why) for name, pose in poses.items()
                                if (why := workspace_violation(pose, workspace))), None)
                if problem is None:
                    job.pick_poses = poses
                    cell.record(job, "log_grasps", [g.T_world_grasp for g in job.result.grasps],
                                [g.width for g in job.result.grasps], index, cell.config.gripper.dimensions())
                    job.result.pick = PickOutcome(grasp=index, T_base_flange=poses["grasp"].tolist(), held=None)
                    return None
                first_problem = first_problem or problem
        assert first_problem is not None
        name, why = first_problem
        raise StepFailed(f"no grasp is within the robot's reach: the best one's {name} pose: {why}", kind="MoveRefused")


class PickMove(Step):
    """Move the flange to one of the pick's poses."""

    kind = "pick_move"
    activity = JobState.PICKING
    needs_robot = True

    def __init__(self, pose: str, doing: str) -> None:
        self.pose, self.doing = pose, doing

    def describe(self) -> str:
        return self.doing

    def _fields(self) -> dict[str, Any]:
        return {"pose": self.pose, "doing": self.doing}

    async def run(self, job: Job, cell: Cell) -> None:
        if self.pose in PLACE_POSES and not _holding(job):
            return None  # nothing in the gripper to put down
        reply = await cell.ask(job, "robot", keys.robot_move(cell.config.cell_id),
                               MoveRequest(T_base_flange=job.pick_poses[self.pose].tolist(), job_id=job.job_id),
                               cell.config.timeouts.move_s)
        moved = parse_reply(MoveReply, reply.payload, "the robot worker")
        job.durations_s[f"pick {self.pose}"] = moved.duration_s
        cell.record(job, "log_robot_pose", np.asarray(moved.T_base_flange))
        return None


class Gripper(Step):
    """Open or close the gripper; closing on the object says whether it holds it. A release that
    puts the object down (``places``) is skipped when the gripper missed it."""

    kind = "gripper"
    activity = JobState.PICKING
    needs_robot = True

    def __init__(self, close: bool, doing: str, *, places: bool = False) -> None:
        self.close, self.doing, self.places = close, doing, places

    def describe(self) -> str:
        return self.doing

    def _fields(self) -> dict[str, Any]:
        return {"close": self.close, "doing": self.doing, "places": self.places}

    async def run(self, job: Job, cell: Cell) -> None:
        assert job.result is not None and job.result.pick is not None
        pick = job.result.pick
        if self.places and not _holding(job):
            return None
        reply = await cell.ask(job, "robot", keys.robot_grip(cell.config.cell_id),
                               GripRequest(close=self.close, job_id=job.job_id), cell.config.timeouts.move_s)
        grip = parse_reply(GripReply, reply.payload, "the robot worker")
        if self.close:
            pick.held, pick.reason, pick.width = grip.holding, grip.reason, grip.width
            verdict = {True: "holds it", False: "missed it", None: "closed (the gripper cannot tell what it holds)"}
            why = f": {grip.reason}" if grip.reason and grip.holding is not True else ""
            # Holding it is the pick going as planned: news, not a warning.
            await cell.note(job, f"the gripper {verdict[grip.holding]}{why}",
                            level=logging.INFO if grip.holding else logging.WARNING)
        pick.placed = pick.placed or self.places
        return None


#: The pick's poses that put the object down: skipped when the gripper missed it.
PLACE_POSES = ("above place", "place", "away")


def _holding(job: Job) -> bool:
    pick = job.result.pick if job.result is not None else None
    return pick is not None and pick.held is not False


def pick_poses(T_world_grasp: np.ndarray, pick: PickRequest, config: CellConfig, *,
               half_turn: bool = False) -> dict[str, np.ndarray]:
    """The flange poses of a pick with this grasp (``core_cy.views.pick_poses``), as the cell's
    gripper is mounted."""
    return _pick_poses(T_world_grasp, config.gripper.T_flange_grasp, approach=pick.approach_m, lift=pick.lift_m,
                       place=pick.place, half_turn=half_turn)
