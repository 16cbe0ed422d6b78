"""robocell.Client and AsyncClient against a simulated cell, the README's examples run as written,
and the commands that read a job (`job`, `export`) from it.

The README's Python blocks marked ``<!-- test: ... -->`` each run in an interpreter of their
own (so that one that leaves a Zenoh session open hangs at exit, and fails here), pointed at
the test cell (tests/conftest.py red_box_cell, shared with tests/test_cell_scan.py) instead of
the default router and cell id.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import robocell
from robocell.core_cy.scoring import volumetric_iou
from robocell.core_cy.superquadric import Superquadric
from robocell.cli.main import main
from robocell.workers.sim.scene import target_from_config, truth_from_config

REPO = Path(__file__).resolve().parents[1]
EXAMPLE_TIMEOUT_S = 120


@pytest.fixture(scope="module")
def cell(red_box_cell):
    """The default scene's cell (tests/conftest.py), which tests/test_cell_scan.py uses too."""
    return red_box_cell


@pytest.fixture(scope="module")
def client(cell):
    with robocell.Client(cell.router, cell=cell.config.cell_id, timeout=10.0) as connected:
        yield connected


@pytest.fixture(scope="module")
def scanned(cell, client):
    """One scan of the simulated object, through the blocking client."""
    return client.scan(target_from_config(cell.config.sim), timeout=60)


def _truth(cell) -> Superquadric:
    return Superquadric.from_dict(truth_from_config(cell.config.sim))


def test_a_scan_returns_the_model_of_the_true_object(cell, scanned):
    assert isinstance(scanned, robocell.ScanResult)
    fit = Superquadric.from_dict(scanned.superquadric.model_dump())
    assert volumetric_iou(_truth(cell), fit) > 0.9
    assert scanned.grasps and len(scanned.T_base_cam) == 3


def test_pick_holds_the_true_object_and_places_it(cell, client):
    target = target_from_config(cell.config.sim)
    result = client.pick(target, place=[target[0], target[1] + 0.15], timeout=60)
    assert result.pick is not None and result.pick.held is True and result.pick.placed


def test_a_job_the_cell_refuses_raises_its_error(client):
    with pytest.raises(robocell.CellError, match="outside the workspace"):
        client.scan([2.0, 0.0, 0.05], timeout=30)


def test_status_jobs_and_cancel_of_a_finished_job(cell, client, scanned):
    assert client.status(scanned.job_id).state is robocell.JobState.SUCCEEDED
    assert scanned.job_id in [job.job_id for job in client.jobs(limit=50)]
    assert client.cell_status().workers == {"robot": True, "camera": True}
    with pytest.raises(robocell.CellError):
        client.cancel(scanned.job_id)  # it has ended: nothing to cancel


def test_the_async_client_hears_every_state_of_a_job(cell):
    import asyncio

    async def run() -> list[str]:
        async with await robocell.AsyncClient.connect(cell.router, cell=cell.config.cell_id) as client:
            job = await client.submit(robocell.ScanRequest(target=target_from_config(cell.config.sim)))
            states = []
            async with asyncio.timeout(60):
                async for event in client.events(job.job_id):
                    states.append(event.state.value)
                    if event.state.finished:
                        break
            return states

    states = asyncio.run(run())
    assert states[0] == "queued" and states[-1] == "succeeded"
    assert {"moving", "capturing", "reconstructing"} <= set(states)


def _readme_examples() -> list[str]:
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    return re.findall(r"<!-- test:[^>]*-->\n```python\n(.*?)```", readme, flags=re.S)


def test_the_readme_has_examples_to_run():
    assert len(_readme_examples()) >= 3


@pytest.mark.parametrize("index", range(3))
def test_a_readme_example_runs_as_written(cell, index, tmp_path):
    example = _readme_examples()[index]
    assert '"tcp/127.0.0.1:7447"' in example and 'cell="cell1"' in example
    code = example.replace('"tcp/127.0.0.1:7447"', repr(cell.router)).replace(
        'cell="cell1"', f"cell={cell.config.cell_id!r}")
    script = tmp_path / "example.py"
    script.write_text(code)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=EXAMPLE_TIMEOUT_S,
                          env={**os.environ, "PYTHONPATH": str(REPO)}, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    expected = ["held it", "refused: view", "succeeded"][index]
    assert expected in done.stdout, done.stdout


# --- the commands that read a job ----------------------------------------------------------------

def _config(cell) -> str:
    return str(cell.processes.config_path)


def test_job_prints_one_json_document(cell, scanned, capsys):
    assert main(["--config", _config(cell), "job", scanned.job_id]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["job_id"] == scanned.job_id and document["state"] == "succeeded"
    assert document["result"]["superquadric"] == json.loads(scanned.superquadric.model_dump_json())


def test_jobs_json_is_one_list(cell, scanned, capsys):
    assert main(["--config", _config(cell), "jobs", "--json"]) == 0
    assert scanned.job_id in [job["job_id"] for job in json.loads(capsys.readouterr().out)]


def test_a_target_the_plan_cannot_reach_names_the_setting_that_moves_it(cell, capsys):
    assert main(["--config", _config(cell), "scan", "--target", "0.9", "0", "0.05"]) == 1
    error = capsys.readouterr().err
    assert "outside the workspace" in error and "[scan] plan standoff" in error, error


def test_export_of_a_job_places_its_model(cell, scanned, tmp_path, capsys):
    import yourdfpy

    out = tmp_path / "job.urdf"
    assert main(["--config", _config(cell), "export", scanned.job_id, "--format", "urdf", "--out", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["grasps"] == len(scanned.grasps)
    robot = yourdfpy.URDF.load(str(out), mesh_dir=str(tmp_path))
    np.testing.assert_allclose(robot.get_transform("part0", "world"), scanned.superquadric.T_world_object,
                               atol=1e-6)


def _matrix(transform) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    t, q = transform.translation, transform.rotation
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    T[:3, 3] = t.x, t.y, t.z
    return T


def test_a_bag_of_a_job_has_its_pictures_and_the_flange_under_the_camera(cell, scanned, tmp_path, capsys):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from robocell.cli.export import TOPICS
    from tests.cell_fixtures import wait_for_footer

    wait_for_footer(scanned.recording)
    out = tmp_path / "bag"
    assert main(["--config", _config(cell), "export", scanned.job_id, "--format", "rosbag", "--out", str(out)]) == 0
    assert capsys.readouterr().err == ""
    seen: dict[str, list] = {}
    with AnyReader([out], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        for connection, _, raw in reader.messages():
            seen.setdefault(connection.topic, []).append(reader.deserialize(raw, connection.msgtype))
    images = seen[TOPICS["image"]]
    assert len(images) == 3 and all(bytes(image.data[:2]) == b"\xff\xd8" for image in images)  # JPEGs
    (static,) = seen[TOPICS["tf_static"]]
    hand_eye = static.transforms[0]
    assert (hand_eye.header.frame_id, hand_eye.child_frame_id) == ("flange", "camera_optical")
    for moved, T_base_cam in zip(seen[TOPICS["tf"]], scanned.T_base_cam):
        flange = moved.transforms[0]
        assert (flange.header.frame_id, flange.child_frame_id) == ("world", "flange")
        np.testing.assert_allclose(_matrix(flange.transform) @ _matrix(hand_eye.transform), T_base_cam, atol=1e-6)
    (cloud,) = seen[TOPICS["points"]]
    points = np.frombuffer(bytes(cloud.data), dtype="<f4").reshape(-1, 3)
    fit = Superquadric.from_dict(scanned.superquadric.model_dump())
    assert np.median(np.linalg.norm(points - fit.T_world_object[:3, 3], axis=1)) < 0.1  # the object's, in metres


def test_scan_ends_with_a_summary_a_person_reads(cell, capsys):
    target = target_from_config(cell.config.sim)
    assert main(["--config", _config(cell), "scan", "--target", *map(str, target)]) == 0
    out = capsys.readouterr().out.splitlines()
    job_id = out[0].split()[1]
    summary = out[-5:]
    truth = _truth(cell)
    assert summary[0].startswith(f"job {job_id} succeeded in ") and " cm (shape " in summary[0]
    centre = ", ".join(f"{v:.3f}" for v in truth.T_world_object[:3, 3])
    assert f"centred at [{centre}] m" in summary[0]  # the true centre, to the millimetre
    assert summary[1].startswith("  silhouette IoU ")
    assert "grasps; the best: " in summary[2]
    assert summary[3] == f"  recording {cell.config.run_dir / (job_id + '.rrd')}; replay it: robocell replay {job_id}"
    assert summary[4] == f"  its model for a simulator or MoveIt: robocell export {job_id} --format urdf"
