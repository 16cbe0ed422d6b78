"""Backgrounds in the simulated cell, end to end: photograph the empty workspace at a scan's poses
(``kind: backgrounds``, ``robocell background``), then scan the object from them.

The cell is real processes on loopback (router, simulated robot and Axis camera, camera worker,
daemon); the reconstruction worker runs in the test process, the real core behind
``ReconstructWorker``, so that the test sees each request and its payload. Pictures and
silhouettes are scored against the simulator's own truth: its renderer's object coverage at
each camera pose, and the true object's superquadric.
"""

from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest

from robocell.core_cy.scoring import volumetric_iou
from robocell.core_cy.superquadric import Superquadric
from robocell.wire.messages import JobState, ReconstructRequest, ScanRequest, ViewPlan
from robocell.workers.sim.render import render
from robocell.workers.sim.scene import scene_from_config, target_from_config, truth_from_config

JOB_TIMEOUT_S = 240.0


@pytest.fixture(scope="module")
def cell(printed_box_cell):
    """The printed box's cell (tests/conftest.py), its backgrounds removed afterwards: the picks'
    scans (tests/test_cell_pick.py) go without them."""
    yield printed_box_cell
    shutil.rmtree(printed_box_cell.config.run_dir / "backgrounds", ignore_errors=True)


def _true_masks(config, T_base_cams) -> list[np.ndarray]:
    """The simulator's own coverage of the object at each camera pose (255: half a pixel or more)."""
    camera = config.camera
    return [render(scene_from_config(config.sim), T, camera.K, camera.dist, tuple(camera.resolution))[1]
            for T in T_base_cams]


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a > 0, b > 0
    return float(np.count_nonzero(a & b)) / max(int(np.count_nonzero(a | b)), 1)


def _decoded(jpeg: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR).astype(np.float32)


def _split(request: ReconstructRequest, payload: bytes) -> list[tuple[bytes, bytes]]:
    """Each view's (picture, background) from a request's payload."""
    views, offset = [], 0
    for view in request.views:
        picture = payload[offset:offset + view.length]
        offset += view.length
        views.append((picture, payload[offset:offset + view.background_length]))
        offset += view.background_length
    assert offset == len(payload)
    return views


def test_backgrounds_taken_before_the_object_serve_the_scan_from_the_same_poses(cell):
    config = cell.config
    target = target_from_config(config.sim)
    reconstructed = len(cell.recorder.seen)
    taken = cell.client.wait(cell.client.submit(ScanRequest(target=target, kind="backgrounds")).job_id,
                             timeout=JOB_TIMEOUT_S)
    assert taken.state is JobState.SUCCEEDED, taken.error
    assert taken.n_views == 3 and len(cell.recorder.seen) == reconstructed   # three pictures, no reconstruction
    events = cell.events(taken.job_id)
    assert all(event.kind == "backgrounds" for event in events)
    assert "kept 3 backgrounds" in events[-1].message
    kept = sorted((config.run_dir / "backgrounds").glob("*.jpg"))
    assert len(kept) == 3

    result = cell.client.scan(ScanRequest(target=target), timeout=JOB_TIMEOUT_S)
    request, payload, reply, _ = cell.recorder.seen[-1]
    assert reply.result is not None and request.job_id == result.job_id
    views = _split(request, payload)
    assert all(background for _, background in views), "every view carried its background"
    assert sorted(background for _, background in views) == sorted(path.read_bytes() for path in kept)

    # Against the simulator's truth: each background is the empty workspace (where the object stands
    # in the scan's picture, the background shows the table: it differs from the picture there, and
    # matches it, within the sensor's noise, everywhere else).
    masks = _true_masks(config, [np.asarray(T) for T in result.T_base_cam])
    for view, ((picture, background), mask) in enumerate(zip(views, masks)):
        difference = np.abs(_decoded(picture) - _decoded(background)).mean(axis=2)
        obj, far = mask > 0, cv2.dilate(mask, np.ones((41, 41), np.uint8)) == 0
        assert difference[obj].mean() > 25, f"view {view}: the object is in its background"
        assert difference[far].mean() < 6, f"view {view}: the background is not the same table from the same pose"

    # The silhouettes the worker drew with them, and the model, against the truth.
    offset, ious = 0, []
    _, _, reply, reply_payload = cell.recorder.seen[-1]
    for blob, mask in zip(reply.silhouettes, masks):
        drawn = cv2.imdecode(np.frombuffer(reply_payload[offset:offset + blob.length], np.uint8),
                             cv2.IMREAD_GRAYSCALE)
        offset += blob.length
        ious.append(_iou(drawn, mask))
    assert min(ious) >= 0.85 and np.mean(ious) >= 0.9, ious
    truth = Superquadric.from_dict(truth_from_config(config.sim))
    fit = Superquadric.from_dict(result.superquadric.model_dump())
    assert volumetric_iou(truth, fit) >= 0.8


def test_a_scan_from_other_poses_goes_without_backgrounds(cell):
    request = ScanRequest(target=target_from_config(cell.config.sim), plan=ViewPlan(standoff=0.45))
    result = cell.client.scan(request, timeout=JOB_TIMEOUT_S)
    sent, payload, _, _ = cell.recorder.seen[-1]
    assert sent.job_id == result.job_id
    assert [view.background_length for view in sent.views] == [0, 0, 0]
    assert sum(view.length for view in sent.views) == len(payload)
