"""Job recordings: a whole fake job logged from two threads, read back from the .rrd file."""

from __future__ import annotations

import subprocess
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
from rerun.chunk import RrdReader

from robocell.cell.recording import JobRecording
from robocell.cell.recording_files import find_recording, recording_summary, replay_command
from robocell.core_cy.superquadric import Superquadric

from tests.helpers import HEIGHT, WIDTH, intrinsics, look_at

CENTRE = np.array([0.6, 0.0, 0.05])
POSITIONS = [(0.6, -0.35, 0.45), (0.95, 0.0, 0.45), (0.6, 0.35, 0.45)]
STEPS = [("moving to view 0", 0.0), ("capturing view 0", 0.8), ("moving to view 1", 1.1),
         ("capturing view 1", 1.9), ("moving to view 2", 2.2), ("capturing view 2", 3.0),
         ("reconstructing", 3.2), ("succeeded", 3.21)]


def _jpeg(index: int) -> bytes:
    image = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    cv2.circle(image, (WIDTH // 2 + 20 * index, HEIGHT // 2), 80, (0, 0, 255), -1)
    ok, encoded = cv2.imencode(".jpg", image)
    assert ok
    return encoded.tobytes()


def _mask(index: int) -> bytes:
    """View ``index``'s silhouette as a worker sends it: a PNG, white = object."""
    mask = np.zeros((HEIGHT, WIDTH), np.uint8)
    cv2.circle(mask, (WIDTH // 2 + 20 * index, HEIGHT // 2), 80, 255, -1)
    return cv2.imencode(".png", mask)[1].tobytes()


def _log_job(path: Path, job_id: str) -> dict[str, object]:
    """Log a complete fake job: motion and capture in one thread, the reconstruction in another."""
    jpegs = [_jpeg(i) for i in range(3)]
    rng = np.random.default_rng(7)
    directions = rng.normal(size=(200, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    T_world_object = np.eye(4)
    T_world_object[:3, 3] = CENTRE
    fit = Superquadric([0.04, 0.03, 0.05], [0.5, 1.0], T_world_object)
    truth_vertices = np.array([[0.55, -0.05, 0.0], [0.65, -0.05, 0.0], [0.6, 0.05, 0.0], [0.6, 0.0, 0.1]])
    truth_faces = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]], np.int32)
    captured = threading.Event()
    errors: list[BaseException] = []

    def motion(rec: JobRecording) -> None:
        for i, position in enumerate(POSITIONS):
            rec.set_time(STEPS[2 * i][1])
            rec.log_text(f"{STEPS[2 * i][0]} ({STEPS[2 * i][1]:.2f} s)")
            pose = look_at(position, CENTRE)
            rec.log_robot_pose(pose)
            rec.set_time(STEPS[2 * i + 1][1])
            rec.log_text(f"{STEPS[2 * i + 1][0]} ({STEPS[2 * i + 1][1]:.2f} s)")
            rec.log_view(i, jpegs[i], intrinsics(), pose, (WIDTH, HEIGHT))
        captured.set()

    def reconstruction(rec: JobRecording) -> None:
        captured.wait(10)
        rec.set_time(STEPS[6][1])
        rec.log_text(STEPS[6][0], "DEBUG")
        for i in range(3):
            rec.log_silhouette(i, _mask(i))
        rec.log_points("sphere", CENTRE + 0.1 * directions)
        rec.log_points("carved", CENTRE + 0.05 * directions, colour=(255, 128, 0))
        rec.log_superquadric("fit", fit)
        rec.log_mesh("truth", truth_vertices, truth_faces)
        rec.set_time(STEPS[7][1])
        rec.log_text(STEPS[7][0], "WARNING")

    def run(target, rec) -> None:
        try:
            target(rec)
        except BaseException as exc:  # re-raised in the main thread below
            errors.append(exc)

    with JobRecording(path, job_id) as rec:
        threads = [threading.Thread(target=run, args=(f, rec)) for f in (motion, reconstruction)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(20)
    if errors:
        raise errors[0]
    return {"jpegs": jpegs}


def _record_batches(path: Path):
    for chunk in RrdReader(str(path)).stream():
        yield chunk, chunk.to_record_batch()


EXPECTED = {
    "/log": ["TextLog"],
    "/world": ["ViewCoordinates"],
    "/world/robot/flange": ["Transform3D", "TransformAxes3D"],
    "/world/points/sphere": ["Points3D"],
    "/world/points/carved": ["Points3D"],
    "/world/fit": ["Mesh3D"],
    "/world/truth": ["Mesh3D"],
    **{f"/world/camera{i}": ["Pinhole", "Transform3D"] for i in range(3)},
    **{f"/world/camera{i}/image": ["EncodedImage"] for i in range(3)},
    **{f"/world/camera{i}/silhouette": ["EncodedImage"] for i in range(3)},
}


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    path = tmp_path_factory.mktemp("runs") / "job-1.rrd"
    logged = _log_job(path, "job-1")
    return path, logged


def test_every_entity_has_its_archetypes(job):
    path, _ = job
    summary = recording_summary(path)
    for entity, archetypes in EXPECTED.items():
        assert summary.get(entity) == archetypes, entity


def test_images_read_back_byte_for_byte(job):
    path, logged = job
    images = {}
    for chunk, batch in _record_batches(path):
        if chunk.entity_path.endswith("/image"):
            images[chunk.entity_path] = [bytes(b) for row in batch.column("EncodedImage:blob").to_pylist()
                                         for b in row]
            assert batch.column("EncodedImage:media_type").to_pylist() == [["image/jpeg"]]
    assert images == {f"/world/camera{i}/image": [logged["jpegs"][i]] for i in range(3)}


def test_text_log_rows_times_and_levels(job):
    path, _ = job
    rows = []
    for chunk, batch in _record_batches(path):
        if chunk.entity_path == "/log":
            times = batch.column("job").to_pylist()
            rows += zip(times, batch.column("TextLog:text").to_pylist(), batch.column("TextLog:level").to_pylist())
    assert len(rows) == len(STEPS)
    rows.sort(key=lambda row: row[0])
    # Both threads' lines landed at the times set, whichever thread set them.
    assert [t.total_seconds() for t, _, _ in rows] == pytest.approx([s for _, s in STEPS])
    assert rows[0][1] == ["moving to view 0 (0.00 s)"]
    assert [level for *_, level in rows][-2:] == [["DEBUG"], ["WARN"]]


def test_job_timeline_on_every_logged_entity(job):
    path, _ = job
    timelines: dict[str, set[str]] = {}
    for chunk in RrdReader(str(path)).stream():
        if not chunk.is_static and chunk.entity_path != "/__properties":
            timelines.setdefault(chunk.entity_path, set()).update(chunk.timeline_names)
    assert set(EXPECTED) - {"/world"} == set(timelines)
    assert all("job" in names for names in timelines.values()), timelines


def test_closed_file_is_complete_while_the_process_runs(job):
    path, _ = job
    store = RrdReader(str(path)).store()  # needs the footer written by close()
    assert "/world/fit" in store.schema().entity_paths()
    assert [r.recording_id for r in RrdReader(str(path)).recordings()] == ["job-1"]


def test_close_is_idempotent_and_later_logging_is_dropped(tmp_path):
    rec = JobRecording(tmp_path / "a.rrd", "a")
    rec.log_text("one")
    rec.close()
    rec.close()
    rec.log_text("too late")
    assert rec.closed
    texts = [t for chunk, batch in _record_batches(tmp_path / "a.rrd") if chunk.entity_path == "/log"
             for t in batch.column("TextLog:text").to_pylist()]
    assert texts == [["one"]]


def test_summary_of_a_recording_still_being_written(tmp_path):
    rec = JobRecording(tmp_path / "open.rrd", "open")
    try:
        rec.log_points("x", np.zeros((3, 3)))
        rec._rec.flush()  # what the daemon's batcher does on its own after a moment
        assert "Points3D" in recording_summary(tmp_path / "open.rrd")["/world/points/x"]
    finally:
        rec.close()


def test_bad_input_is_refused_with_its_shape(tmp_path):
    with JobRecording(tmp_path / "b.rrd", "b") as rec:
        with pytest.raises(ValueError, match=r"\(N, 3\)"):
            rec.log_points("sphere", np.zeros((4, 2)))
        with pytest.raises(ValueError, match="4x4"):
            rec.log_robot_pose(np.eye(3))
        with pytest.raises(ValueError, match="view 0's silhouette is not a PNG"):
            rec.log_silhouette(0, cv2.imencode(".jpg", np.zeros((HEIGHT, WIDTH), np.uint8))[1].tobytes())
        # A few bytes that declare 20000x20000 pixels: refused by the header, never decoded.
        bomb = b"\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR\x00\x00N\x20\x00\x00N\x20"
        with pytest.raises(ValueError, match="20000x20000 pixels"):
            rec.log_silhouette(0, bomb)
        rec.log_view(1, _jpeg(1), intrinsics(), look_at(POSITIONS[1], CENTRE), (WIDTH, HEIGHT))
        half = cv2.imencode(".png", np.zeros((HEIGHT // 2, WIDTH // 2), np.uint8))[1].tobytes()
        with pytest.raises(ValueError, match=f"view 1's silhouette is {WIDTH // 2}x{HEIGHT // 2} pixels, "
                                             f"its image {WIDTH}x{HEIGHT}"):
            rec.log_silhouette(1, half)


def test_concurrent_recordings_stay_separate(tmp_path):
    def record(job_id: str) -> None:
        with JobRecording(tmp_path / f"{job_id}.rrd", job_id) as rec:
            for step in range(20):
                rec.set_time(step * 0.1)
                rec.log_text(f"{job_id} step {step}")
                rec.log_points("carved", np.full((5, 3), step, np.float64))

    threads = [threading.Thread(target=record, args=(j,)) for j in ("A", "B")]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(20)
    for job_id in ("A", "B"):
        path = tmp_path / f"{job_id}.rrd"
        assert [r.recording_id for r in RrdReader(str(path)).recordings()] == [job_id]
        texts = [t[0] for chunk, batch in _record_batches(path) if chunk.entity_path == "/log"
                 for t in batch.column("TextLog:text").to_pylist()]
        assert sorted(texts) == sorted(f"{job_id} step {s}" for s in range(20))


def test_find_recording(tmp_path, monkeypatch):
    run_dir = tmp_path / "runs"
    run_dir.mkdir()
    (run_dir / "j7.rrd").write_bytes(b"")
    elsewhere = tmp_path / "copy.rrd"
    elsewhere.write_bytes(b"")
    assert find_recording("j7", run_dir) == run_dir / "j7.rrd"
    assert find_recording(str(elsewhere), run_dir) == elsewhere
    monkeypatch.chdir(tmp_path)
    assert find_recording("j7.rrd", run_dir) == run_dir / "j7.rrd"  # a bare file name also tries run_dir
    with pytest.raises(FileNotFoundError, match="no recording for 'j8'") as info:
        find_recording("j8", run_dir)
    assert str(run_dir / "j8.rrd") in str(info.value)
    with pytest.raises(FileNotFoundError, match="missing.rrd"):
        find_recording(str(tmp_path / "missing.rrd"), run_dir)


def test_replay_command_native_and_web(tmp_path):
    path = tmp_path / "j.rrd"
    native = replay_command(path)
    assert native[1:] == [str(path), "--bind", "127.0.0.1"]  # rerun's own default is every network
    assert Path(native[0]).name == "rerun"
    # The SDK's own viewer binary itself, not the venv's wrapper script, which leaves it running at a Ctrl-C.
    import rerun_cli
    assert Path(native[0]) == Path(rerun_cli.__file__).with_name("rerun")
    assert Path(native[0]).read_bytes()[:4] == b"\x7fELF"
    web = replay_command(path, web=True, web_port=9191, grpc_port=9877)
    assert web == [native[0], str(path), "--bind", "127.0.0.1", "--serve-web", "--port", "9877",
                   "--web-viewer-port", "9191"]
    help_text = subprocess.run([native[0], "--help"], capture_output=True, text=True, timeout=60, check=True).stdout
    for flag in ("--serve-web", "--bind", "--port", "--web-viewer-port"):
        assert flag in help_text


def test_a_refused_reconstruction_is_taken_out_of_the_recording_from_then_on(tmp_path):
    path = tmp_path / "j2.rrd"
    with JobRecording(path, "j2") as rec:
        rec.log_view(0, _jpeg(0), intrinsics(), look_at(POSITIONS[0], CENTRE), (WIDTH, HEIGHT))
        rec.set_time(1.0)
        rec.log_silhouette(0, _mask(0))
        rec.log_points("carved", CENTRE + np.zeros((3, 3)))
        rec.log_superquadric("fit", Superquadric([0.04, 0.03, 0.05], [0.5, 1.0], np.eye(4)))
        rec.set_time(2.0)
        rec.clear_reconstruction()
    cleared = {}
    for chunk, batch in _record_batches(path):
        if "Clear:is_recursive" in batch.schema.names:
            cleared[chunk.entity_path] = [t.total_seconds() for t in batch.column("job").to_pylist()]
    assert cleared == {entity: [2.0] for entity in ("/world/points", "/world/fit", "/world/camera0/silhouette",
                                                   "/world/camera0/outline")}
    assert recording_summary(path)["/world/camera0/image"] == ["EncodedImage"]  # the pictures stay


def test_a_workers_silhouette_that_is_not_a_png_of_its_view_costs_only_itself(tmp_path):
    from robocell.cell.recorder_process import _Drawing
    from robocell.wire.messages import POINTS_ENCODING, Blob, Reconstruction, ReconstructReply

    T = np.eye(4)
    T[:3, 3] = CENTRE
    result = Reconstruction(superquadric={"size": [0.04, 0.03, 0.05], "shape": [0.5, 1.0], "T_world_object": T.tolist()},
                            silhouette_iou=[0.9] * 3, residual=0.001, timings_ms={"total": 1.0},
                            centre=list(CENTRE), radius=0.1)
    bomb = b"\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR\x00\x00N\x20\x00\x00N\x20"  # declares 20000x20000 pixels
    silhouettes = [_mask(0), bomb, _mask(2)]
    points = (CENTRE + 0.01 * np.eye(3)).astype("<f4").tobytes()
    reply = ReconstructReply(job_id="j3", result=result, worker="w", ticket="t",
                             silhouettes=[Blob(encoding="image/png", length=len(s)) for s in silhouettes],
                             points=Blob(encoding=POINTS_ENCODING, length=len(points)))
    path = tmp_path / "j3.rrd"
    with JobRecording(path, "j3") as rec:
        for view in range(3):
            rec.log_view(view, _jpeg(view), intrinsics(), look_at(POSITIONS[view], CENTRE), (WIDTH, HEIGHT))
        _Drawing(n_points=100).reconstruction(rec, reply.model_dump_json(), b"".join(silhouettes) + points)
    summary = recording_summary(path)
    assert summary["/world/camera0/silhouette"] == summary["/world/camera2/silhouette"] == ["EncodedImage"]
    assert "/world/camera1/silhouette" not in summary
    assert summary["/world/fit"] == ["Mesh3D"] and summary["/world/points/carved"] == ["Points3D"]
    texts = [text for _, batch in _record_batches(path) for name in batch.schema.names if name.endswith(":text")
             for text in batch.column(name).to_pylist()]
    assert any("silhouette of view 1 is not drawn" in str(text) and "20000x20000" in str(text) for text in texts), texts
