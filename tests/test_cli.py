"""`robocell reconstruct` and `robocell sim` as other programs use them: real subprocesses."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core_cy.scoring import volumetric_iou
from core_cy.superquadric import Superquadric

from .bundles import edit_scan

BUNNY = Path(__file__).resolve().parents[2] / "shared" / "data" / "bunny"


def robocell(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "cell.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def lines(process):
    return [json.loads(line) for line in process.stdout.splitlines()]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """One bundle of each family from `robocell sim`, with its truth."""
    out = tmp_path_factory.mktemp("sim")
    paths = []
    for shape in ("box", "cylinder", "ellipsoid", "rounded-box"):
        process = robocell("sim", "--out", out, "--shape", shape, "--seed", 11)
        assert process.returncode == 0, process.stderr
        paths += [Path(p) for p in process.stdout.split()]
    return paths


def test_simulated_scans_scored_against_the_truth(simulated):
    process = robocell("reconstruct", *simulated)
    assert process.returncode == 0, process.stderr
    results = lines(process)
    assert [r["scan"] for r in results] == [str(p) for p in simulated]  # one line each, in order
    for path, result in zip(simulated, results):
        truth = Superquadric.from_dict(json.loads((path / "truth.json").read_text()))
        fit = Superquadric.from_dict(result["superquadric"])
        assert volumetric_iou(fit, truth) > 0.75, path.name
        assert len(result["silhouette_iou"]) == 3 and min(result["silhouette_iou"]) > 0.85
        assert result["timings_ms"]["total"] > 0 and "points" not in result


def test_points_option_adds_the_cloud(simulated):
    (result,) = lines(robocell("reconstruct", "--points", "--n-points", 400, simulated[0]))
    points = np.asarray(result["points"])
    assert points.ndim == 2 and points.shape[1] == 3 and 300 < len(points) <= 400


def test_bunny_real_photographs():
    if not (BUNNY / "scan.json").exists():
        pytest.skip(f"no test data at {BUNNY}")
    (result,) = lines(robocell("reconstruct", BUNNY))
    assert np.mean(result["silhouette_iou"]) >= 0.7


def _broken(tmp_path, template, name, change):
    target = shutil.copytree(template, tmp_path / name)
    change(target)
    return target


BAD_BUNDLES = {
    "missing-scan-json": (lambda d: (d / "scan.json").unlink(), "no scan.json"),
    "missing-image": (lambda d: (d / "view1.jpg").unlink(), "view 1: image file 'view1.jpg' not found"),
    "truncated-jpeg": (lambda d: (d / "view2.jpg").write_bytes((d / "view2.jpg").read_bytes()[:3000]),
                       "view 2: the JPEG is truncated"),
    "garbage-jpeg": (lambda d: (d / "view0.jpg").write_bytes(b"\xff\xd8 this is not a JPEG \xff\xd9"),
                     "view 0: the image is not a decodable image"),
    "empty-silhouette": (lambda d: edit_scan(d, lambda s: s.update(
        segmentation={"method": "hsv", "lower": [50, 90, 40], "upper": [70, 255, 255]})),
        "view 0: the silhouette is empty"),
    "silhouette-everywhere": (lambda d: edit_scan(d, lambda s: s.update(
        segmentation={"method": "threshold", "value": 0})), "touches all four image borders"),
    "one-view": (lambda d: edit_scan(d, lambda s: s.update(views=s["views"][:1])), "need at least 2 views"),
    "singular-pose": (lambda d: edit_scan(d, lambda s: s["views"][1].update(
        T_world_cam=[[0, 0, 0, 0.5], [0, 0, 0, 0], [0, 0, 0, 0.5], [0, 0, 0, 1]])), "view 1: T_world_cam"),
    "scaled-pose": (lambda d: edit_scan(d, lambda s: s["views"][2].update(
        T_world_cam=(np.diag([2.0, 2.0, 2.0, 1.0])).tolist())), "view 2: T_world_cam's rotation"),
    "nan-in-K": (lambda d: edit_scan(d, lambda s: s["views"][0]["K"][1].__setitem__(1, float("nan"))),
                 "view 0: K contains NaN"),
    "under-the-table": (lambda d: edit_scan(d, lambda s: s.update(support_plane=[0, 0, -1, 0])), "under the table"),
    "malformed-json": (lambda d: (d / "scan.json").write_text('{"views": ['), "scan.json is not valid JSON"),
}


def test_bad_bundles_fail_one_by_one(tmp_path, sphere_bundle_template):
    good = shutil.copytree(sphere_bundle_template, tmp_path / "good")
    bad = [_broken(tmp_path, sphere_bundle_template, name, change) for name, (change, _) in BAD_BUNDLES.items()]
    process = robocell("reconstruct", good, *bad, good)
    assert process.returncode == 1
    results = lines(process)
    assert len(results) == len(bad) + 2
    assert "superquadric" in results[0] and "superquadric" in results[-1]  # the others still finish
    for (name, (_, message)), result in zip(BAD_BUNDLES.items(), results[1:-1]):
        assert result["scan"] == str(tmp_path / name)
        assert message in result["error"], (name, result["error"])
        assert "\n" not in result["error"]
    assert all(str(tmp_path / name) in process.stderr for name in BAD_BUNDLES)  # said to a person too


def test_reconstruct_parses_alone_with_the_global_options():
    """`robocell reconstruct` builds only its own parser; the options before it still work."""
    from cell.cli import _command, build_parser

    argv = ["-v", "--config", "cell.toml", "reconstruct", "--points", "scan"]
    assert _command(argv) == "reconstruct"
    assert _command(["--config", "reconstruct", "sim"]) == "sim"  # a config file named reconstruct
    assert _command(["-v"]) is None
    args = build_parser("reconstruct").parse_args(argv)
    assert args.verbose and args.config == "cell.toml" and args.points and args.scan_dirs == ["scan"]
    with pytest.raises(SystemExit):
        build_parser("reconstruct").parse_args(["sim"])  # the others are not there
