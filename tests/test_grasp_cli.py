"""`robocell reconstruct --grasps` end to end: `robocell sim` bundles, real subprocesses,
the best grasp judged against the simulated truth by the benchmark's judge."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from robocell.workers.sim.judge import JudgeGripper, judge, parts_from_truth
from robocell.workers.sim.objects import SuperquadricObject
from robocell.workers.sim.scans import make_spec
from robocell.core_cy.gripper import DEFAULT_GRIPPER


def robocell(*args):
    return subprocess.run([sys.executable, "-m", "robocell", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


@pytest.fixture(scope="module")
def bundles(tmp_path_factory):
    """A box, a lying cylinder, and a mug from `robocell sim` (a compound: its truth is a union)."""
    out = tmp_path_factory.mktemp("sim")
    box = SuperquadricObject.on_table("box", (0.04, 0.025, 0.03), (0.6, 0.0), 30.0)
    cylinder = SuperquadricObject.on_table("cylinder", (0.02, 0.02, 0.05), (0.6, 0.0), 70.0, lying=True)
    paths = [make_spec(name, obj, seed=seed).write(out) for name, obj, seed in
             (("box", box, 3), ("cylinder", cylinder, 5))]
    process = robocell("sim", "scans", "--out", out, "--shape", "mug", "--seed", 4)
    assert process.returncode == 0, process.stderr
    return [*paths, Path(process.stdout.split()[0])]


def test_grasps_are_added_best_first_and_the_best_holds_the_true_object(bundles):
    process = robocell("reconstruct", "--grasps", "--max-grasps", 4, *bundles)
    assert process.returncode == 0, process.stderr
    results = [json.loads(line) for line in process.stdout.splitlines()]
    assert [r["scan"] for r in results] == [str(p) for p in bundles]
    for path, result in zip(bundles, results):
        grasps = result["grasps"]
        assert 1 <= len(grasps) <= 4 and set(grasps[0]) == {"T_world_grasp", "width", "score"}
        assert [g["score"] for g in grasps] == sorted((g["score"] for g in grasps), reverse=True) or \
            grasps[0]["score"] >= max(g["score"] for g in grasps) - 0.05
        assert result["timings_ms"]["grasp"] > 0
        truth = json.loads((path / "truth.json").read_text())
        verdict = judge(np.array(grasps[0]["T_world_grasp"]), parts_from_truth(truth),
                        JudgeGripper.from_dict(DEFAULT_GRIPPER.to_dict()), [0, 0, 1, 0])
        assert verdict.holds, (path.name, verdict.reason)
        assert grasps[0]["width"] == pytest.approx(verdict.width, abs=0.01)  # the model's width, within 1 cm
    assert "parts" in json.loads((bundles[2] / "truth.json").read_text())


def test_without_grasps_the_output_is_unchanged(bundles):
    (result,) = [json.loads(line) for line in robocell("reconstruct", bundles[0]).stdout.splitlines()]
    assert "grasps" not in result and "grasp" not in result["timings_ms"]


def test_a_bad_gripper_file_is_one_line_naming_the_field(bundles, tmp_path):
    bad = tmp_path / "gripper.json"
    bad.write_text(json.dumps({**DEFAULT_GRIPPER.to_dict(), "pad_length": 0.09}))
    process = robocell("reconstruct", "--grasps", "--gripper", bad, bundles[0])
    assert process.returncode == 2 and process.stdout == ""
    assert len(process.stderr.strip().splitlines()) == 1 and "pad_length" in process.stderr


def test_a_missing_gripper_file_or_gripper_without_grasps_is_refused(bundles, tmp_path):
    missing = robocell("reconstruct", "--grasps", "--gripper", tmp_path / "nope.json", bundles[0])
    assert missing.returncode == 2 and "cannot read the gripper file" in missing.stderr
    alone = robocell("reconstruct", "--gripper", tmp_path / "nope.json", bundles[0])
    assert alone.returncode == 2 and "only apply with --grasps" in alone.stderr
