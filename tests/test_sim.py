"""Tests of the simulator (workers.sim): objects, rendering, cameras, bundles, CLI.

Answers are worked out independently of the code under test where possible:
a sphere's image is an ellipse with a closed form, a superquadric's volume is
a product of Beta functions, a convex object projects inside its silhouette.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.special import beta

from robocell.cli import sim as cli
from robocell.workers.sim import objects
from robocell.workers.sim.objects import FAMILIES, CupStack, LumpyFigure, SuperquadricObject, vertex_normals
from robocell.workers.sim.render import TableScene, project, render
from robocell.workers.sim.scans import (
    HSV_SEGMENTATION,
    default_K,
    look_at,
    plan_views,
    standard_set,
    write_scan,
)

K_ODD = np.array([[610.0, 0.0, 300.0], [0.0, 590.0, 250.0], [0.0, 0.0, 1.0]])  # fx != fy, off-centre


def hsv_mask(bgr: np.ndarray, seg: dict) -> np.ndarray:
    """The HSV segmentation of DESIGN.md §3, hue range wrapping round 0 when lower > upper."""
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    lo, hi = seg["lower"], seg["upper"]
    h = hsv[..., 0]
    hue = (h >= lo[0]) | (h <= hi[0]) if lo[0] > hi[0] else (h >= lo[0]) & (h <= hi[0])
    sv = (hsv[..., 1] >= lo[1]) & (hsv[..., 1] <= hi[1]) & (hsv[..., 2] >= lo[2]) & (hsv[..., 2] <= hi[2])
    return hue & sv


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def sq_volume(size, shape) -> float:
    """Closed-form superquadric volume (Jaklic, Leonardis, Solina 2000)."""
    (a1, a2, a3), (e1, e2) = size, shape
    return 2 * a1 * a2 * a3 * e1 * e2 * beta(e1 / 2 + 1, e1) * beta(e2 / 2, e2 / 2)


def mesh_volume(v: np.ndarray, f: np.ndarray) -> float:
    t = v[f]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6)


# --- cameras -----------------------------------------------------------------


def test_look_at_is_rigid_and_aims_at_target():
    pos, target = np.array([0.3, -0.25, 0.4]), np.array([0.62, 0.04, 0.03])
    T = look_at(pos, target)
    R = T[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)  # right-handed
    np.testing.assert_allclose(T[3], [0, 0, 0, 1])
    np.testing.assert_allclose(T[:3, 3], pos)
    np.testing.assert_allclose(R[:, 2], (target - pos) / np.linalg.norm(target - pos), atol=1e-12)
    assert abs(R[2, 0]) < 1e-12  # image x axis horizontal
    assert R[2, 1] < 0  # image y axis points down in the world
    uv, z = project(target, T, K_ODD)
    np.testing.assert_allclose(uv[0], [300.0, 250.0], atol=1e-9)
    assert z[0] == pytest.approx(np.linalg.norm(target - pos))


def test_look_at_right_is_right():
    # Looking along +x with z up, world -y is on the right of the image.
    T = look_at([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    uv, _ = project([[1.0, -0.1, 0.0], [1.0, 0.0, 0.1]], T, default_K())
    assert uv[0, 0] > 319.5  # right
    assert uv[1, 1] < 239.5  # up


def test_look_at_rejects_degenerate():
    with pytest.raises(ValueError):
        look_at([0, 0, 1], [0, 0, 0])  # straight down, along up
    with pytest.raises(ValueError):
        look_at([1, 2, 3], [1, 2, 3])


def test_plan_views_ranges_and_spacing():
    target = np.array([0.6, 0.0, 0.04])
    cams = plan_views(target, 4, (0.45, 0.6), (40, 50), 10.0, np.random.default_rng(5), jitter_deg=2.0)
    assert len(cams) == 4
    az = []
    for T in cams:
        off = T[:3, 3] - target
        d = np.linalg.norm(off)
        assert 0.45 <= d <= 0.6
        assert 40 <= np.degrees(np.arcsin(off[2] / d)) <= 50
        az.append(np.degrees(np.arctan2(off[1], off[0])))
        # The optical axis passes within the jitter of the target.
        angle = np.degrees(np.arccos(-(T[:3, 2] @ off) / d))
        assert angle <= 2.0 * np.sqrt(2) + 1e-9
    steps = np.diff(np.unwrap(np.radians(az)))
    np.testing.assert_allclose(np.degrees(steps), 90.0, atol=4.0 + 1e-9)


def test_plan_views_without_rng_is_exact():
    target = np.array([0.6, 0.0, 0.05])
    for T in plan_views(target, 3):
        assert np.linalg.norm(T[:3, 3] - target) == pytest.approx(0.55)
        np.testing.assert_allclose(project(target, T, default_K())[0][0], [319.5, 239.5], atol=1e-9)


# --- objects -----------------------------------------------------------------


@pytest.mark.parametrize("lying", [False, True])
@pytest.mark.parametrize("family", list(FAMILIES))
def test_superquadric_stands_on_table(family, lying):
    size = np.array([0.05, 0.03, 0.02])
    obj = SuperquadricObject.on_table(family, size, (0.6, 0.02), 37.0, lying)
    v, f = obj.mesh()
    assert abs(v[:, 2].min()) <= 1e-6 * size.min()
    # Upright it rests on a3, lying on a2 (its y axis points up).
    assert obj.T_world_object[2, 3] == pytest.approx(size[1] if lying else size[2])
    assert f.dtype == np.int32 and v.dtype == np.float64
    # A closed, outward mesh whose volume matches the closed form.
    assert mesh_volume(v, f) == pytest.approx(sq_volume(size, FAMILIES[family]), rel=5e-3)
    edges = {tuple(e) for e in np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]).tolist()}
    assert len(edges) == 3 * len(f) and all((b, a) in edges for a, b in edges)  # closed, oriented
    helper = getattr(objects, family.replace("-", "_"))(size, (0.6, 0.02), 37.0, lying)
    assert helper.truth() == obj.truth()


def test_support_function_for_any_orientation():
    rng = np.random.default_rng(3)
    for shape in FAMILIES.values():
        obj = SuperquadricObject([0.04, 0.025, 0.03], shape, np.eye(4))
        v = obj.mesh()[0]
        for n in rng.normal(size=(5, 3)):
            n /= np.linalg.norm(n)
            h = obj.support(n)
            assert (v @ n).max() <= h + 1e-12  # nothing beyond the support plane
            assert (v @ n).max() >= 0.99 * h  # and the mesh reaches it


@pytest.mark.parametrize("family", list(FAMILIES))
def test_superquadric_inside_agrees_with_mesh(family):
    obj = SuperquadricObject.on_table(family, [0.045, 0.03, 0.025], (0.55, -0.03), 20.0, lying=True)
    v, f = obj.mesh()
    n = vertex_normals(v, f)
    step = 1e-3 * 0.025
    assert obj.inside(v - step * n).all()
    assert not obj.inside(v + step * n).any()
    # Monte Carlo volume of inside() matches the closed form.
    rng = np.random.default_rng(0)
    lo, hi = v.min(axis=0), v.max(axis=0)
    p = lo + rng.random((200_000, 3)) * (hi - lo)
    vol = obj.inside(p).mean() * np.prod(hi - lo)
    assert vol == pytest.approx(sq_volume(obj.size, obj.shape), rel=0.02)


def test_superquadric_inside_far_points_no_warning():
    obj = SuperquadricObject.on_table("box", [0.03, 0.03, 0.03], (0.0, 0.0))
    assert not obj.inside([[1e3, 0.0, 0.0], [0.0, -1e6, 5.0]]).any()
    with pytest.raises(ValueError):
        SuperquadricObject([0.1, 0.1, 0.1], [0.1, 2.5], np.eye(4))


@pytest.mark.parametrize("inverted", [True, False])
def test_cup_stack(inverted):
    cups = CupStack((0.6, 0.1), 0.025, 0.04, 0.06, top_inverted=inverted, nest_offset=0.02)
    v, f = cups.mesh()
    assert v[:, 2].min() == 0.0
    assert v[:, 2].max() == pytest.approx(0.12 if inverted else 0.08)
    assert mesh_volume(v, f) > 0
    c = [0.6, 0.1]
    inside = cups.inside([[*c, 0.001], [*c, 0.07], [0.6 + 0.039, 0.1, 0.059], [0.6 + 0.026, 0.1, 0.001]])
    assert inside.tolist() == [True, True, True, False]
    t = cups.truth()
    assert t["kind"] == "cup-stack" and t["bbox_min"][2] == 0.0
    json.dumps(t)


def test_lumpy_figure():
    lumpy = LumpyFigure((0.6, 0.0), (0.05, 0.04, 0.045), seed=4)
    v, f = lumpy.mesh()
    assert v[:, 2].min() == 0.0
    assert mesh_volume(v, f) > 0
    up = v[:, 2] > 1e-3  # away from the cut base, the mesh vertices are on the surface
    radial = v[up] - lumpy.centre
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert lumpy.inside(v[up] - 1e-5 * radial).all()
    assert not lumpy.inside(v[up] + 1e-5 * radial).any()
    assert not lumpy.inside([[0.6, 0.0, -1e-4]]).any()  # nothing under the table
    r = np.linalg.norm(v[up] - lumpy.centre, axis=1)
    assert r.max() / r.min() > 1.5  # lumpy, not a sphere
    again = LumpyFigure((0.6, 0.0), (0.05, 0.04, 0.045), seed=4)
    np.testing.assert_array_equal(again.mesh()[0], v)


# --- rendering ---------------------------------------------------------------


def sphere_ellipse(centre_cam: np.ndarray, r: float, K: np.ndarray) -> tuple[float, np.ndarray]:
    """Area (px^2) and centroid (px) of a sphere's image: the conic of its tangent cone."""
    C = centre_cam
    Q = (C @ C - r * r) * np.eye(3) - np.outer(C, C)  # d^T Q d <= 0 inside, d = (x, y, 1)
    M, b, c = Q[:2, :2], Q[:2, 2], Q[2, 2]
    x0 = -np.linalg.solve(M, b)
    k = b @ np.linalg.solve(M, b) - c
    area = np.pi * k / np.sqrt(np.linalg.det(M)) * K[0, 0] * K[1, 1]
    return area, K[:2, :2] @ x0 + K[:2, 2]


def test_sphere_mask_matches_analytic_ellipse():
    r = 0.04
    ball = SuperquadricObject.on_table("ellipsoid", [r, r, r], (0.62, 0.06))
    centre = ball.T_world_object[:3, 3]
    # Off-centre on purpose: the image is then a true ellipse whose centroid is
    # not the projection of the sphere's centre.
    T = look_at([0.3, -0.28, 0.42], [0.5, 0.3, 0.1])
    bgr, mask = render(ball, T, K_ODD, image_size=(640, 480), noise_sigma=0.0)
    area, centroid = sphere_ellipse((centre - T[:3, 3]) @ T[:3, :3], r, K_ODD)
    ys, xs = np.nonzero(mask)
    assert len(xs) == pytest.approx(area, rel=0.015)
    np.testing.assert_allclose([xs.mean(), ys.mean()], centroid, atol=0.25)
    centre_px = project(centre, T, K_ODD)[0][0]
    assert np.linalg.norm(centre_px - centroid) > 1.0  # the test can tell the two apart
    assert bgr.shape == (480, 640, 3) and bgr.dtype == np.uint8 and set(np.unique(mask)) == {0, 255}


@pytest.mark.parametrize("dist", [None, [-0.25, 0.08, 0.001, -0.002, 0.0]])
def test_convex_object_projects_inside_its_mask(dist):
    box = SuperquadricObject.on_table("rounded-box", [0.05, 0.03, 0.025], (0.7, 0.1), 25.0)
    T = look_at([0.35, -0.2, 0.45], [0.6, 0.0, 0.0])  # object well off the image centre
    _, mask = render(box, T, default_K(), dist, noise_sigma=0.0)
    grown = cv2.dilate(mask, np.ones((3, 3), np.uint8))
    uv, _ = project(box.mesh()[0], T, default_K(), dist)
    px = np.rint(uv).astype(int)
    # Every point of a convex solid projects into its silhouette.
    assert (grown[px[:, 1], px[:, 0]] > 0).all()
    # And the silhouette is no larger than the projected points' hull.
    hull = np.zeros_like(mask)
    cv2.fillConvexPoly(hull, cv2.convexHull(np.rint(uv * 16).astype(np.int32)), 255, cv2.LINE_8, 4)
    assert iou(mask > 0, hull > 0) > 0.97


def test_render_occlusion_nearer_object_wins():
    far = SuperquadricObject.on_table("box", [0.05, 0.05, 0.05], (0.8, 0.0))
    near = SuperquadricObject.on_table("box", [0.02, 0.02, 0.02], (0.5, 0.0))
    T = look_at([0.2, 0.0, 0.1], [0.8, 0.0, 0.03])
    both, m_both = render([far, near], T, default_K(), noise_sigma=0.0)
    order, m_order = render([near, far], T, default_K(), noise_sigma=0.0)
    np.testing.assert_array_equal(both, order)  # the order of the list does not matter
    _, m_far = render(far, T, default_K(), noise_sigma=0.0)
    _, m_near = render(near, T, default_K(), noise_sigma=0.0)
    np.testing.assert_array_equal(m_both, np.maximum(m_far, m_near))


# --- bundles -----------------------------------------------------------------


def _seed_for(kind: str) -> int:
    return next(s for s in range(100) if TableScene.from_seed(s).kind == kind)


@pytest.mark.parametrize("kind", ["wood", "fabric"])
def test_write_scan_bundle(tmp_path: Path, kind: str):
    seed = _seed_for(kind)
    obj = SuperquadricObject.on_table("cylinder", [0.03, 0.03, 0.05], (0.58, -0.04), 10.0, lying=True)
    target = obj.T_world_object[:3, 3]
    cams = plan_views(target, 3, rng=np.random.default_rng(seed))
    K = default_K()
    out = write_scan(tmp_path / "a", obj, cams, K, seed=seed, write_masks=True)
    scan = json.loads((out / "scan.json").read_text())
    assert set(scan) == {"views", "segmentation", "support_plane"}
    assert scan["segmentation"] == HSV_SEGMENTATION
    assert HSV_SEGMENTATION == {"method": "hsv", "lower": [170, 90, 20], "upper": [10, 255, 255]}
    assert scan["support_plane"] == [0, 0, 1, 0]
    assert len(scan["views"]) == 3
    for i, view in enumerate(scan["views"]):
        assert set(view) == {"image", "K", "T_world_cam"}  # no dist given, masks not named
        np.testing.assert_allclose(view["K"], K)
        np.testing.assert_allclose(view["T_world_cam"], cams[i])
        bgr = cv2.imread(str(out / view["image"]), cv2.IMREAD_COLOR)
        assert bgr is not None and bgr.shape == (480, 640, 3)
        truth_mask = cv2.imread(str(out / f"mask{i}.png"), cv2.IMREAD_UNCHANGED) > 0
        assert iou(hsv_mask(bgr, scan["segmentation"]), truth_mask) > 0.95
    truth = json.loads((out / "truth.json").read_text())
    assert truth["kind"] == "superquadric"
    np.testing.assert_allclose(truth["size"], obj.size)
    np.testing.assert_allclose(truth["shape"], FAMILIES["cylinder"])
    np.testing.assert_array_equal(truth["T_world_object"], obj.T_world_object)  # exact round trip
    # Deterministic: the same call writes the same bytes.
    again = write_scan(tmp_path / "b", obj, cams, K, seed=seed, write_masks=True)
    for name in sorted(p.name for p in out.iterdir()):
        assert (out / name).read_bytes() == (again / name).read_bytes(), name


def test_write_scan_with_distortion_and_two_objects(tmp_path: Path):
    objs = [CupStack((0.6, 0.0)), LumpyFigure((0.6, 0.12), seed=1)]
    cams = plan_views([0.6, 0.06, 0.04], 2, distance=(0.6, 0.7))
    dist = [0.05, -0.02, 0.0, 0.0, 0.0]
    out = write_scan(tmp_path, objs, cams, default_K(), dist, seed=1, image_size=(320, 240))
    scan = json.loads((out / "scan.json").read_text())
    assert [v["dist"] for v in scan["views"]] == [dist, dist]
    assert cv2.imread(str(out / "view1.jpg")).shape == (240, 320, 3)
    truth = json.loads((out / "truth.json").read_text())
    assert [t["kind"] for t in truth["objects"]] == ["cup-stack", "lumpy"]


def test_standard_set():
    specs = standard_set(0)
    names = [s.name for s in specs]
    assert len(set(names)) == len(names)
    sq = [s for s in specs if s.objects[0].truth()["kind"] == "superquadric"]
    assert len(sq) >= 24
    assert len(specs) - len(sq) >= 2
    for family in FAMILIES:
        assert sum(s.name.startswith(family + "-") and s.name[len(family) + 1:].isdigit() for s in sq) == 6
    lying = [s for s in sq if abs(s.objects[0].T_world_object[2, 2]) < 1e-9]
    assert len(lying) >= 4
    for spec in specs:
        obj = spec.objects[0]
        if isinstance(obj, SuperquadricObject):
            assert np.all(2 * obj.size >= 0.03 - 1e-12) and np.all(2 * obj.size <= 0.15 + 1e-12)
        assert np.linalg.norm(spec.target[:2] - [0.6, 0.0]) <= 0.1
        for T in spec.cameras:
            off = T[:3, 3] - spec.target
            d = np.linalg.norm(off)
            assert 0.4 <= d <= 0.7, spec.name
            assert 35 <= np.degrees(np.arcsin(off[2] / d)) <= 55, spec.name
            uv, _ = project(obj.mesh()[0], T, spec.K)  # the whole object in view
            assert uv.min() >= 0 and uv[:, 0].max() <= 639 and uv[:, 1].max() <= 479, spec.name
    again = standard_set(0)
    for a, b in zip(specs, again):
        assert a.name == b.name and a.seed == b.seed
        np.testing.assert_array_equal(np.array(a.cameras), np.array(b.cameras))


# --- command line ------------------------------------------------------------


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="robocell sim")
    cli.add_arguments(parser)
    return parser.parse_args(argv)


def test_cli_writes_a_bundle(tmp_path: Path, capsys):
    args = _parse(["--out", str(tmp_path), "--shape", "box", "--size", "0.04", "0.03", "0.02",
                   "--yaw", "15", "--lying", "--views", "2", "--seed", "7", "--masks"])
    assert cli.run(args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1
    bundle = Path(lines[0])
    assert bundle.parent == tmp_path
    scan = json.loads((bundle / "scan.json").read_text())
    assert len(scan["views"]) == 2
    assert (bundle / "mask1.png").exists()
    truth = json.loads((bundle / "truth.json").read_text())
    np.testing.assert_allclose(truth["size"], [0.04, 0.03, 0.02])
    assert truth["T_world_object"][2][3] == pytest.approx(0.03)  # lying on a2


def test_cli_rejects_shape_options_without_shape(capsys):
    assert cli.run(_parse(["--yaw", "10"])) == 2
    assert "--shape" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        _parse(["--set", "standard", "--shape", "box"])


def test_broad_set():
    from robocell.workers.sim.scans import BROAD_FAMILIES, broad_set

    specs = broad_set(0, per_family=2)
    assert len(specs) == len(BROAD_FAMILIES) * 2 * 3
    assert {s.name.rsplit("-", 2)[0] for s in specs} == set(BROAD_FAMILIES)
    for spec in specs:
        obj = spec.objects[0]
        views = int(spec.name.rsplit("-", 1)[1][:-1])
        assert len(spec.cameras) == views in (3, 4, 6)
        assert 70 <= spec.jpeg_quality <= 95 and 1 <= spec.noise_sigma <= 4 and 0.15 <= spec.ambient <= 0.4
        full = 2 * obj.size
        family = spec.name.rsplit("-", 2)[0]
        if family == "flat-box":
            assert 0.016 <= full.min() <= 0.024, spec.name
        elif family == "plate":
            assert obj.size[0] == obj.size[1] and full[2] <= 0.02 and abs(obj.T_world_object[2, 2]) < 1e-9
        else:
            assert np.all(full >= 0.02 - 1e-12) and np.all(full <= 0.15 + 1e-12), spec.name
        for T in spec.cameras:
            off = T[:3, 3] - spec.target
            assert 20 - 2.5 <= np.degrees(np.arcsin(off[2] / np.linalg.norm(off))) <= 60 + 2.5, spec.name
    # One object, one look, three layouts of views.
    same = [s for s in specs if s.name.startswith("plate-01-")]
    assert len(same) == 3 and len({s.seed for s in same}) == 1 and len({s.jpeg_quality for s in same}) == 1
    assert same[0].objects[0] is same[2].objects[0]


def test_cli_writes_flat_boxes_plates_and_supplied_masks(tmp_path: Path, capsys):
    args = _parse(["--out", str(tmp_path), "--shape", "plate", "--views", "2", "--jpeg-quality", "75",
                   "--noise", "0", "--ambient", "0.2", "--supplied-masks"])
    assert cli.run(args) == 0
    bundle = Path(capsys.readouterr().out.split()[0])
    scan = json.loads((bundle / "scan.json").read_text())
    assert [v["mask"] for v in scan["views"]] == ["mask0.png", "mask1.png"]
    truth = json.loads((bundle / "truth.json").read_text())
    assert truth["shape"] == list(FAMILIES["cylinder"]) and truth["size"] == [0.06, 0.06, 0.008]
    assert truth["T_world_object"][2][3] == pytest.approx(0.06)  # standing on its rim
    assert cli.run(_parse(["--out", str(tmp_path), "--shape", "flat-box", "--ambient", "2"])) == 2
    assert "--ambient" in capsys.readouterr().err
