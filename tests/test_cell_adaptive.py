"""Adaptive scans in the simulated cell: one more view at a time while the model is unsure, and a
daemon killed during a plan that grew carries that plan on.

The reconstruction worker runs in the test process with the real core; the choice of the next view
(``core_cy.next_view``) is a stand-in of this file whose verdict the test sets (sure after so many
views), so that what is tested is the cell's side: it asks with poses the robot may take, takes the
view chosen, stops when the model is sure, and stops at the cap. The last test lets the core's own
choice through the same worker. One cell serves the module.
"""

from __future__ import annotations

import asyncio
import threading
import types
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pytest

from robocell.core_cy.plan import workspace_violation
from robocell.wire.messages import JobState, ReconstructRequest, ScanRequest
import robocell.workers.reconstruct.worker as worker_module
from robocell.workers.reconstruct.worker import reconstruct_request
from robocell.workers.sim.scene import target_from_config

from tests.cell_fixtures import SMALL_CAMERA, InProcessWorker, cell_config, running_cell, wait_until


@dataclass
class StandIn:
    """``core_cy.next_view.choose_next_view`` as the test wants it: sure once the scan has
    ``sure_at`` views; until then the candidate farthest from every view so far. With ``sure_at``
    None, the core's own choice (``core``)."""

    core: Callable
    sure_at: int | None = 3
    asked: list[tuple[int, list[np.ndarray]]] = field(default_factory=list)  # (views so far, candidate camera poses)

    def choose_next_view(self, reconstruction, cameras, candidates, *, support_plane=None, workspace=None):
        if self.sure_at is None:
            return self.core(reconstruction, cameras, candidates, support_plane=support_plane, workspace=workspace)
        assert len(cameras) == len(reconstruction.silhouettes)
        poses = [np.asarray(c.T_world_cam) for c in candidates]
        self.asked.append((len(cameras), poses))
        sure = len(cameras) >= self.sure_at
        seen = [np.asarray(c.T_world_cam)[:3, 2] for c in cameras]
        far = int(np.argmin([max(float(p[:3, 2] @ axis) for axis in seen) for p in poses]))
        return types.SimpleNamespace(candidate=None if sure else far, T_world_cam=poses[far],
                                     expected_gain=0.0 if sure else 0.05, uncertainty=0.01 if sure else 0.2,
                                     sure=sure)


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """An ellipsoid longest along x, on the simulated table (the core's own choice is tested on it);
    the stand-in's verdicts do not depend on the object."""
    config = cell_config(tmp_path_factory.mktemp("adaptive"), cell_id="adaptive", camera=SMALL_CAMERA,
                         sim={"shape": "ellipsoid", "size": [0.07, 0.03, 0.025], "position": [0.6, 0.0], "yaw_deg": 0})
    before = worker_module.choose_next_view
    stand_in = StandIn(core=before)
    worker_module.choose_next_view = stand_in.choose_next_view  # the worker runs in this process
    gate = threading.Event()
    gate.set()
    held = threading.Event()

    async def run(request_json: str, payload: bytes) -> tuple[str, bytes]:
        if not gate.is_set() and len(ReconstructRequest.model_validate_json(request_json).views) >= 4:
            held.set()  # the reconstruction of a grown plan: kept here until the test lets go
            await asyncio.to_thread(gate.wait, 30.0)
        return await asyncio.to_thread(reconstruct_request, request_json, payload, "stand-in")

    try:
        with running_cell(config, reconstructors=0) as cell:
            worker = InProcessWorker(cell.loop, cell.router, "stand-in", run)
            try:
                wait_until(lambda: [r.worker for r in cell.status().reconstructors] == ["stand-in"], timeout=20,
                           what="the in-process worker in the pool")
                yield cell, stand_in, gate, held
            finally:
                gate.set()
                worker.close()
    finally:
        worker_module.choose_next_view = before


def adaptive(cell, **fields) -> ScanRequest:
    return ScanRequest(target=target_from_config(cell.config.sim), views="adaptive", **fields)


def _views_taken(cell, job_id: str) -> list[int]:
    return [e.view for e in cell.events(job_id) if e.state is JobState.CAPTURING]


def test_a_model_sure_after_three_views_takes_no_fourth(rig):
    cell, stand_in, _, _ = rig
    stand_in.sure_at, stand_in.asked[:] = 3, []
    result = cell.client.scan(adaptive(cell), timeout=60)
    assert len(result.T_base_cam) == 3 and result.uncertainty == pytest.approx(0.01)
    assert [views for views, _ in stand_in.asked] == [3]
    assert _views_taken(cell, result.job_id) == [0, 1, 2]
    assert any("the model is sure after 3 views" in e.message for e in cell.events(result.job_id))


def test_an_unsure_model_takes_the_fourth_view_it_chose_among_poses_the_robot_may_take(rig):
    cell, stand_in, _, _ = rig
    stand_in.sure_at, stand_in.asked[:] = 4, []
    result = cell.client.scan(adaptive(cell), timeout=60)
    assert [views for views, _ in stand_in.asked] == [3, 4]
    assert _views_taken(cell, result.job_id) == [0, 1, 2, 3] and len(result.T_base_cam) == 4
    _, candidates = stand_in.asked[0]
    hand_eye_inverse = np.linalg.inv(np.asarray(cell.config.T_flange_cam))
    assert len(candidates) >= 6
    for T_cam in candidates:  # every candidate is a camera pose whose flange pose is in the workspace
        assert workspace_violation(T_cam @ hand_eye_inverse, cell.config.robot.workspace) is None
    # The fourth picture was taken where the stand-in chose (the robot's own pose, read back).
    seen = [np.asarray(T)[:3, 2] for T in result.T_base_cam[:3]]
    far = int(np.argmin([max(float(p[:3, 2] @ axis) for axis in seen) for p in candidates]))
    np.testing.assert_allclose(result.T_base_cam[3], candidates[far], atol=1e-3)


def test_a_model_never_sure_ends_at_the_cap_with_its_uncertainty(rig):
    cell, stand_in, _, _ = rig
    stand_in.sure_at, stand_in.asked[:] = 99, []
    result = cell.client.scan(adaptive(cell, max_views=5), timeout=90)
    assert len(result.T_base_cam) == 5 and result.uncertainty == pytest.approx(0.2)
    assert [views for views, _ in stand_in.asked] == [3, 4, 5]  # at five, to report its uncertainty
    messages = [e.message for e in cell.events(result.job_id)]
    assert any("the scan has its 5 views: ending with a model still unsure" in m for m in messages)


def test_a_planned_scan_does_not_ask_for_a_next_view(rig):
    cell, stand_in, _, _ = rig
    stand_in.sure_at, stand_in.asked[:] = 3, []
    result = cell.client.scan(ScanRequest(target=target_from_config(cell.config.sim)), timeout=60)
    assert len(result.T_base_cam) == 3 and result.uncertainty is None and stand_in.asked == []


def test_a_daemon_killed_during_a_grown_plan_carries_that_plan_on(rig):
    """Killed while the fourth view's reconstruction waits at the worker: restarted, the daemon sends
    the four pictures it kept again, takes no picture again, and the job ends with four views."""
    cell, stand_in, gate, held = rig
    stand_in.sure_at, stand_in.asked[:] = 4, []
    gate.clear()
    held.clear()
    try:
        status = cell.client.submit(adaptive(cell))
        assert held.wait(30), "the grown plan's reconstruction never reached the worker"
        before = _views_taken(cell, status.job_id)
        assert before == [0, 1, 2, 3]
        assert cell.loop.run(cell.processes.stop_child("daemon", kill=True)) == -9
        cell.loop.run(cell.processes.start_child("daemon"))
        wait_until(lambda: any("carrying on from step 6 of 6" in e.message for e in cell.events(status.job_id)),
                   timeout=30, what="the restarted daemon to carry the grown plan on")
    finally:
        gate.set()
    final = cell.wait(status.job_id)
    assert final.state is JobState.SUCCEEDED, final.error
    assert _views_taken(cell, status.job_id) == before  # no picture taken again
    assert len(cell.client.result(status.job_id).T_base_cam) == 4
    assert cell.tracebacks() == {}


# --- with the core's own choice (core_cy.next_view), in the same worker -------------------------

def test_with_the_core_an_adaptive_scan_takes_a_fourth_view_only_when_the_model_is_unsure(rig):
    """Three nearly coincident low views from one side, along the object's length, leave its depth
    unseen (the fit recovers it from views spread over 20-40 degrees of elevation): the core is
    unsure and a fourth view is taken. Three views all around it leave nothing unseen: none is."""
    cell, stand_in, _, _ = rig
    stand_in.sure_at = None
    target = target_from_config(cell.config.sim)
    one_side = {"standoff": 0.4, "elevations_deg": [10.0, 11.0, 12.0], "azimuths_deg": [179.0, 180.0, 181.0]}
    unsure = cell.client.scan(ScanRequest(target=target, plan=one_side, views="adaptive", max_views=4), timeout=120)
    messages = [e.message for e in cell.events(unsure.job_id)]
    assert len(unsure.T_base_cam) == 4, messages
    assert any("the model is unsure" in m and "taking view 3" in m for m in messages)
    around = cell.client.scan(ScanRequest(target=target, views="adaptive", max_views=4), timeout=120)
    messages = [e.message for e in cell.events(around.job_id)]
    assert len(around.T_base_cam) == 3, messages
    assert any("the model is sure after 3 views" in m for m in messages)
