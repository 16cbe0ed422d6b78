"""Models in parts (DESIGN.md §1.11, §1.12): unions of known superquadrics seen by ideal cameras
(rendered by workers/sim, not by the code under test), fitted back and scored against the truth."""

from __future__ import annotations

import dataclasses
import functools
import hashlib

import numpy as np
import pytest

from robocell.core_cy._silhouette_fit_cy import normal_equations
from robocell.core_cy.camera import Camera
from robocell.core_cy.edges import edge_samples, silhouette_outline
from robocell.core_cy.grasp import DEFAULT_GRIPPER, plan_grasps
from robocell.core_cy.reconstruct import Options, View, reconstruct
from robocell.core_cy.silhouette_fit import _Fitter, _Problem, _Views
from robocell.core_cy.superquadric import Superquadric, inside_outside
from robocell.wire.bundle import load_bundle
from robocell.workers.sim.judge import JudgeGripper, Part, judge, parts_from_truth, union_iou
from robocell.workers.sim.objects import CompoundObject, SuperquadricObject
from robocell.workers.sim.render import render
from robocell.workers.sim.scans import default_K, one_sided_set, plan_views, printed_products_set

TABLE = [0.0, 0.0, 1.0, 0.0]
JUDGE_GRIPPER = JudgeGripper.from_dict(DEFAULT_GRIPPER.to_dict())


def _placed(family: str, size, centre, yaw_deg: float = 0.0) -> SuperquadricObject:
    shape = {"box": (0.1, 0.1), "cylinder": (0.1, 1.0), "ellipsoid": (1.0, 1.0), "rounded-box": (0.4, 0.4)}[family]
    T = np.eye(4)
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = centre
    return SuperquadricObject(size, shape, T)


COMPOUNDS = {
    # A cylinder standing on a lying box, off its middle.
    "can on a box": lambda: CompoundObject("can on a box", [
        _placed("box", (0.06, 0.03, 0.015), (0.6, 0.0, 0.015), 20.0),
        _placed("cylinder", (0.02, 0.02, 0.03), (0.6 + 0.03 * np.cos(np.radians(20)),
                                                 0.03 * np.sin(np.radians(20)), 0.058))]),
    # An L: a lying bar and an upright block on its end.
    "l of boxes": lambda: CompoundObject("l of boxes", [
        _placed("box", (0.06, 0.02, 0.015), (0.6, 0.0, 0.015), -30.0),
        _placed("box", (0.018, 0.02, 0.04), (0.6 + 0.042 * np.cos(np.radians(-30)),
                                              0.042 * np.sin(np.radians(-30)), 0.068), -30.0)]),
}

SINGLES = {
    "box": lambda: SuperquadricObject.on_table("box", [0.05, 0.03, 0.025], (0.6, 0.0), 25.0),
    "cylinder": lambda: SuperquadricObject.on_table("cylinder", [0.03, 0.03, 0.06], (0.6, 0.0), 25.0),
    "ellipsoid": lambda: SuperquadricObject.on_table("ellipsoid", [0.045, 0.035, 0.03], (0.6, 0.0), 25.0),
    "rounded box": lambda: SuperquadricObject.on_table("rounded-box", [0.04, 0.035, 0.03], (0.6, 0.0), 25.0),
    "lying cylinder": lambda: SuperquadricObject.on_table("cylinder", [0.025, 0.025, 0.07], (0.6, 0.0), 25.0,
                                                          lying=True),
}


def _truth_parts(obj) -> list[Superquadric]:
    truth = obj.truth()
    return [Superquadric.from_dict(part) for part in truth.get("parts", [truth])]


def _cameras(obj, views: int, azimuths=None) -> list[Camera]:
    """Ideal cameras at 45 degrees looking at the object's middle, 0.5 m away; evenly around it
    unless ``azimuths`` (degrees) are given."""
    vertices = obj.mesh()[0]
    target = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    K = default_K()
    if azimuths is None:
        poses = plan_views(target, views, distance=(0.5, 0.5), elevation_deg=(45.0, 45.0), azimuth_start_deg=10.0)
    else:
        poses = [plan_views(target, 1, distance=(0.5, 0.5), elevation_deg=(45.0, 45.0),
                            azimuth_start_deg=float(a))[0] for a in azimuths]
    return [Camera(K=K, T_world_cam=pose, view=i) for i, pose in enumerate(poses)]


_masks: dict[tuple[str, bytes, bytes, bytes], np.ndarray] = {}


def _mask(obj, camera: Camera) -> np.ndarray:
    """``obj``'s true silhouette from ``camera``, rendered once per mesh and pose: several tests fit the
    same object from the same side (a fourth view's tests refit their three views four times)."""
    vertices, faces = obj.mesh()
    shape = hashlib.sha256(np.ascontiguousarray(vertices).tobytes() + np.ascontiguousarray(faces).tobytes())
    key = type(obj).__name__, shape.digest(), np.asarray(camera.T_world_cam).tobytes(), np.asarray(camera.K).tobytes()
    if key not in _masks:
        mask = render(obj, camera.T_world_cam, camera.K, noise_sigma=0.0)[1]
        mask.flags.writeable = False  # shared by the tests that fit it: none may change it
        _masks[key] = mask
    return _masks[key]


def _reconstruct(obj, cameras, **options):
    views = [View(camera, mask=_mask(obj, camera)) for camera in cameras]
    return reconstruct(views, support_plane=TABLE, options=Options(**options))


def _union_iou(fitted, true, n: int = 200_000, seed: int = 0) -> float:
    """Monte Carlo volumetric IoU of two unions of superquadrics."""
    centres = np.array([p.T_world_object[:3, 3] for p in (*fitted, *true)])
    reach = max(np.linalg.norm(p.size) for p in (*fitted, *true))
    low, high = centres.min(axis=0) - reach, centres.max(axis=0) + reach
    points = np.random.default_rng(seed).uniform(low, high, size=(n, 3))

    def inside(parts):
        return np.logical_or.reduce([inside_outside(points, p) <= 1.0 for p in parts])

    a, b = inside(fitted), inside(true)
    return float(np.count_nonzero(a & b) / np.count_nonzero(a | b))


@functools.lru_cache(maxsize=8)
def _compound_fit(name: str, views: int):
    obj = COMPOUNDS[name]()
    return obj, _reconstruct(obj, _cameras(obj, views))


@pytest.mark.parametrize("name", COMPOUNDS)
def test_a_union_of_two_superquadrics_is_recovered_as_two_parts(name):
    obj, result = _compound_fit(name, 3)
    truth = _truth_parts(obj)
    assert len(result.parts) == 2
    assert _union_iou(result.parts, truth) > 0.97
    # One superquadric could not: the parts are what explains the silhouettes.
    assert _union_iou([result.superquadric], truth) < 0.9
    assert min(result.silhouette_iou) > 0.95
    line = result.to_dict()
    assert len(line["parts"]) == 2 and set(line["parts"][0]) == {"size", "shape", "T_world_object"}


def test_a_union_is_found_where_the_screening_picks_a_part_that_does_not_pay(monkeypatch):
    # The screening (each proposal a few steps) is a guess: here its winner is made the one
    # superquadric with a speck inside it, a part that pays for nothing (as a start already at its
    # minimum can win on the real photographs). The proposals it left behind still find the two parts.
    obj = COMPOUNDS["can on a box"]()
    cameras = _cameras(obj, 3)
    single = _reconstruct(obj, cameras, max_parts=1).superquadric
    screened = _Fitter.best_of
    rounds = []

    def speck_first(self, starts, *args, **kwargs):
        best = screened(self, starts, *args, **kwargs)
        if isinstance(starts[0], Superquadric) or rounds:
            return best  # the one superquadric's own fit, or a later round of parts
        rounds.append(len(starts))
        speck = Superquadric(0.05 * single.size, single.shape, single.T_world_object)
        return self.descent((single, speck))

    monkeypatch.setattr(_Fitter, "best_of", speck_first)
    result = _reconstruct(obj, cameras)
    assert rounds and len(result.parts) == 2
    assert _union_iou(result.parts, _truth_parts(obj)) > 0.95


def _lying(yaw_deg: float, centre, size) -> SuperquadricObject:
    """A cylinder lying with its axis along the horizontal direction ``yaw_deg``."""
    axis = np.array([np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg)), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    T = np.eye(4)
    T[:3, :3] = np.stack([up, np.cross(axis, up), axis], axis=1)
    T[:3, 3] = centre
    return SuperquadricObject(size, (0.1, 1.0), T)


def _dumbbell(yaw_deg: float) -> CompoundObject:
    """Two round weights (2.8 cm radius, 3 cm wide) and the bar between them (0.9 cm radius), lying
    along ``yaw_deg``: between the weights only 5 cm of bar, hidden behind them along its axis."""
    axis = np.array([np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg)), 0.0])
    centre = np.array([0.6, 0.0, 0.028])
    return CompoundObject("dumbbell", [
        _lying(yaw_deg, centre, (0.009, 0.009, 0.053)),
        _lying(yaw_deg, centre - 0.04 * axis, (0.028, 0.028, 0.015)),
        _lying(yaw_deg, centre + 0.04 * axis, (0.028, 0.028, 0.015))])


@pytest.mark.parametrize("yaw", [20.0, 50.0])
def test_a_dumbbell_is_recovered_as_weights_without_the_gap_between_them(yaw):
    # One superquadric fills the gap between the weights (IoU about 0.56): the parts leave it out.
    obj = _dumbbell(yaw)
    result = _reconstruct(obj, _cameras(obj, 3))
    truth = _truth_parts(obj)
    assert _union_iou([result.superquadric], truth) < 0.6
    assert 2 <= len(result.parts) <= 3
    assert _union_iou(result.parts, truth) > 0.85


@pytest.mark.parametrize("name", SINGLES)
def test_a_single_superquadric_is_never_split(name):
    obj = SINGLES[name]()
    result = _reconstruct(obj, _cameras(obj, 3))
    assert len(result.parts) == 1
    assert _union_iou(result.parts, _truth_parts(obj)) > 0.97


@pytest.mark.parametrize("name", ["cylinder", "can on a box"])
def test_a_fourth_view_does_not_lower_the_iou(name):
    # Three views from one side (60 degrees of azimuth), then a fourth from each of four other sides.
    obj = SINGLES[name]() if name in SINGLES else COMPOUNDS[name]()
    truth = _truth_parts(obj)
    one_side = [10.0, 40.0, 70.0]
    three = _union_iou(_reconstruct(obj, _cameras(obj, 3, one_side)).parts, truth)
    for fourth in (130.0, 190.0, 250.0, 310.0):
        four = _union_iou(_reconstruct(obj, _cameras(obj, 4, one_side + [fourth])).parts, truth)
        assert four >= three - 0.02, f"a fourth view at {fourth} degrees: IoU {four:.3f} after {three:.3f}"


def test_a_thin_box_standing_on_its_edge_is_fitted_upright():
    # 10 x 6 cm and 1.2 cm thin, standing on a long edge.
    T = np.eye(4)
    c, s = np.cos(np.radians(35)), np.sin(np.radians(35))
    T[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
    T[:3, 3] = (0.6, 0.0, 0.03)
    obj = SuperquadricObject([0.05, 0.03, 0.006], (0.1, 0.1), T)
    result = _reconstruct(obj, _cameras(obj, 3))
    fit = result.superquadric
    # The fitted axis nearest the table's normal is the truth's height axis (its size 3 cm), upright.
    R = fit.T_world_object[:3, :3]
    up = int(np.argmax(np.abs(R[2])))
    assert np.degrees(np.arccos(min(1.0, abs(R[2, up])))) < 5.0
    assert fit.size[up] == pytest.approx(0.03, rel=0.1)
    assert _union_iou(result.parts, _truth_parts(obj)) > 0.9


def test_the_planner_refuses_a_grasp_whose_finger_cuts_the_second_part():
    # A box with a post standing close beside it: grasps of the box alone that close across its
    # length send a finger through the post; planned on the union, none does.
    box = Superquadric([0.02, 0.03, 0.02], [0.1, 0.1], _pose((0.6, 0.0, 0.02)))
    post = Superquadric([0.012, 0.012, 0.05], [0.1, 1.0], _pose((0.6, 0.048, 0.05)))
    true = parts_from_truth({"parts": [box.to_dict(), post.to_dict()]})
    alone = plan_grasps(box, TABLE, max_grasps=50)
    cut = [g for g in alone if _finger_hits(g, post)]
    assert cut, "the box alone has grasps that the post is in the way of"
    on_union = plan_grasps([box, post], TABLE, max_grasps=50)
    assert on_union
    assert not [g for g in on_union if _finger_hits(g, post)]
    verdict = judge(on_union[0].T_world_grasp, true, JUDGE_GRIPPER, TABLE, mu=DEFAULT_GRIPPER.friction)
    assert verdict.holds, verdict.reason


def _pose(centre) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = centre
    return T


def _finger_hits(grasp, part: Superquadric) -> bool:
    """Whether a finger, from full opening until its pad meets the grasped width, passes
    through the part: a dense grid of the swept volumes tested against its inside-outside function."""
    g = DEFAULT_GRIPPER
    x = np.linspace(-g.finger_width / 2, g.finger_width / 2, 5)
    y = np.linspace(grasp.width / 2 + 0.001, g.max_opening / 2 + g.finger_thickness, 12)
    z = np.linspace(g.palm, g.tip, 10)
    grid = np.stack(np.meshgrid(x, y, z, indexing="ij"), -1).reshape(-1, 3)
    grid = np.concatenate([grid, grid * [1, -1, 1]])
    world = grid @ grasp.T_world_grasp[:3, :3].T + grasp.T_world_grasp[:3, 3]
    return bool(np.any(inside_outside(world, part) < 1.0))


def test_union_normal_equations_match_central_differences():
    obj = COMPOUNDS["can on a box"]()
    cameras = _cameras(obj, 3)
    edges = [edge_samples(silhouette_outline(m), m, None, count=64)
             for m in (render(obj, c.T_world_cam, c.K, noise_sigma=0.0)[1] for c in cameras)]
    truth = _truth_parts(obj)
    views = _Views.pack(cameras, edges, truth[0].T_world_object[:3, 3])
    plane = np.array(TABLE)
    problem = _Problem(tuple(truth), views, plane, 500.0, 1.0)
    x = problem.x0 + np.random.default_rng(3).normal(size=22) * 0.01
    JtJ, Jtr = np.empty((22, 22)), np.empty(22)
    problem.evaluate(x, JtJ, Jtr)
    problem.keep(True)
    args = (problem.R0, problem.t0, problem.scale, problem.planes, 1.0, plane, 500.0, 0.0)
    owner = np.empty(views.count, np.intp)
    normal_equations(x, *args, JtJ, Jtr, True, owner)
    assert set(owner.tolist()) == {0, 1}  # each part answers for some of the samples
    numeric = np.empty(22)
    for k in range(22):
        step = np.zeros(22)
        step[k] = 1e-6
        numeric[k] = (normal_equations(x + step, *args, JtJ.copy(), Jtr.copy(), False)
                      - normal_equations(x - step, *args, JtJ.copy(), Jtr.copy(), False)) / 2e-6
    np.testing.assert_allclose(Jtr, numeric, rtol=1e-4, atol=1e-5 * np.abs(numeric).max())
    assert np.all(np.abs(JtJ[:11, 11:]) == 0)  # a residual is one part's


def test_a_view_of_something_else_gives_the_best_model_and_its_disagreement():
    # The third view shows another object: at most six parts, and the view's IoU says so.
    obj = COMPOUNDS["l of boxes"]()
    other = SINGLES["ellipsoid"]()
    cameras = _cameras(obj, 3)
    masks = [render(obj, c.T_world_cam, c.K, noise_sigma=0.0)[1] for c in cameras[:2]]
    masks.append(render(other, cameras[2].T_world_cam, cameras[2].K, noise_sigma=0.0)[1])
    result = reconstruct([View(c, mask=m) for c, m in zip(cameras, masks)], support_plane=TABLE)
    assert 1 <= len(result.parts) <= 6
    assert len(result.silhouette_iou) == 3 and all(0.0 <= iou <= 1.0 for iou in result.silhouette_iou)


def test_a_flat_hammer_lying_on_the_table_is_not_put_under_it(tmp_path):
    # Scene seed 1840 (bench_next_view's hammer seen from one side): with the fourth view 210 degrees
    # round, the silhouettes' enclosing sphere centres this flat object 2.3 mm below the table, which
    # is a centre placed low, not a wrong plane: the reconstruction stands, as good as the three views'.
    scan = next(s for s in one_sided_set(1, per_family=1) if s.spec.seed == 1840)
    scan.spec.write(tmp_path)
    bundle = load_bundle(tmp_path / scan.spec.name)
    truth = parts_from_truth(scan.spec.objects[0].truth())
    views = [*bundle.views[:scan.n_seen], bundle.views[scan.n_seen + 7]]
    result = reconstruct(views, segmentation=bundle.segmentation, support_plane=bundle.support_plane)
    assert union_iou([Part.from_dict(part.to_dict()) for part in result.parts], truth) > 0.93
    plane = np.asarray(bundle.support_plane)
    assert plane[:3] @ np.asarray(result.centre) + plane[3] > 0


def _product_with_true_masks(tmp_path, seed: int, name: str) -> float:
    """The volumetric IoU against the truth (the judge's) of the model of one of the simulator's printed products
    in parts (``printed_products_set(seed)``), reconstructed from its true masks."""
    spec = {spec.name: spec for spec in printed_products_set(seed)}[name]
    directory = spec.write(tmp_path)
    bundle = load_bundle(directory)
    views = [View(view.camera, mask=(directory / f"truth_mask{index}.png").read_bytes())
             for index, view in enumerate(bundle.views)]
    result = reconstruct(views, support_plane=bundle.support_plane)
    return union_iou([Part.from_dict(part.to_dict()) for part in result.parts],
                     parts_from_truth(spec.objects[0].truth()))


def test_a_hammer_s_handle_is_no_rod_running_on_past_what_the_cameras_saw(tmp_path):
    """A white hammer on oak, its true masks given (``printed_products_set(9)``): a rod along the handle explains
    the handle's edges, and nothing pulls back its outline where it runs on past every sample, so the one
    superquadric grew along the handle to 1.2 m and the parts followed (volumetric IoU 0.013 before). No part
    reaches farther than the views see the object reach."""
    assert _product_with_true_masks(tmp_path, 9, "oak-white-ycb-hammer") > 0.95


def test_a_drill_s_barrel_is_a_cylinder_along_its_length_not_a_square_bar_across(tmp_path):
    """A drill standing on fabric, its true masks given (``printed_products_set(15)``): the parts search fitted
    its barrel, a round cylinder along x, as a square bar whose z axis stood across it, which cannot be round in
    its cross-section; its outlines ran 0.93 px from the samples, the true union's 0.16 (volumetric IoU 0.78
    before). Each part is also tried with another of its axes as z, as the one superquadric is."""
    assert _product_with_true_masks(tmp_path, 15, "fabric-dark-power-drill") > 0.9


def _printed_parts(printed_scene, seed: int, name: str, backgrounds: bool = False) -> tuple[int, float]:
    """How many parts ``auto``'s model of one of the simulator's printed scenes (the ``printed_scene``
    fixture) has (its images alone, a single-superquadric object with its cast shadow; ``backgrounds``:
    with a photograph of the empty table beside each view), and its volumetric IoU with the truth."""
    spec, directory = printed_scene(seed, name)
    bundle = load_bundle(directory)
    views = bundle.views if backgrounds else [dataclasses.replace(view, background=None) for view in bundle.views]
    result = reconstruct(views, segmentation=bundle.segmentation, support_plane=bundle.support_plane)
    model = [Part.from_dict(part.to_dict()) for part in result.parts]
    return len(result.parts), union_iou(model, parts_from_truth(spec.objects[0].truth()))


def test_a_shadow_that_one_view_took_in_is_no_slab(printed_scene):
    """A tin lying on wood: one view's silhouette takes in the strip of shadow beside its foot. Three slabs,
    one held edge-on to the other views, explained that view the better with less volume than the tin,
    which passed for carving away what the view shows empty (3 parts, 0.515 before). It covers more of
    that view, not less, and the shadow's pixels are the table's shade: the tin stays one part."""
    parts, iou = _printed_parts(printed_scene, 2, "wood-tin-lying-can")
    assert parts == 1
    assert iou > 0.83


def test_a_dark_face_that_one_view_left_out_is_no_second_part(printed_scene):
    """A box of the oak table's own colour and grain, lit from one side: one view's silhouette leaves out
    its face turned from the lamp, as dark as the shadow beside it. A slab on a lower box explained that
    and the other views' small errors by a little more than a part pays (2 parts, 0.589 before); on the
    pixels whose colour says which side they are on, it does not pay, and the box stays one part."""
    parts, iou = _printed_parts(printed_scene, 1, "oak-table-colour-box")
    assert parts == 1
    assert iou > 0.85


def test_a_box_that_one_view_sees_wrong_rests_on_a_face(printed_scene):
    """A box of the oak table's own colour, a background photographed: the third view's silhouette leaves
    out much of the box (0.70 against the truth, the others 0.91 and 0.90). One superquadric tilted 21
    degrees, balanced on an edge as no box rests, followed it (0.587 before); held at rest on a face it
    explains the silhouettes as well, and the tilt pays in no two views."""
    parts, iou = _printed_parts(printed_scene, 8, "oak-table-colour-box", backgrounds=True)
    assert parts == 1
    assert iou > 0.75


def test_a_top_that_two_views_left_out_is_no_slab(printed_scene):
    """A tall sugar box on white laminate: two views' silhouettes leave out its white top, lit as the table
    is; the third sees the box whole. A box cut short with a slab 9 mm thick along one end, as tall as the
    third view says, explained the first two the better by covering less beyond their silhouettes' convex
    hulls, where a face left out explains them as well (2 parts, 0.790 before): it stays one box."""
    parts, iou = _printed_parts(printed_scene, 10, "laminate-sugar-box-tall-box")
    assert parts == 1
    assert iou > 0.9


def test_which_samples_a_resting_box_contradicts_its_own_outline_says(printed_scene):
    """A box of the oak table's own colour, its images alone: two views' silhouettes are far off (0.54 and
    0.52 against the truth), the third near (0.95). The one superquadric stood tilted 33 degrees; held at rest,
    it was fitted with the samples that the tilted model's outline contradicted set doubtful (0.470); with
    those its own outline contradicts instead, 0.70."""
    parts, iou = _printed_parts(printed_scene, 9, "oak-table-colour-box")
    assert parts == 1
    assert iou > 0.65


@pytest.mark.parametrize("name", ["hammer-00", "t-bars-00"])
def test_a_union_on_the_table_is_held_at_rest_as_one_superquadric_is(tmp_path, name):
    """Two bars on the table, a hammer and a T, three views all around (the simulator's compound scenes):
    each bar rests on a face. The union, fitted held at rest as one superquadric is, its tilt kept only
    where it pays (none does), matches the truth (0.95 each while a tilted part of a union was only tried
    upright and let tilt again)."""
    from robocell.workers.sim.scans import compound_set

    spec = {spec.name: spec for spec in compound_set(0, per_kind=1)}[name]
    spec.write(tmp_path)
    bundle = load_bundle(tmp_path / name)
    result = reconstruct(bundle.views, segmentation=bundle.segmentation, support_plane=bundle.support_plane)
    model = [Part.from_dict(part.to_dict()) for part in result.parts]
    assert len(result.parts) == 2
    assert union_iou(model, parts_from_truth(spec.objects[0].truth())) > 0.98


def test_a_tilt_that_every_view_sees_is_kept():
    """A box held tilted 20 degrees on the table (on a wedge, say): resting on a face, it would explain
    every view worse by far more than a part must pay, so the tilt stays (volumetric IoU 0.93, as before
    the model was tried at rest)."""
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    T = np.eye(4)
    T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    T[:3, 3] = (0.6, 0.0, 0.05 * s + 0.025 * c)  # its lowest edge on the table
    obj = SuperquadricObject([0.05, 0.03, 0.025], (0.1, 0.1), T)
    result = _reconstruct(obj, _cameras(obj, 3))
    R = result.superquadric.T_world_object[:3, :3]
    assert np.degrees(np.arccos(min(1.0, float(np.max(np.abs(R[2])))))) == pytest.approx(20.0, abs=1.0)
    assert _union_iou(result.parts, _truth_parts(obj)) > 0.9


def test_a_shadow_on_the_table_that_the_views_took_in_is_no_part(printed_scene):
    """A dark can on a dark rubber mat: two views' silhouettes take in its shadow, which lies on the table
    in every view alike (2 parts before: the can and a sheet on the shadow). The model is the can alone.
    How well it fits depends on the search's path: with Python 3.11's numpy a sheet on the table is
    found, keeps the shadow off the can's outline and leaves the model (0.98); with 3.13's the sheet is
    never tried and the can is fitted round the shadow (0.745)."""
    parts, iou = _printed_parts(printed_scene, 1, "rubber-mat-dark-can")
    assert parts == 1
    assert iou > 0.7


def test_a_part_that_no_view_sees_rise_off_the_table_is_flat_on_it():
    """A sheet 0.8 mm thick on the table rises less than the edges' noise in every view: paint or a shadow
    to the cameras. A can of the same footprint standing there, or the sheet lifted 2 cm, does not."""
    from robocell.core_cy.parts import _flat_on_table

    plane = np.array([0.0, 0.0, 1.0, 0.0])
    K = default_K()
    cameras = [Camera(K=K, T_world_cam=T, view=i) for i, T in enumerate(
        plan_views([0.6, 0.0, 0.0], 3, (0.5, 0.55), (35.0, 55.0), 20.0, np.random.default_rng(0)))]

    def at(height: float, half_height: float) -> Superquadric:
        T = np.eye(4)
        T[:3, 3] = [0.6, 0.0, height]
        return Superquadric([0.04, 0.03, half_height], [0.2, 0.2], T)

    assert _flat_on_table(at(0.0004, 0.0004), cameras, plane)
    assert not _flat_on_table(at(0.05, 0.05), cameras, plane)
    assert not _flat_on_table(at(0.02, 0.0004), cameras, plane)


def test_a_part_that_one_view_pays_for_at_another_views_cost_is_not_kept(printed_scene):
    """A box of the oak table's own colour: one view's silhouette leaves out much of it (0.64 IoU with the
    box). A second part, the union thinner, explained that view by 0.08 more and carved away what it shows
    empty, but explained another view by 0.05 less (2 parts, 0.634 before): that moves one view's error to
    another, and the box stays one part."""
    parts, iou = _printed_parts(printed_scene, 4, "oak-table-colour-box")
    assert parts == 1
    assert iou > 0.85


def test_a_view_that_left_out_a_face_is_not_carved_into_slabs(printed_scene):
    """A tall printed box on white laminate, its empty table photographed: one view's silhouette leaves
    out the box's white top face (0.84 IoU with the one box). Three slabs round a column covered less
    of it and passed for carving away what that view shows empty (3 parts, 0.640 before), but what
    they left out lies beyond the silhouette's convex hull, where a face left out explains it as well
    as table seen through the object: the box stays one part."""
    parts, iou = _printed_parts(printed_scene, 5, "laminate-sugar-box-tall-box", backgrounds=True)
    assert parts == 1
    assert iou > 0.95


def test_a_part_whose_thickness_no_view_sees_is_a_sheet():
    """A sheet 0.6 mm thick, lifted 5 cm over the table, spans less than the edges' noise across its
    thickness in every view: no body to the cameras. A plate 8 mm thick, lying or standing, is one."""
    from robocell.core_cy.parts import _sheet

    K = default_K()
    cameras = [Camera(K=K, T_world_cam=T, view=i) for i, T in enumerate(
        plan_views([0.6, 0.0, 0.0], 3, (0.5, 0.55), (35.0, 55.0), 20.0, np.random.default_rng(0)))]

    def plate(half_thickness: float, standing: bool = False) -> Superquadric:
        T = np.eye(4)
        T[:3, 3] = [0.6, 0.0, 0.05]
        if standing:
            T[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
        return Superquadric([0.04, 0.03, half_thickness], [0.2, 0.2], T)

    assert _sheet(plate(0.0003), cameras)
    assert _sheet(plate(0.0003, standing=True), cameras)
    assert not _sheet(plate(0.004), cameras)
    assert not _sheet(plate(0.004, standing=True), cameras)


def test_a_box_the_colour_of_its_table_is_no_two_sheets(printed_scene):
    """A box of the oak table's own colour and grain: one view's silhouette takes in its shadow, another a
    stretch of table, and most of its outline is on pixels auto cannot confirm. Held only by the samples
    left, along the shadow and the table, the fit made it a slab floating over the table from every start
    (0.01; two sheets once, 0.004), right or not as the last bit of a descent fell (0.95 on one platform,
    0.56 on another). Fitted with every sample sure, it agrees the better with the silhouettes: the
    model is a body where the box is, on any platform."""
    parts, iou = _printed_parts(printed_scene, 5, "oak-table-colour-box")
    assert iou > 0.9


def test_a_stretch_of_outline_that_the_other_views_contradict_does_not_drag_the_model(printed_scene):
    """A box of the oak table's own colour: the views' silhouettes each take in or leave out a stretch
    that their colours cannot tell (0.888 / 0.879 / 0.899 IoU with the truth), and the one superquadric
    followed them (0.866). The samples of those stretches, far from the outline the views hold it to,
    are doubtful, and the fit goes on without their pull."""
    parts, iou = _printed_parts(printed_scene, 3, "oak-table-colour-box")
    assert parts == 1
    assert iou > 0.89
