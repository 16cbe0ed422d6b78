"""The simulator's printed scenes: area-true edges, cast shadows, prints fixed on the object,
pictures of the empty workspace, and the printed set's bundles.

Every expected value is worked out here apart from the renderer: exact polygon areas by
clipping, shadows by marching from the table towards the lamp with the object's own inside test.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from robocell.wire.bundle import load_bundle
from robocell.workers.sim.objects import YCB_LIKE, SuperquadricObject, compound, rotation_z
from robocell.workers.sim.render import Light, TableScene, project, render, render_layers
from robocell.workers.sim.scans import (PRINTED_SCENES, PRODUCT_SET_LOOKS, PRODUCT_TABLES, default_K, look_at,
                                       printed_products_set, printed_set, write_scan)
from robocell.workers.sim.textures import TABLE_KINDS, PrintedObject, product_look

SIZE = (320, 240)
K = default_K(SIZE, f=300.0)
LIGHT = Light.from_angles(azimuth_deg=200.0, elevation_deg=40.0, strength=0.9, ambient=0.3)


class ExactBox:
    """A box with eight vertices: its projection is exactly the hull of its projected corners."""

    def __init__(self, half, centre, yaw_deg: float = 0.0) -> None:
        self.half, self.centre = np.asarray(half, float), np.asarray(centre, float)
        self.R = rotation_z(yaw_deg)

    def corners(self):
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        return (signs * self.half) @ self.R.T + self.centre

    def mesh(self):
        quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        faces = [f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))]
        return self.corners(), np.array(faces, np.int32)

    def inside(self, points):
        q = (np.asarray(points, float).reshape(-1, 3) - self.centre) @ self.R
        return (np.abs(q) <= self.half).all(axis=1)

    def truth(self):
        return {"kind": "box"}


def _oriented_outward(box: ExactBox) -> bool:
    v, f = box.mesh()
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return bool((np.einsum("ij,ij->i", n, v[f].mean(axis=1) - box.centre) > 0).all())


def _clip_area(polygon: np.ndarray, x0: float, y0: float) -> float:
    """Area of a convex polygon (N, 2) inside the unit square at (x0, y0) (Sutherland-Hodgman)."""
    pts = [tuple(p) for p in polygon]
    for axis, bound, keep_above in ((0, x0, True), (0, x0 + 1, False), (1, y0, True), (1, y0 + 1, False)):
        out = []
        for k in range(len(pts)):
            p, q = pts[k], pts[(k + 1) % len(pts)]
            p_in = (p[axis] >= bound) if keep_above else (p[axis] <= bound)
            q_in = (q[axis] >= bound) if keep_above else (q[axis] <= bound)
            if p_in:
                out.append(p)
            if p_in != q_in:
                t = (bound - p[axis]) / (q[axis] - p[axis])
                out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
        pts = out
        if not pts:
            return 0.0
    a = np.array(pts)
    return 0.5 * abs(np.dot(a[:, 0], np.roll(a[:, 1], -1)) - np.dot(a[:, 1], np.roll(a[:, 0], -1)))


def test_edges_are_area_true():
    box = ExactBox([0.04, 0.025, 0.03], [0.6, 0.02, 0.03], yaw_deg=27.0)
    assert _oriented_outward(box)
    T = look_at([0.33, -0.21, 0.37], [0.6, 0.0, 0.02])
    layers = render_layers(box, T, K, image_size=SIZE)
    uv, _ = project(box.corners(), T, K)
    hull = uv[ConvexHull(uv).vertices]  # counter-clockwise
    # Pixel (i, j) covers [j - 0.5, j + 0.5] x [i - 0.5, i + 0.5].
    exact = np.zeros(SIZE[::-1])
    lo, hi = np.floor(hull.min(0)).astype(int) - 1, np.ceil(hull.max(0)).astype(int) + 1
    for i in range(lo[1], hi[1] + 1):
        for j in range(lo[0], hi[0] + 1):
            exact[i, j] = _clip_area(hull, j - 0.5, i - 0.5)
    edge = (exact > 0) & (exact < 1)
    err = layers.coverage - exact
    nxt = np.roll(hull, -1, axis=0)
    area = 0.5 * abs((hull[:, 0] * nxt[:, 1] - hull[:, 1] * nxt[:, 0]).sum())
    assert exact.sum() == pytest.approx(area, rel=1e-9)  # the clipping itself is right
    assert edge.sum() > 150
    # Area-true: within a fraction of a pixel per edge pixel, with no bias outwards or inwards
    # (OpenCV's anti-aliased fill would be about a pixel outside all round).
    assert abs(err.sum()) < 0.02 * edge.sum()
    assert np.abs(err[edge]).mean() < 0.05
    assert np.abs(err).max() <= 0.3
    assert np.abs(err[~edge]).max() == 0  # inside is all object, outside none
    # The true mask is the coverage at one half.
    _, mask = render(box, T, K, image_size=SIZE, noise_sigma=0.0)
    np.testing.assert_array_equal(mask > 0, layers.coverage >= 0.5)
    assert abs((mask > 0).sum() - area) < 0.1 * edge.sum()


def _table_points(T, shape):
    """World points of the table z = 0 seen by each pixel (H, W, 3), computed apart from the renderer."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w]
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u, float)], -1) @ T[:3, :3].T
    s = -T[2, 3] / rays[..., 2]
    return T[:3, 3] + s[..., None] * rays


def test_shadow_falls_where_geometry_says():
    light = dataclasses.replace(LIGHT, angular_radius_deg=0.2)  # a sharp edge, to compare closely
    obj = SuperquadricObject.on_table("rounded-box", [0.03, 0.02, 0.05], (0.6, 0.0), 15.0)
    T = look_at([0.35, 0.2, 0.35], [0.6, 0.0, 0.03])
    table = TableScene.of_kind("laminate", 1)
    layers = render_layers(obj, T, K, image_size=SIZE, table=table, light=light)
    empty = render_layers([], T, K, image_size=SIZE, table=table, light=light)
    points = _table_points(T, SIZE[::-1])
    # Independent truth: march from each table point towards the lamp and ask the object.
    steps = np.linspace(1e-4, 0.25, 600)
    window = (np.abs(points[..., 0] - 0.6) < 0.25) & (np.abs(points[..., 1]) < 0.25) & (layers.coverage == 0)
    p = points[window]
    blocked = np.zeros(len(p), bool)
    for s in steps:
        blocked |= obj.inside(p + s * light.L)
    truth = np.zeros(SIZE[::-1], bool)
    truth[window] = blocked
    # Round the object's foot the ambient light is dimmer too (the object hides part of the sky):
    # compare the lamp's shadow farther out.
    foot = obj.mesh()[0]
    foot = foot[foot[:, 2] < 0.002, :2]
    gap = np.full(SIZE[::-1], np.inf)
    gap[window] = np.min(np.linalg.norm(p[:, None, :2] - foot[None], axis=2), axis=1)
    window &= gap > 0.03
    assert truth.sum() > 800  # a real shadow, not a speck
    said = layers.shadow > 0.5  # the lamp's share of the light here is about two thirds
    # Away from the soft edge (2 px of it), the renderer says exactly what the geometry says.
    edge = cv2.dilate(truth.astype(np.uint8), np.ones((5, 5))) != cv2.erode(truth.astype(np.uint8), np.ones((5, 5)))
    assert (said[window & ~edge] == truth[window & ~edge]).all()
    # And the shadow is the lamp's share missing: ambient over ambient plus the direct light.
    ratio = layers.image[truth & ~edge].sum(1) / empty.image[truth & ~edge].sum(1)
    expected = light.ambient / (light.ambient + light.strength * light.L[2])
    assert np.median(ratio) == pytest.approx(expected, rel=0.02)
    lit = window & ~truth & ~edge
    same = np.isclose(layers.image[lit], empty.image[lit], rtol=1e-5).all(axis=1)
    assert same.mean() > 0.9995  # a pixel or two at the far end of the soft edge
    assert (empty.shadow == 0).all()


def test_without_a_light_there_is_no_shadow_and_the_table_is_as_before():
    obj = SuperquadricObject.on_table("box", [0.03, 0.02, 0.05], (0.6, 0.0), 15.0)
    T = look_at([0.35, 0.2, 0.35], [0.6, 0.0, 0.03])
    table = TableScene.from_seed(3)
    layers = render_layers(obj, T, K, image_size=SIZE, table=table)
    assert (layers.shadow == 0).all()
    free = layers.coverage == 0
    np.testing.assert_array_equal(layers.image[free], table.background(T, K, None, SIZE)[free])


def _printed_box(T_world_object=None) -> PrintedObject:
    look = product_look("sugar-box", np.random.default_rng(4), 0.05)
    obj = SuperquadricObject.on_table("box", [0.045, 0.03, 0.05], (0.6, 0.01), 30.0)
    if T_world_object is not None:
        obj = SuperquadricObject(obj.size, obj.shape, T_world_object)
    return PrintedObject(obj, look)


def test_a_point_of_the_object_has_the_same_albedo_in_two_views():
    printed = _printed_box()
    # Both cameras see the side face turned towards -x (the box is turned 30 degrees) and the top.
    cams = [look_at([0.33, -0.12, 0.2], [0.6, 0.0, 0.04]), look_at([0.36, 0.12, 0.16], [0.6, 0.0, 0.04])]
    layers = [render_layers(printed, T, K, image_size=SIZE, light=LIGHT) for T in cams]
    v, f = printed.mesh()
    # A convex object: a face point is visible where its normal faces the camera.
    centres = v[f].mean(axis=1)
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    seen = np.ones(len(f), bool)
    samples = []
    for T, lay in zip(cams, layers):
        to_cam = T[:3, 3] - centres
        seen &= np.einsum("ij,ij->i", normals, to_cam) > 0.4 * np.linalg.norm(to_cam, axis=1)
        full = cv2.erode((lay.coverage == 1).astype(np.uint8), np.ones((3, 3))) > 0
        uv = np.rint(project(centres, T, K)[0]).astype(int)
        uv = np.clip(uv, 0, [SIZE[0] - 1, SIZE[1] - 1])
        seen &= full[uv[:, 1], uv[:, 0]]
        samples.append(lay.albedo[uv[:, 1], uv[:, 0]])
    a, b = samples[0][seen], samples[1][seen]
    assert seen.sum() > 100 and a.std(axis=0).max() > 0.1  # points on several colours of the print
    diff = np.abs(a - b).max(axis=1)
    assert np.median(diff) < 0.01
    assert (diff > 0.15).mean() < 0.15  # pixels on an edge of the print mix two colours


def test_the_print_moves_with_the_object():
    base = _printed_box()
    M = np.eye(4)
    M[:3, :3] = rotation_z(70.0)
    M[:3, 3] = [0.05, -0.08, 0.0]
    moved = _printed_box(M @ base.object.T_world_object)
    T = look_at([0.35, -0.2, 0.35], [0.6, 0.0, 0.04])
    a = render_layers(base, T, K, image_size=SIZE, light=LIGHT)
    b = render_layers(moved, M @ T, K, image_size=SIZE, light=LIGHT)
    full = (a.coverage == 1) & (b.coverage == 1)
    assert full.sum() > 1000
    diff = np.abs(a.albedo[full] - b.albedo[full]).max(axis=1)
    assert np.median(diff) < 1e-4 and (diff > 0.05).mean() < 0.01


def test_background_is_the_render_without_the_object_and_its_shadow():
    printed = _printed_box()
    T = look_at([0.55, 0.35, 0.35], [0.66, 0.0, 0.02])  # from the side the shadow falls to (+x)
    table = TableScene.of_kind("oak", 2)
    look = dict(image_size=SIZE, table=table, light=LIGHT, noise_sigma=2.0)
    layers = render_layers(printed, T, K, image_size=SIZE, table=table, light=LIGHT)
    scene, _ = render(printed, T, K, rng=np.random.default_rng(5), **look)
    empty, _ = render([], T, K, rng=np.random.default_rng(5), **look)
    touched = cv2.dilate(((layers.coverage > 0) | (layers.shadow > 0)).astype(np.uint8), np.ones((7, 7))) > 0
    np.testing.assert_array_equal(scene[~touched], empty[~touched])
    shadow = cv2.erode(((layers.shadow > 0.5) & (layers.coverage == 0)).astype(np.uint8), np.ones((7, 7))) > 0
    assert shadow.sum() > 200
    assert (scene[shadow].astype(int).sum(1) < 0.8 * empty[shadow].astype(int).sum(1)).mean() > 0.99


def test_light_must_shine_from_above():
    with pytest.raises(ValueError, match="above the table"):
        Light((1.0, 0.0, -0.2))
    with pytest.raises(ValueError, match="ambient"):
        Light(ambient=1.5)


@pytest.mark.parametrize("kind", TABLE_KINDS)
def test_table_kinds_are_textured_and_fixed_in_the_world(kind):
    table = TableScene.of_kind(kind, 0)
    xy = np.random.default_rng(0).uniform([0.4, -0.2], [0.8, 0.2], (2000, 2)).astype(np.float32)
    colour = table.table_colour(xy, np.full(len(xy), 5e-4, np.float32))
    assert colour.shape == (2000, 3) and np.isfinite(colour).all()
    assert colour.std(axis=0).max() > 1.0  # a texture, not a flat colour
    np.testing.assert_array_equal(colour, table.table_colour(xy, np.full(len(xy), 5e-4, np.float32)))
    with pytest.raises(ValueError, match="unknown table kind"):
        TableScene.of_kind("marble", 0)


def _grey_table(table: TableScene, T: np.ndarray, scale: int) -> tuple[np.ndarray, np.ndarray]:
    """The table's grey albedo as a 640x480 view sees it, rendered at ``scale`` times the resolution and
    averaged down, and where every sample of a pixel falls on the table."""
    w, h = 640, 480
    colours, on_table, _ = table.trace(T, default_K((w * scale, h * scale), 600.0 * scale), None,
                                       (w * scale, h * scale))
    grey = colours.mean(axis=1).reshape(h, scale, w, scale).mean(axis=(1, 3))
    return grey, on_table.reshape(h, scale, w, scale).all(axis=(1, 3))


def test_the_oak_s_growth_rings_are_averaged_over_a_pixel_low_over_the_table():
    """A camera's pixel averages the light that falls on it. Low over an oak board a pixel spans several of its
    growth rings (3.5-5.5 mm apart) along the depth; read at one point each, the rings alias into bands of
    moire that the board does not have, and that another view of the same boards sees elsewhere. The table
    as a view renders it agrees, at the scale of such bands, with the same view rendered at four times the
    resolution and averaged down, where the rings are resolved: the 99th percentile of the difference is 1.4
    grey levels (3.4 and 2.7 when the rings were read at one point; the boards' grey spreads by 12)."""
    for seed in (0, 1):
        table = TableScene.of_kind("oak", seed)
        azimuth = np.radians(40 * seed)
        # 0.65 m from the table's middle, 25 degrees over it.
        T = look_at([0.6 + 0.589 * np.cos(azimuth), 0.589 * np.sin(azimuth), 0.275], [0.6, 0.0, 0.0])
        seen, on_table = _grey_table(table, T, 1)
        resolved, resolved_on_table = _grey_table(table, T, 4)
        inside = cv2.erode((on_table & resolved_on_table).astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
        assert inside.mean() > 0.5 and resolved[inside].std() > 8  # a view of the boards, their grain seen
        bands = cv2.GaussianBlur((seen - resolved).astype(np.float32), (0, 0), 2.0)
        assert np.percentile(np.abs(bands[inside]), 99) < 2.0, seed


def test_printed_set_bundles_load_and_name_no_segmentation(tmp_path: Path):
    specs = printed_set(0)
    assert len({s.name for s in specs}) == len(specs) == len(PRINTED_SCENES)
    assert {s.table_kind for s in specs} == {*TABLE_KINDS, "wood", "fabric"}
    assert {"mustard", "sugar-box", "soup-can", "tin", "white", "dark", "table-colour"} <= {s.object_kind for s in specs}
    assert all(s.segmentation is None and s.light is not None for s in specs)
    assert [s.light.direction for s in specs] != [s.light.direction for s in printed_set(1)]
    spec = next(s for s in specs if s.object_kind == "white")
    path = spec.write(tmp_path)
    scan = json.loads((path / "scan.json").read_text())
    assert "segmentation" not in scan and scan["support_plane"] == [0, 0, 1, 0]
    assert all("mask" not in v and "background" not in v for v in scan["views"])
    bundle = load_bundle(path)
    assert len(bundle.views) == len(spec.cameras)
    for i, T in enumerate(spec.cameras):
        truth = cv2.imread(str(path / f"truth_mask{i}.png"), cv2.IMREAD_GRAYSCALE)
        _, mask = render(spec.objects, T, spec.K, image_size=spec.image_size, table=spec.table, light=spec.light)
        np.testing.assert_array_equal(truth, mask)
        assert 0.01 < (truth > 0).mean() < 0.5  # the object is in the picture, not the picture
    assert json.loads((path / "truth.json").read_text())["kind"] == "superquadric"


def test_backgrounds_are_written_and_named(tmp_path: Path):
    obj = SuperquadricObject.on_table("cylinder", [0.03, 0.03, 0.04], (0.6, 0.0))
    T = look_at([0.35, -0.2, 0.35], [0.6, 0.0, 0.04])
    path = write_scan(tmp_path / "b", obj, [T], K, seed=3, image_size=SIZE, light=LIGHT, segmentation=None,
                      backgrounds=True, truth_masks=True)
    scan = json.loads((path / "scan.json").read_text())
    assert scan["views"][0]["background"] == "background0.jpg"
    background = cv2.imread(str(path / "background0.jpg"))
    view = cv2.imread(str(path / "view0.jpg"))
    truth = cv2.imread(str(path / "truth_mask0.png"), cv2.IMREAD_GRAYSCALE) > 0
    assert background.shape == view.shape
    grey = lambda im: im.astype(float).mean(axis=2)  # noqa: E731
    far = cv2.erode((~truth).astype(np.uint8), np.ones((61, 61))) > 0
    assert np.abs(grey(view) - grey(background))[far].mean() < 3  # the same table, other noise
    assert np.abs(grey(view) - grey(background))[truth].mean() > 20  # no object in the background


def test_the_cell_camera_photographs_a_printed_object_and_the_empty_workspace():
    from robocell.wire.config import SimConfig
    from robocell.workers.sim import scene
    from robocell.workers.sim.camera import SceneCamera

    objects = scene.scene_from_config(SimConfig())  # printed by default
    assert isinstance(objects[0], PrintedObject) and objects[0].look.name == "sugar-box"
    table, light = scene.surroundings(objects, 0)
    assert table.kind == "oak" and light is not None
    camera = SceneCamera(objects, K=K, image_size=SIZE)
    T = look_at([0.35, -0.2, 0.35], scene.target_from_config(SimConfig()))
    decode = lambda data: cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR).astype(float)  # noqa: E731
    with_object, empty = decode(camera.jpeg(T)), decode(camera.jpeg(T, empty=True))
    _, truth = render(objects, T, K, image_size=SIZE, table=table, light=light)
    layers = render_layers(objects, T, K, image_size=SIZE, table=table, light=light)
    near = cv2.dilate(((layers.coverage > 0) | (layers.shadow > 0)).astype(np.uint8), np.ones((9, 9))) > 0
    changed = np.abs(with_object - empty).mean(axis=2) > 25
    assert changed[truth > 0].mean() > 0.5 and changed[~near].mean() < 0.001
    camera.object_present = False
    assert np.abs(decode(camera.jpeg(T)) - empty).mean(axis=2)[truth > 0].mean() < 5


def test_printed_products_set_puts_each_product_in_parts_on_many_tables_and_in_many_looks(tmp_path: Path):
    specs = printed_products_set(0)
    assert [s.object_kind for s in specs] == list(YCB_LIKE)
    assert {s.table_kind for s in specs} == set(PRODUCT_TABLES) == {*TABLE_KINDS, "wood", "fabric"}
    for s in specs:
        table, product = s.table_kind, s.object_kind
        assert s.name.startswith(f"{table}-") and s.name.endswith(f"-{product}")
        assert s.name[len(table) + 1:-len(product) - 1] in PRODUCT_SET_LOOKS
        assert s.segmentation is None and s.light is not None and s.truth_masks and len(s.cameras) == 3
    # Three seeds put each product on three tables and in three looks; the lamp moves with the seed.
    met: dict[str, set] = {}
    for seed in range(3):
        for s in printed_products_set(seed):
            met.setdefault(s.object_kind, set()).add(s.name.removesuffix(f"-{s.object_kind}"))
    assert all(len({name.split("-")[0] for name in names}) == 3 and len(names) == 3 for names in met.values())
    assert [s.light.direction for s in specs] != [s.light.direction for s in printed_products_set(1)]
    mug = next(s for s in specs if s.object_kind == "ycb-mug")
    path = mug.write(tmp_path)
    scan = json.loads((path / "scan.json").read_text())
    assert "segmentation" not in scan and scan["support_plane"] == [0, 0, 1, 0]
    truth = json.loads((path / "truth.json").read_text())
    assert len(truth["parts"]) == len(compound("ycb-mug", (0.6, 0.0)).truth()["parts"]) > 1
    for i in range(3):
        mask = cv2.imread(str(path / f"truth_mask{i}.png"), cv2.IMREAD_GRAYSCALE) > 0
        # The whole mug in every view: none of it on the image's border.
        assert mask.sum() > 2000 and not (mask[[0, -1]].any() or mask[:, [0, -1]].any())


def test_cli_writes_backgrounds_and_knows_the_printed_set(tmp_path: Path, capsys):
    import argparse

    from robocell.cli import sim as cli

    parser = argparse.ArgumentParser(prog="robocell sim scans")
    cli.add_arguments(parser)
    assert parser.parse_args(["--set", "printed"]).set_name == "printed"
    assert parser.parse_args(["--set", "printed-products"]).set_name == "printed-products"
    args = parser.parse_args(["--out", str(tmp_path), "--shape", "cylinder", "--views", "1", "--backgrounds"])
    assert cli.run(args) == 0
    bundle = Path(capsys.readouterr().out.split()[0])
    scan = json.loads((bundle / "scan.json").read_text())
    assert scan["views"][0]["background"] == "background0.jpg"
    assert cv2.imread(str(bundle / "background0.jpg")).shape == (480, 640, 3)
