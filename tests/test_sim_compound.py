"""Compound simulated objects, one-sided scans and the judge of unions: what the benchmarks score against."""

from __future__ import annotations

import numpy as np
import pytest

from robocell.core_cy.camera import Camera
from tests.helpers import intrinsics, sphere_silhouette
from robocell.workers.sim.judge import Part, inside_union, parts_from_truth, union_iou, union_silhouette_iou
from robocell.workers.sim.objects import COMPOUNDS, EVERYDAY, compound
from robocell.workers.sim.scans import compound_set, fourth_view_candidates, one_sided_set, one_sided_views

KINDS = sorted(EVERYDAY)


@pytest.mark.parametrize("kind", KINDS)
def test_each_kind_is_one_body_of_parts_resting_on_the_table(kind):
    obj = compound(kind, (0.6, 0.05), yaw_deg=70.0, seed=3)
    vertices, _ = obj.mesh()
    assert vertices[:, 2].min() == pytest.approx(0.0, abs=1e-9)  # resting on the table, not in it
    assert 0.03 < np.ptp(vertices, axis=0).max() < 0.2  # an object a wrist camera frames at 0.4-0.7 m
    truth = parts_from_truth(obj.truth())
    assert len(truth) == len(obj.parts) >= 2
    # truth.json describes what is rendered: the same inside test on random points.
    rng = np.random.default_rng(0)
    points = rng.uniform(vertices.min(0) - 0.005, vertices.max(0) + 0.005, size=(20000, 3))
    np.testing.assert_array_equal(inside_union(points, truth), obj.inside(points))
    # One body: every part overlaps another (a grid of its own points, its ends included, reaches into one).
    for i, part in enumerate(truth):
        others = [p for j, p in enumerate(truth) if j != i]
        grid = np.stack(np.meshgrid(*[np.linspace(-1, 1, 25)] * 3), -1).reshape(-1, 3) * part.size
        world = grid @ part.T_world_part[:3, :3].T + part.T_world_part[:3, 3]
        mine = inside_union(world, [part])
        assert np.any(mine & inside_union(world, others)), f"{kind}: part {i} touches no other part"


def test_the_grasp_benchmarks_compounds_are_unchanged():
    assert list(COMPOUNDS) == ["cups", "mug", "box-and-ball", "l-boxes"]
    with pytest.raises(ValueError, match="no compound object 'kettle'"):
        compound("kettle", (0.6, 0.0))


def test_compound_set_names_each_kind():
    specs = compound_set(0, per_kind=2)
    assert [s.name for s in specs[:2]] == [f"{KINDS[0]}-00", f"{KINDS[0]}-01"] or specs[0].name.endswith("-00")
    assert {s.name.rsplit("-", 1)[0] for s in specs} == set(EVERYDAY)
    assert len(specs) == 2 * len(EVERYDAY) and all(len(s.cameras) == 3 for s in specs)


def azimuth_deg(T, target) -> float:
    offset = T[:3, 3] - target
    return float(np.degrees(np.arctan2(offset[1], offset[0])))


def test_one_sided_views_span_sixty_degrees_of_azimuth_aimed_at_the_target():
    target = np.array([0.6, 0.1, 0.04])
    poses = one_sided_views(target, 100.0, 0.5)
    assert [round(azimuth_deg(T, target), 6) for T in poses] == [70.0, 100.0, 130.0]
    for T in poses:
        assert np.linalg.norm(T[:3, 3] - target) == pytest.approx(0.5)
        forward = T[:3, 2]
        np.testing.assert_allclose(forward, (target - T[:3, 3]) / 0.5, atol=1e-12)
    candidates = fourth_view_candidates(target, 0.5, azimuth_start_deg=100.0)
    assert len(candidates) == 12
    steps = np.diff([azimuth_deg(T, target) for T in candidates]) % 360
    np.testing.assert_allclose(steps, 30.0)


def test_one_sided_compounds_turn_their_second_part_away_from_the_cameras():
    scans = [s for s in one_sided_set(0, families=()) if s.family in ("mug", "hammer")]
    assert len(scans) == 2
    for scan in scans:
        obj = scan.spec.objects[0]
        seen = scan.spec.cameras[:3]
        assert len(scan.spec.cameras) == 15
        towards_cameras = np.mean([T[:2, 3] for T in seen], axis=0) - obj.parts[0].T_world_object[:2, 3]
        plus_x = obj.parts[0].T_world_object[:2, 0]  # the side the handle, the head, stands on
        assert plus_x @ towards_cameras / np.linalg.norm(towards_cameras) < -0.9  # within ~25 degrees of away


def box_part(centre, half=1.0) -> Part:
    T = np.eye(4)
    T[:3, 3] = centre
    return Part(np.full(3, half), np.array([0.02, 0.02]), T)


def test_union_iou_worked_out_by_hand():
    # Two cubes of side 2, the second moved by 1 along x: overlap 4, union 12.
    assert union_iou([box_part([0, 0, 0])], [box_part([1, 0, 0])]) == pytest.approx(1 / 3, abs=0.01)
    # A model of both cubes against the pair as truth, and against one of them: 12 / 12 and 8 / 12.
    pair = [box_part([0, 0, 0]), box_part([1, 0, 0])]
    assert union_iou(list(reversed(pair)), pair) == 1.0
    assert union_iou([box_part([0, 0, 0])], pair) == pytest.approx(8 / 12, abs=0.01)
    assert union_iou([box_part([10, 0, 0])], pair) == 0.0


def test_union_silhouette_iou_of_a_sphere_seen_by_an_ideal_camera():
    K = intrinsics()
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, -0.5]
    camera = Camera(K=K, T_world_cam=T)
    silhouette = sphere_silhouette(camera, np.zeros(3), 0.05)
    sphere = Part(np.full(3, 0.05), np.array([1.0, 1.0]), np.eye(4))
    assert union_silhouette_iou([sphere], K, T, silhouette) > 0.97
    half = Part(np.array([0.05, 0.05, 0.05]), np.array([1.0, 1.0]), np.eye(4))
    moved = half.T_world_part.copy()
    moved[0, 3] = 0.1  # a second sphere, beside the first, that the silhouette does not have
    both = [sphere, Part(half.size, half.shape, moved)]
    assert union_silhouette_iou(both, K, T, silhouette) == pytest.approx(0.5, abs=0.03)


def test_robocell_sim_writes_an_everyday_compound_with_its_parts(tmp_path, capsys):
    import json

    from robocell.cli.main import main

    assert main(["sim", "scans", "--shape", "hammer", "--out", str(tmp_path)]) == 0
    (bundle,) = [line for line in capsys.readouterr().out.splitlines() if line]
    truth = json.loads((tmp_path / "hammer-000" / "truth.json").read_text())
    assert bundle.endswith("hammer-000")
    # The head and the handle, as the simulator's own object says: nothing lost on the way to the file.
    expected = compound("hammer", (0.6, 0.0), 30.0, seed=0).truth()["parts"]
    assert len(truth["parts"]) == len(expected) >= 2
    np.testing.assert_allclose([p["size"] for p in truth["parts"]], [p["size"] for p in expected])
