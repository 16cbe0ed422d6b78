"""The whole cell, end to end: every part a real process, talking Zenoh on loopback.

One cell serves the module, and tests/test_api.py (simulated robot moving instantly,
simulated Axis camera, camera and reconstruction workers, daemon). Scans are scored against
the simulated object's truth; the recording is read back with Rerun's reader;
one client speaks nothing but plain ``zenoh`` and the documented keys.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import zenoh
from rerun.chunk import RrdReader

from robocell.wire import keys
from robocell.wire.client import AsyncCellClient
from robocell.wire.errors import MoveRefused, RemoteError
from robocell.wire.messages import JobState, MoveRequest, ScanRequest
from robocell.cell.recording_files import recording_summary, replay_command
from robocell.workers.sim.scene import target_from_config, truth_from_config
from robocell.wire.transport import Transport, session_config
from robocell.core_cy.scoring import volumetric_iou
from robocell.core_cy.superquadric import Superquadric

from tests.cell_fixtures import JOB_TIMEOUT_S, look_away_poses, wait_for_footer, wait_until


@pytest.fixture(scope="module")
def cell(red_box_cell):
    """The default scene's cell (tests/conftest.py), which tests/test_api.py uses too."""
    return red_box_cell


@pytest.fixture(scope="module")
def scanned(cell):
    """One scan of the simulated object, from submit to result."""
    status = cell.submit(label="scored")
    assert status.state is JobState.QUEUED
    final = cell.wait(status.job_id)
    assert final.state is JobState.SUCCEEDED, final.error
    return final, cell.client.result(status.job_id)


def test_scan_scores_well_against_the_truth(cell, scanned):
    status, result = scanned
    truth = Superquadric.from_dict(truth_from_config(cell.config.sim))
    fit = Superquadric.from_dict(result.superquadric.model_dump())
    assert volumetric_iou(truth, fit) > 0.7
    assert len(result.silhouette_iou) == 3 and min(result.silhouette_iou) > 0.85
    assert np.linalg.norm(fit.T_world_object[:3, 3] - truth.T_world_object[:3, 3]) < 0.01
    assert result.timings_ms["total"] > 0
    assert len(result.T_base_cam) == 3
    # The simulated box is one superquadric: one part, the superquadric itself (DESIGN.md §3).
    assert len(result.parts) == 1
    assert volumetric_iou(truth, Superquadric.from_dict(result.parts[0].model_dump())) > 0.7


def test_scan_goes_through_every_state_in_order(cell, scanned):
    status, _ = scanned
    steps = [(e.state, e.view) for e in cell.events(status.job_id)]
    expected = [(JobState.QUEUED, None)]
    for view in range(3):
        expected += [(JobState.MOVING, view), (JobState.CAPTURING, view)]
    expected += [(JobState.RECONSTRUCTING, None), (JobState.SUCCEEDED, None)]
    assert steps == expected
    times = [e.time for e in cell.events(status.job_id)]
    assert times == sorted(times)


# The (state, view) of every event of a scan that succeeds, in order.
WHOLE_SCAN = [(JobState.QUEUED, None), *[(state, view) for view in range(3)
                                         for state in (JobState.MOVING, JobState.CAPTURING)],
              (JobState.RECONSTRUCTING, None), (JobState.SUCCEEDED, None)]


def test_a_clients_scan_hears_every_event_and_gets_the_result_from_the_last(cell):
    for label in ("first scan of this client", "second"):  # the second reuses the client's subscription
        heard = []
        result = cell.client.scan(ScanRequest(target=target_from_config(cell.config.sim), label=label),
                                  timeout=JOB_TIMEOUT_S, on_event=heard.append)
        assert [(e.state, e.view) for e in heard] == WHOLE_SCAN
        assert {e.job_id for e in heard} == {result.job_id}
        assert heard[-1].result == result == cell.client.result(result.job_id)
        # The stored history leaves the result out: it is stored once.
        assert cell.events(result.job_id)[-1] == heard[-1].model_copy(update={"result": None})


def test_watching_one_job_and_every_job_loses_no_event(cell):
    """``events(job)`` started after the job's submit still gets its first events; ``events()``
    watches every job. Both ride on the client's one subscription."""
    request = ScanRequest(target=target_from_config(cell.config.sim), label="watched")

    async def until_ended(stream, n_jobs: int) -> dict[str, list]:
        heard: dict[str, list] = {}
        async with contextlib.aclosing(stream):
            async for event in stream:
                heard.setdefault(event.job_id, []).append((event.state, event.view))
                if sum(steps[-1][0].finished for steps in heard.values()) == n_jobs:
                    return heard

    async def watch():
        async with await AsyncCellClient.connect(cell.router, cell.config.cell_id) as client:
            every_job = asyncio.create_task(until_ended(client.events(), n_jobs=2))
            await asyncio.sleep(0)  # the watch has begun
            await client.cell_status()  # a round trip: the router has the subscription before the submits
            first, second = await client.submit(request), await client.submit(request)
            one_job = await asyncio.wait_for(until_ended(client.events(second.job_id), n_jobs=1), JOB_TIMEOUT_S)
            return first.job_id, second.job_id, one_job, await asyncio.wait_for(every_job, JOB_TIMEOUT_S)

    first, second, one_job, every_job = cell.loop.run(watch(), timeout=2 * JOB_TIMEOUT_S)
    assert one_job == {second: WHOLE_SCAN}
    assert every_job == {first: WHOLE_SCAN, second: WHOLE_SCAN}


def test_recording_holds_images_poses_clouds_and_meshes(cell, scanned):
    status, result = scanned
    assert status.recording == result.recording
    wait_for_footer(result.recording)
    summary = recording_summary(result.recording)
    for view in range(3):
        assert summary[f"/world/camera{view}"] == ["Pinhole", "Transform3D"]
        assert summary[f"/world/camera{view}/image"] == ["EncodedImage"]
        assert summary[f"/world/camera{view}/silhouette"] == ["EncodedImage"]
    assert summary["/world/points/sphere"] == ["Points3D"]
    assert summary["/world/points/carved"] == ["Points3D"]
    assert summary["/world/fit"] == ["Mesh3D"]
    assert "/world/truth" not in summary  # the daemon does not know the simulator's truth
    assert summary["/log"] == ["TextLog"]
    # The simulator logs its truth into the same recording itself (Rerun's shared recordings).
    truth = Path(result.recording).with_suffix(".truth.rrd")
    wait_for_footer(truth)
    assert recording_summary(truth)["/world/truth"] == ["Mesh3D"]
    ids = {(entry.application_id, entry.recording_id)
           for path in (result.recording, truth) for entry in RrdReader(str(path)).recordings()}
    assert ids == {("robocell", result.job_id)}
    assert [str(p) for p in replay_command(Path(result.recording))[1:3]] == [result.recording, str(truth)]


def test_plain_zenoh_client_with_only_the_documented_keys(cell):
    """What a program in another language does: JSON on documented keys, nothing of robocell's code."""
    prefix = f"robocell/{cell.config.cell_id}"
    request = json.dumps({"schema_version": 1, "target": target_from_config(cell.config.sim), "label": "plain zenoh"})
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([cell.router]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    events: list[dict] = []
    with zenoh.open(conf) as session:
        replies = list(session.get(f"{prefix}/submit", payload=request, timeout=10.0))
        assert len(replies) == 1 and replies[0].ok is not None, replies
        status = json.loads(replies[0].ok.payload.to_bytes())
        job_id = status["job_id"]
        assert status["state"] == "queued"
        subscriber = session.declare_subscriber(f"{prefix}/events/{job_id}",
                                                lambda sample: events.append(json.loads(sample.payload.to_bytes())))
        try:
            def finished():
                for reply in session.get(f"{prefix}/jobs/{job_id}", timeout=10.0):
                    state = json.loads(reply.ok.payload.to_bytes())["state"]
                    return state if state in ("succeeded", "failed", "cancelled") else None
                return None

            assert wait_until(finished, timeout=JOB_TIMEOUT_S, interval=0.05, what="the job") == "succeeded"
            reply = next(iter(session.get(f"{prefix}/jobs/{job_id}/result", timeout=10.0)))
            result = json.loads(reply.ok.payload.to_bytes())
            wait_until(lambda: events and events[-1]["state"] == "succeeded", timeout=5.0, what="the last event")
        finally:
            subscriber.undeclare()
    assert result["job_id"] == job_id
    assert set(result["superquadric"]) >= {"size", "shape", "T_world_object"}
    truth = Superquadric.from_dict(truth_from_config(cell.config.sim))
    assert volumetric_iou(truth, Superquadric.from_dict(result["superquadric"])) > 0.7
    # The subscription may have started after the first events: what came is the tail, in order.
    states = [e["state"] for e in events]
    assert states[-2:] == ["reconstructing", "succeeded"]
    assert all(e["job_id"] == job_id for e in events)
    # The succeeded event carries the result: a client that watches events needs no further query.
    assert events[-1]["result"] == result
    assert all(e.get("result") is None for e in events[:-1])


def test_a_result_asked_with_wait_is_answered_as_the_job_ends(cell):
    """``jobs/<id>/result?wait=<s>``, the question a client asks as it submits: answered once the job has
    succeeded (its status then says so), with the result the store took; a wait that is no number is refused."""
    status = cell.submit(label="asked at once")

    async def ask(parameters: str):
        async with await Transport.open(cell.router) as transport:
            return await transport.query(keys.result(cell.config.cell_id, status.job_id), timeout=JOB_TIMEOUT_S + 5,
                                         parameters=parameters)

    with pytest.raises(RemoteError, match="not a number of seconds"):
        asyncio.run(ask("wait=soon"))
    reply = asyncio.run(ask(f"wait={JOB_TIMEOUT_S}"))
    assert cell.client.status(status.job_id).state is JobState.SUCCEEDED
    assert json.loads(reply.payload) == cell.client.result(status.job_id).model_dump(mode="json")


async def _ask(router: str, key: str, payload: str | bytes | None = None, parameters: str = ""):
    async with await Transport.open(router) as transport:
        return await transport.query(key, payload, timeout=10.0, parameters=parameters)


@pytest.mark.parametrize("payload, named", [
    (b"", "empty payload"),
    (b"{not json", "Invalid JSON"),
    (b"[1, 2]", "ScanRequest"),
    (json.dumps({"target": [0.6, 0.0]}), "target"),
    (json.dumps({"target": [0.6, 0.0, "high"]}), "target.2"),
    (json.dumps({"target": [0.6, 0.0, 0.05], "colour": "red"}), "colour"),
    (json.dumps({"target": [0.6, 0.0, 0.05], "schema_version": 3}), "schema_version"),
    (json.dumps({"target": [0.6, 0.0, 0.05]}), r"^invalid ScanRequest: schema_version: Field required \("),
    (json.dumps({"target": [0.6, 0.0, 0.05], "plan": {"standoff": -1}}), "plan.standoff"),
    (json.dumps({"target": [0.6, 0.0, 0.05], "plan": {"azimuths_deg": [0, float("nan"), 240]}}),
     "invalid ScanRequest: plan.azimuths_deg.1: Input should be a finite number"),
    (json.dumps({"target": [0.6, 0.0, 0.05], "plan": {"elevations_deg": [90, 40, 35]}}),
     "invalid ScanRequest: plan.elevations_deg.0"),
    (json.dumps({"flange_poses": [np.eye(4).tolist()] * 3, "target": [0.6, 0.0, 0.05]}), "exactly one"),
    (json.dumps({"flange_poses": [[[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 0.4], [0, 0, 0, 1]],
                                  [[2, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 0.4], [0, 0, 0, 1]]]}),
     "flange_poses.1"),
])
def test_invalid_request_is_refused_naming_the_field(cell, payload, named):
    before = len(cell.client.list(limit=1000))
    with pytest.raises(RemoteError, match=named):
        cell.loop.run(_ask(cell.router, keys.submit(cell.config.cell_id), payload))
    assert len(cell.client.list(limit=1000)) == before
    assert cell.daemon_running()


def test_pose_outside_the_workspace_is_refused_before_the_robot_moves(cell):
    before = cell.robot_state()
    inside = np.asarray(cell.config.robot.home)
    above = inside.copy()
    above[2, 3] = 1.4
    poses = [inside.tolist(), above.tolist(), inside.tolist()]
    n_jobs = len(cell.client.list(limit=1000))
    with pytest.raises(RemoteError, match=r"view 1 is outside the workspace: z = 1.4 m is above"):
        cell.client.submit(ScanRequest(flange_poses=poses))
    assert len(cell.client.list(limit=1000)) == n_jobs  # no job was made
    # The robot worker checks too, for callers other than the daemon.
    # The refusal keeps its kind across the wire, with the limit it names.
    with pytest.raises(MoveRefused, match="move refused before moving: z = 1.4 m") as refused:
        cell.loop.run(_ask(cell.router, keys.robot_move(cell.config.cell_id),
                           MoveRequest(T_base_flange=above.tolist()).model_dump_json()))
    assert refused.value.limit == "workspace"
    after = cell.robot_state()
    assert after.T_base_flange == before.T_base_flange and not after.moving


def test_workers_refuse_malformed_requests_naming_the_field(cell):
    cell_id = cell.config.cell_id
    with pytest.raises(RemoteError, match=r"invalid MoveRequest: T_base_flange: Field required"):
        cell.loop.run(_ask(cell.router, keys.robot_move(cell_id), json.dumps({"job_id": "x"})))
    with pytest.raises(RemoteError, match=r"invalid MoveRequest: T_base_flange: .*rigid"):
        cell.loop.run(_ask(cell.router, keys.robot_move(cell_id),
                           json.dumps({"T_base_flange": (2 * np.eye(4)).tolist()})))
    reconstructors = cell.loop.run(_alive(cell.router, keys.RECONSTRUCTORS_ALIVE))
    worker = reconstructors[0].rsplit("/", 1)[-1]
    with pytest.raises(RemoteError, match=r"invalid ReconstructRequest: views: List should have at least 2 items"):
        cell.loop.run(_ask_with_attachment(cell.router, keys.reconstructor(worker), b"\xff\xd8",
                                           json.dumps({"job_id": "x", "views": []})))
    with pytest.raises(RemoteError, match=r"missing attachment"):
        cell.loop.run(_ask(cell.router, keys.reconstructor(worker), b"\xff\xd8"))
    assert cell.robot_state().T_base_flange  # the workers are still there
    assert cell.tracebacks() == {}


async def _alive(router: str, key_expr: str) -> list[str]:
    async with await Transport.open(router) as transport:
        return await transport.alive(key_expr)


async def _ask_with_attachment(router: str, key: str, payload: bytes, attachment: str):
    async with await Transport.open(router) as transport:
        return await transport.query(key, payload, attachment=attachment, timeout=10.0)


def test_reconstruction_error_fails_the_job_with_the_cores_message(cell):
    status = cell.submit(flange_poses=look_away_poses(cell.config), label="nothing in view")
    final = cell.wait(status.job_id)
    assert final.state is JobState.FAILED
    assert final.error.startswith("reconstructing: view 0: nothing stands on the table near the views' aim"), final.error
    with pytest.raises(RemoteError, match=f"job {status.job_id} has no result: it is failed"):
        cell.client.result(status.job_id)


def test_a_scan_requests_segmentation_reaches_the_reconstruction(cell):
    # Told the object is brighter than white, the reconstruction finds nothing: the request's method
    # was used (the default, auto, finds the simulated object).
    status = cell.submit(segmentation={"method": "threshold", "value": 255}, label="a method the scene defeats")
    final = cell.wait(status.job_id)
    assert final.state is JobState.FAILED
    assert "grey > 255" in final.error, final.error


def test_job_queries_list_idempotency_and_unknown_jobs(cell, scanned):
    status, _ = scanned
    listed = cell.client.list(limit=1000)
    assert status.job_id in [job.job_id for job in listed]
    succeeded = cell.client.list({JobState.SUCCEEDED}, limit=1000)
    assert succeeded and all(job.state is JobState.SUCCEEDED for job in succeeded)
    with pytest.raises(RemoteError, match="no job 'nope'"):
        cell.client.status("nope")
    with pytest.raises(RemoteError, match="already succeeded: nothing to cancel"):
        cell.client.cancel(status.job_id)
    with pytest.raises(RemoteError, match="unknown job query 'frobnicate'"):
        cell.loop.run(_ask(cell.router, f"{keys.job(cell.config.cell_id, status.job_id)}/frobnicate"))
    with pytest.raises(RemoteError, match="bad parameters"):
        cell.loop.run(_ask(cell.router, keys.jobs(cell.config.cell_id), parameters="state=sleeping"))
    first = cell.client.submit(cell.scan_request(request_id="same-request"))
    again = cell.client.submit(cell.scan_request(request_id="same-request"))
    assert again.job_id == first.job_id
    assert cell.wait(first.job_id).state is JobState.SUCCEEDED
    at_once = cell.loop.run(_submit_together(cell, cell.scan_request(request_id="at-once"), 5))
    assert len({status.job_id for status in at_once}) == 1
    assert [job.job_id for job in cell.client.list(limit=1000) if job.request.request_id == "at-once"] \
        == [at_once[0].job_id]
    assert cell.wait(at_once[0].job_id).state is JobState.SUCCEEDED
    assert "withdrawn" not in cell.log("daemon")  # found as the same request, not by the store's backstop


async def _submit_together(cell, request: ScanRequest, n: int):
    """``n`` submits of one request, all sent before any is answered."""
    async with await AsyncCellClient.connect(cell.router, cell.config.cell_id) as client:
        return await asyncio.gather(*(client.submit(request) for _ in range(n)))


def test_every_query_gets_exactly_one_answer(cell, scanned):
    """``jobs``, ``jobs/<id>`` and ``jobs/<id>/result`` each reach exactly one queryable."""
    status, _ = scanned
    prefix = f"robocell/{cell.config.cell_id}"
    with zenoh.open(session_config(cell.router)) as session:
        for key in (f"{prefix}/jobs", f"{prefix}/jobs/{status.job_id}", f"{prefix}/jobs/{status.job_id}/result"):
            for _ in range(5):
                replies = list(session.get(key, timeout=10.0, consolidation=zenoh.ConsolidationMode.NONE))
                assert len(replies) == 1 and replies[0].ok is not None, (key, replies)
                json.loads(replies[0].ok.payload.to_bytes())


def test_command_line_scan_shows_progress_and_the_result(cell):
    argv = [sys.executable, "-m", "robocell", "--config", str(cell.processes.config_path), "scan",
            "--target", *map(str, target_from_config(cell.config.sim)), "--timeout", "60", "--json"]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=90)
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()  # with --json the progress goes to stderr, the one JSON document to stdout
    assert lines[0].startswith("job ") and lines[0].endswith(" queued")
    # Every step, the first ones too: they can come before the submit's answer.
    assert [line.split()[1] for line in lines[1:]] == [state.value for state, _ in WHOLE_SCAN]
    assert any("capturing view 2" in line for line in lines)
    result = json.loads(done.stdout)
    assert result["silhouette_iou"] and result["recording"].endswith(".rrd")


def test_no_process_logged_a_traceback(cell):
    assert cell.tracebacks() == {}
