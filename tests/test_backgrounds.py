"""Backgrounds of the empty workspace (``cell/backgrounds.py``): kept by pose, found within the
tolerance, replaced at the same pose, deleted by retention; the request that takes them, its plan,
and the simulator's empty workspace while they are taken."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest
from pydantic import ValidationError

from robocell.cell.backgrounds import Backgrounds
from robocell.cell.plan import job_steps, step_from_spec
from robocell.cell.retention import apply_retention, disk_usage
from robocell.cell.store import JobStore
from robocell.wire.config import RetentionConfig
from robocell.wire.messages import BACKGROUND_POSE_TOLERANCE, JobEvent, JobState, Lifecycle, PickRequest, ScanRequest
from robocell.workers.sim.workspace import Workspace

K = [[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]]
SIZE = (64, 48)
DAY = 86400.0
NOW = 1_800_000_000.0


def _jpeg(value: int, size=SIZE) -> bytes:
    return cv2.imencode(".jpg", np.full((size[1], size[0], 3), value, np.uint8))[1].tobytes()


def _pose(x: float = 0.6, turn_deg: float = 0.0) -> np.ndarray:
    c, s = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = [x, 0.0, 0.5]
    return T


def _find(kept: Backgrounds, T: np.ndarray, **camera):
    return kept.find(T, **{"K": K, "dist": None, "size": SIZE, **camera})


def test_a_background_is_found_from_its_pose_within_the_tolerance_and_by_the_same_camera_only(tmp_path):
    kept = Backgrounds(tmp_path)
    kept.keep("job1", 0, _jpeg(100), _pose(), K=K, dist=None, now=NOW)
    metres, degrees = BACKGROUND_POSE_TOLERANCE
    assert metres == 0.001 and degrees == 0.1
    assert _find(kept, _pose(0.6 + 0.0005)).path.read_bytes() == _jpeg(100)
    assert _find(kept, _pose(turn_deg=0.05)) is not None
    assert _find(kept, _pose(0.6 + 0.002)) is None            # two pixels off at the object
    assert _find(kept, _pose(turn_deg=0.3)) is None
    assert _find(kept, _pose(), size=(128, 96)) is None        # another resolution
    assert _find(kept, _pose(), K=[[610.0, 0, 319.5], [0, 610.0, 239.5], [0, 0, 1]]) is None  # recalibrated
    assert _find(kept, _pose(), dist=[0.1, 0, 0, 0, 0]) is None
    assert _find(kept, _pose(), dist=[0, 0, 0, 0, 0]) is not None   # no distortion, said either way


def test_a_new_background_at_a_pose_replaces_the_old_one_and_leaves_the_others(tmp_path):
    kept = Backgrounds(tmp_path)
    kept.keep("job1", 0, _jpeg(100), _pose(), K=K, dist=None, now=NOW)
    kept.keep("job1", 1, _jpeg(110), _pose(0.7), K=K, dist=None, now=NOW)
    kept.keep("job2", 0, _jpeg(120), _pose(0.6 + 0.0003), K=K, dist=None, now=NOW + 60)
    assert sorted(b.path.name for b in kept.all()) == ["job1-1.jpg", "job2-0.jpg"]
    assert _find(kept, _pose()).path.read_bytes() == _jpeg(120)
    assert sorted(p.name for p in (tmp_path / "backgrounds").iterdir()) == [
        "job1-1.jpg", "job1-1.json", "job2-0.jpg", "job2-0.json"]   # no temporary file left


def test_a_picture_without_its_description_is_no_background(tmp_path):
    kept = Backgrounds(tmp_path)
    made = kept.keep("job1", 0, _jpeg(100), _pose(), K=K, dist=None, now=NOW)
    made.description.unlink()       # as a crash between the two writes would leave it
    assert kept.all() == [] and _find(kept, _pose()) is None
    (tmp_path / "backgrounds" / "job1-0.json").write_text("{not json")
    assert kept.all() == []


def test_retention_deletes_backgrounds_past_their_age_then_the_oldest_past_the_size(tmp_path):
    kept = Backgrounds(tmp_path)
    for view, age_days in enumerate([10.0, 3.0, 2.0, 1.0]):
        made = kept.keep("job1", view, _jpeg(100 + view), _pose(0.5 + 0.1 * view), K=K, dist=None,
                         now=NOW - age_days * DAY)
        for path in (made.path, made.description):
            os.utime(path, (NOW - age_days * DAY, NOW - age_days * DAY))
    one = sum(p.stat().st_size for p in (tmp_path / "backgrounds").glob("job1-1.*"))
    policy = RetentionConfig(backgrounds_max_age_days=7, backgrounds_max_mb=2.5 * one / 1024 / 1024)
    usage = disk_usage(tmp_path, policy, now=NOW)
    assert usage.backgrounds > 0 and usage.backgrounds_to_free > 0
    with JobStore(tmp_path / "jobs.sqlite") as store:
        report = apply_retention(tmp_path, store, policy, NOW)
    # The ten-day-old one by age, then the three-day-old one: two are left within the size.
    assert report.backgrounds_deleted == 2 and report.background_bytes_freed > 0
    assert sorted(b.path.name for b in kept.all()) == ["job1-2.jpg", "job1-3.jpg"]
    assert sorted(p.name for p in (tmp_path / "backgrounds").iterdir()) == [
        "job1-2.jpg", "job1-2.json", "job1-3.jpg", "job1-3.json"]
    assert "2 backgrounds" in report.summary()


def test_a_backgrounds_request_takes_the_scans_poses_and_keeps_the_pictures():
    request = ScanRequest(target=[0.6, 0.0, 0.05], kind="backgrounds")
    poses = [_pose(0.5), _pose(0.6), _pose(0.7)]
    steps = job_steps(request, poses)
    assert [step.kind for step in steps] == ["view", "view", "view", "keep-backgrounds"]
    assert [step_from_spec(step.spec()).spec() for step in steps] == [step.spec() for step in steps]
    assert ScanRequest(target=[0.6, 0.0, 0.05]).kind == "scan"


@pytest.mark.parametrize("fields", [{"pick": PickRequest()}, {"views": "adaptive"}])
def test_backgrounds_take_no_pick_and_no_adaptive_views(fields):
    with pytest.raises(ValidationError, match="kind: backgrounds photographs the empty workspace"):
        ScanRequest(target=[0.6, 0.0, 0.05], kind="backgrounds", **fields)


class _Camera:
    object_present = True


def _event(job_id: str, lifecycle: Lifecycle, kind: str = "scan") -> bytes:
    state = JobState.MOVING if lifecycle is Lifecycle.RUNNING else JobState(lifecycle.value)
    return JobEvent(job_id=job_id, state=state, lifecycle=lifecycle, kind=kind, message="m",
                    time=0.0).model_dump_json().encode()


def test_the_simulated_workspace_is_empty_while_a_backgrounds_job_runs_only():
    camera = _Camera()
    workspace = Workspace(camera)  # type: ignore[arg-type]
    seen = []
    for payload in [_event("b", Lifecycle.QUEUED, "backgrounds"),      # queued behind a scan: still there
                    _event("a", Lifecycle.RUNNING),
                    _event("b", Lifecycle.RUNNING, "backgrounds"),     # its first step: the object leaves
                    _event("a", Lifecycle.SUCCEEDED),                  # another job's end changes nothing
                    b"not an event",
                    _event("b", Lifecycle.RUNNING, "backgrounds"),
                    _event("b", Lifecycle.SUCCEEDED, "backgrounds"),   # its end: the object is back
                    _event("c", Lifecycle.RUNNING)]:
        workspace.heard(payload)
        seen.append(camera.object_present)
    assert seen == [True, True, False, False, False, False, True, True]
