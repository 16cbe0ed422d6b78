"""The recorder's honest records (issue 23): a recording that could not be written, or whose recorder
process died, is named by :meth:`Recorder.finish`; a dead recorder is replaced, and the next job is
recorded again. Every recording is read back with Rerun's own reader, not with the recorder's check."""

from __future__ import annotations

import os
import signal
import warnings
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from robocell.cell.recorder import Recorder
from tests.cell_fixtures import wait_until
from tests.helpers import tmpfs

VERDICT_S = 60.0  # a recorder process imports Rerun first, at the lowest priority, on a busy machine


def _texts(path: Path) -> list[str]:
    """The log lines of a complete recording (Rerun's reader, warnings as errors: no footer fails)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        texts = []
        for chunk in RrdReader(str(path)).stream():
            if chunk.entity_path == "/log":
                texts += [text for [text] in chunk.to_record_batch().column("TextLog:text").to_pylist()]
    return texts


@pytest.fixture
def recorder():
    recorder = Recorder(n_points=50)
    recorder.start()
    yield recorder
    recorder.stop()


def test_a_complete_recording_is_told_whole(recorder, tmp_path):
    path = tmp_path / "j1.rrd"
    recorder.open("j1", path)
    recorder.call("j1", 0.5, "log_text", "moving", "INFO")
    assert recorder.finish("j1").result(VERDICT_S) is None
    assert _texts(path) == ["moving"]


def test_a_recorder_killed_mid_job_is_named_and_replaced_and_the_next_job_is_recorded(recorder, tmp_path):
    first, second = tmp_path / "j1.rrd", tmp_path / "j2.rrd"
    recorder.open("j1", first)
    recorder.call("j1", 0.5, "log_text", "moving", "INFO")
    wait_until(lambda: first.exists() and first.stat().st_size > 0, timeout=VERDICT_S, interval=0.05,
               what="the recorder to begin the first recording")
    [victim] = recorder.pids
    os.kill(victim, signal.SIGKILL)
    recorder.call("j1", 1.0, "log_text", "capturing", "INFO")
    problem = recorder.finish("j1").result(VERDICT_S)
    assert problem is not None and f"recorder process {victim} died (killed by SIGKILL)" in problem, problem
    assert str(first) in problem

    recorder.open("j2", second)
    recorder.call("j2", 0.5, "log_text", "moving again", "INFO")
    assert recorder.finish("j2").result(VERDICT_S) is None
    assert second.stat().st_size > 0 and _texts(second) == ["moving again"]
    assert recorder.pids and victim not in recorder.pids


def test_a_recording_on_a_full_device_is_named(recorder, tmp_path):
    """/dev/full takes the file's opening and refuses every write, as a full disk does."""
    full, fine = tmp_path / "j1.rrd", tmp_path / "j2.rrd"
    full.symlink_to("/dev/full")
    recorder.open("j1", full)
    recorder.call("j1", 0.5, "log_text", "moving", "INFO")
    problem = recorder.finish("j1").result(VERDICT_S)
    assert problem is not None and str(full) in problem and "No space left on device" in problem, problem
    recorder.open("j2", fine)
    recorder.call("j2", 0.5, "log_text", "moving", "INFO")
    assert recorder.finish("j2").result(VERDICT_S) is None
    assert _texts(fine) == ["moving"]


@pytest.fixture
def small_disk(tmp_path):
    """A 256 kB tmpfs (needs root and mount; skipped where there are none)."""
    with tmpfs(tmp_path, "256k") as mount_point:
        yield mount_point


def test_a_recording_that_fills_the_disk_is_named_cut_short(recorder, small_disk):
    path = small_disk / "j1.rrd"
    recorder.open("j1", path)
    recorder.call("j1", 0.5, "log_text", "moving", "INFO")
    cloud = np.random.default_rng(1).random((60_000, 3))  # 720 kB of float32: more than the disk holds
    recorder.call("j1", 1.0, "log_points", "carved", cloud)
    problem = recorder.finish("j1").result(VERDICT_S)
    assert problem is not None and str(path) in problem, problem
    with warnings.catch_warnings(), pytest.raises((RuntimeError, Warning)):
        warnings.simplefilter("error")
        list(RrdReader(str(path)).stream())  # Rerun cannot read it whole either


def test_a_model_in_parts_is_drawn_each_part_in_its_colour_with_the_unions_outline_over_the_image(tmp_path):
    """Two boxes side by side, seen from straight above: one mesh whose vertices take two colours,
    and one outline around both, where a pinhole projection (computed here) puts their corners."""
    from robocell.cell.recording import JobRecording
    from robocell.core_cy.superquadric import Superquadric

    from tests.helpers import HEIGHT, WIDTH, intrinsics

    K = intrinsics()
    T_world_cam = np.diag([1.0, -1.0, -1.0, 1.0])  # looking down -z from 1 m up
    T_world_cam[2, 3] = 1.0
    parts = []
    for x in (-0.1, 0.1):
        T = np.eye(4)
        T[:3, 3] = [x, 0.0, 0.0]
        parts.append(Superquadric([0.1, 0.05, 0.05], [0.1, 0.1], T))  # nearly boxes: 0.2 x 0.1 each, touching
    path = tmp_path / "j1.rrd"
    with JobRecording(path, "j1") as rec:
        rec.log_view(0, b"\xff\xd8\xff\xd9", K, T_world_cam, (WIDTH, HEIGHT))
        rec.log_parts("fit", parts)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        chunks = {chunk.entity_path: chunk.to_record_batch() for chunk in RrdReader(str(path)).stream()}
    colours = chunks["/world/fit"].column("Mesh3D:vertex_colors").to_pylist()[0]
    assert len(set(colours)) == 2
    [strips] = chunks["/world/camera0/outline"].column("LineStrips2D:strips").to_pylist()
    assert len(strips) == 1  # one outline: the union, not one per part
    outline = np.asarray(strips[0])
    # The union is the box |x| <= 0.2, |y| <= 0.05 at depth 0.95 (its top) to 1.05 (its bottom).
    fx, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    half_u, half_v = fx * 0.2 / 0.95, fx * 0.05 / 0.95
    assert np.allclose([outline[:, 0].min(), outline[:, 0].max()], [cx - half_u, cx + half_u], atol=4)
    assert np.allclose([outline[:, 1].min(), outline[:, 1].max()], [cy - half_v, cy + half_v], atol=4)
