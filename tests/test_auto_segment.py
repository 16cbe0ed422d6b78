"""The ``auto`` segmentation (DESIGN.md §1.10), scored against the true silhouettes of scenes
ray-traced apart from it (tests/seg_scenes.py): textures, a cast shadow, area-true edges, blur,
noise, JPEG."""

import json
from pathlib import Path
import subprocess
import sys

import cv2
import numpy as np
import pytest

from robocell.core_cy import auto_segment
from robocell.core_cy.auto_segment import aim_point, auto_silhouettes
from robocell.core_cy.camera import Camera
from robocell.core_cy.errors import GeometryError, ImageError, SilhouetteError
from robocell.core_cy.quality import silhouette_iou
from robocell.core_cy.reconstruct import View, reconstruct
from robocell.core_cy.plan import look_at
from tests.seg_scenes import Scene, render_scan, render_view
from robocell.wire.bundle import load_bundle
from robocell.wire.errors import BundleError

TABLE = [0.0, 0.0, 1.0, 0.0]

SCENES = {
    "red box on a beige table": Scene(),
    "printed can on wood": Scene(shape="cylinder", size=(0.035, 0.035, 0.06), object_print="label",
                                 table_texture="wood", yaw=1.0),
    "white box on a dark mat": Scene(object_bgr=(230, 230, 230), table_bgr=(30, 32, 35), light=(-0.4, 0.5, 0.8)),
    # Dino- and temple-like: a bright object on a dark, uniform ground.
    "white can on black": Scene(shape="cylinder", size=(0.03, 0.03, 0.05), object_bgr=(225, 230, 235),
                                table_bgr=(12, 12, 12), light=(0.2, 0.3, 0.9), ambient=0.6),
}


def robocell(*args):
    return subprocess.run([sys.executable, "-m", "robocell", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a > 0, b > 0
    return float((a & b).sum() / max(1, (a | b).sum()))


@pytest.fixture(scope="module")
def scans():
    return {name: render_scan(scene, seed=number) for number, (name, scene) in enumerate(SCENES.items())}


def _cameras(cams):
    return [Camera(K=K, T_world_cam=T, view=index) for index, (K, T) in enumerate(cams)]


@pytest.mark.parametrize("name, plane", [(name, TABLE) for name in SCENES] + [
    # Without a plane the aim alone seeds the cut: a one-coloured object is found whole.
    ("red box on a beige table", None), ("white can on black", None)])
def test_silhouettes_against_the_truth(scans, name, plane):
    images, truths, cams = scans[name]
    found = auto_silhouettes(images, _cameras(cams), support_plane=plane)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert min(ious) > 0.9, ious
    for silhouette, outline in found:  # one filled region, 0/255, its outline on it
        assert set(np.unique(silhouette)) == {0, 255}
        assert silhouette[outline[:, 1], outline[:, 0]].all()


def _own_exposures(images):
    """Each of three pictures with its own exposure, tint and a gradient of a quarter across it, in its own
    direction."""
    height, width = images[0].shape[:2]
    ys, xs = np.mgrid[0:height, 0:width]
    gains = [(0.8, (1.0, 0.95, 1.05), xs / width), (1.15, (1.05, 1.0, 0.92), ys / height),
             (1.0, (0.95, 1.05, 1.0), 1.0 - (xs + ys) / (width + height))]
    return [np.clip(image * (exposure * (0.85 + 0.3 * ramp))[..., None] * np.array(tint), 0, 255).astype(np.uint8)
            for image, (exposure, tint, ramp) in zip(images, gains)]


def test_each_camera_s_own_exposure_white_balance_and_shading(scans):
    # A real camera sets its own exposure and white balance per picture, and a ground may be shaded in
    # the picture rather than on the table (as the shared contract check's renderer does): the table
    # then differs from view to view by a smooth gain, which is no parallax. Here each view gets its own
    # exposure, tint and a gradient of a quarter across the picture, in its own direction.
    images, truths, cams = scans["red box on a beige table"]
    found = auto_silhouettes(_own_exposures(images), _cameras(cams), support_plane=TABLE)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert min(ious) > 0.9, ious


#: Objects near the camera, filling over a tenth of each picture, on textured tables (with the seed of the
#: scan that lost them): the fit of each view's light (_even_the_light) took their parallax for light.
NEAR_OBJECTS = {
    "a mint box on a grey grid mat": (Scene(size=(0.026, 0.04, 0.062), yaw=0.76, object_bgr=(100, 210, 175),
                                            table_bgr=(100, 98, 96), table_texture="grid", light=(0.2, 0.7, 0.67),
                                            ambient=0.4), 1),
    "a cream wooden box on a red wooden table": (Scene(size=(0.055, 0.044, 0.04), yaw=1.49,
                                                       object_bgr=(182, 173, 151), object_print="wood",
                                                       table_bgr=(229, 115, 120), table_texture="wood",
                                                       light=(-0.57, 0.13, 0.8), ambient=0.4), 2),
}


@pytest.mark.parametrize("name", NEAR_OBJECTS)
def test_an_object_near_the_camera_is_no_light(name):
    # Near the camera an object and its parallax come near half of the table that two views share. The
    # light was even here, but the fit of each view's light field took the object's parallax in, fitted
    # fields of up to e^+-0.9, and divided the pictures by them: 0.695 and 0.659 (the mint box's views
    # 1 and 2), 0.735 and 0.617 (the wooden box's 0 and 2) before.
    scene, seed = NEAR_OBJECTS[name]
    images, truths, cams = render_scan(scene, seed=seed)
    assert min(np.mean(truth > 0) for truth in truths) > 0.1  # the object is near: over a tenth of each view
    found = auto_silhouettes(images, _cameras(cams), support_plane=TABLE)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert min(ious) > 0.9, ious


def test_an_object_near_the_camera_with_each_camera_s_own_exposure():
    # The light's fit still evens each camera's own exposure, tint and gradient out where the object is near.
    scene, seed = NEAR_OBJECTS["a mint box on a grey grid mat"]
    images, truths, cams = render_scan(scene, seed=seed)
    found = auto_silhouettes(_own_exposures(images), _cameras(cams), support_plane=TABLE)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert min(ious) > 0.9, ious


@pytest.mark.parametrize("seed", [0, 2, 4])
def test_a_tall_object_near_low_views_keeps_its_top_whose_table_points_no_other_view_sees(seed):
    # Seen from 15-30 degrees up and near, the ray past a tall box's top meets the table far behind it, out of
    # every other view's picture: nothing confirms the table there. It was taken for table that the others
    # confirm, and, dark, for their confirmed shadow: the graph cut was told it was table for sure and the
    # dark box lost its upper half (0.57 to 0.83 before).
    scene = Scene(size=(0.048, 0.026, 0.063), position=(-0.014, 0.015), yaw=2.62, object_bgr=(38, 36, 38),
                  table_bgr=(89, 87, 95), light=(-0.03, 0.78, 0.63), ambient=0.48, noise=2.9)
    images, truths, cams = render_scan(scene, seed=seed, size=(640, 480), elevations=(15.0, 30.0))
    found = auto_silhouettes(images, _cameras(cams), support_plane=TABLE)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert min(ious) > 0.9, ious


def test_views_aimed_under_the_table_find_the_object():
    # An arm may aim its views at where a flat object meets the table, or a little under it: the views'
    # aim is then below the table, and the object is found all the same (it once raised "under the table").
    scene = Scene(size=(0.04, 0.03, 0.012))
    _, _, cams = render_scan(scene, seed=5)
    K = cams[0][0]
    images, truths, poses = [], [], []
    for index, (_, T) in enumerate(cams):
        below = look_at(T[:3, 3], [scene.centre[0], scene.centre[1], -0.02])
        image, truth = render_view(scene, below, K, (320, 240), 500 + index)
        images.append(image)
        truths.append(truth)
        poses.append((K, below))
    cameras = _cameras(poses)
    assert aim_point(cameras)[2] < 0.0
    found = auto_silhouettes(images, cameras, support_plane=TABLE)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert min(ious) > 0.85, ious
    # The plane's side is told by the cameras, which look down on the table: upside down, it is refused.
    with pytest.raises(GeometryError, match="under the table"):
        auto_silhouettes(images, cameras, support_plane=[0.0, 0.0, -1.0, 0.0])


@pytest.mark.parametrize("layout", [2, 14])
def test_a_flat_box_seen_by_six_views_is_found_in_every_view(layout):
    # A flat box's top, 2.4 cm above the table and of one colour, stands out through the plane only along
    # its outline, and with six views all round the other views' agreement leaves a corner of it in some
    # views on the first look; a view is looked at again while the others' silhouettes grow (the classic
    # red scene of workers/sim, a renderer apart from the one the other tests here use). Before: views
    # of 0.05 to 0.13 here (layout 2). Layout 14: every view's first look holds only the top's corners
    # (views of 0.00 to 0.09 before); the corners' own colour joins the rest of the top in what hides
    # the table points from the other views.
    from robocell.workers.sim.objects import SuperquadricObject
    from robocell.workers.sim.render import render
    from robocell.workers.sim.scans import default_K, plan_views

    rng = np.random.default_rng(layout)
    box = SuperquadricObject.on_table((0.2, 0.2), [0.06, 0.04, 0.012], (0.6, 0.0))
    poses = plan_views([0.6, 0.0, 0.0], 6, distance=(0.45, 0.65), elevation_deg=(30, 65), rng=rng,
                       azimuth_start_deg=rng.uniform(0, 360))
    K = default_K()
    rendered = [render(box, T, K, rng=np.random.default_rng(100 + i)) for i, T in enumerate(poses)]
    found = auto_silhouettes([image for image, _ in rendered], [Camera(K, T) for T in poses],
                             support_plane=TABLE)
    ious = [_iou(silhouette, truth) for (silhouette, _), (_, truth) in zip(found, rendered)]
    assert min(ious) > 0.95, ious


@pytest.mark.xfail(reason="a flat object top of exactly the table's colour and light has no cue at the coarse "
                          "scale: its sides are found, its top is not (a known limit)", strict=False)
def test_an_object_the_colour_of_the_table():
    scene = Scene(shape="cylinder", size=(0.035, 0.035, 0.05), object_bgr=(150, 170, 190), table_texture="grid")
    images, truths, cams = render_scan(scene, seed=5)
    found = auto_silhouettes(images, _cameras(cams), support_plane=TABLE)
    assert min(_iou(s, t) for (s, _), t in zip(found, truths)) > 0.85


def test_a_dark_face_of_the_table_s_colour_beside_its_shadow():
    """A box of the table's colour, lit from one side: its dark faces are of the colour of its shadow, which
    the other views see on the table through the plane exactly where the face stands. Only the grain tells
    them apart (the table's, kept in its shadow; the box's own on its face), dark as both are."""
    scene = Scene(size=(0.035, 0.03, 0.035), object_bgr=(110, 150, 190), object_print="wood",
                  table_bgr=(110, 150, 190), table_texture="wood", light=(0.6, -0.2, 0.6))
    images, truths, cams = render_scan(scene, seed=0, size=(640, 480))
    found = auto_silhouettes(images, _cameras(cams), support_plane=TABLE)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert np.mean(ious) > 0.85 and min(ious) > 0.78, ious


def test_a_background_picture_is_used(scans):
    scene = SCENES["printed can on wood"]
    images, truths, cams = scans["printed can on wood"]
    empty, _, _ = render_scan(Scene(**{**scene.__dict__, "with_object": False}), seed=1)
    found = auto_silhouettes(images, _cameras(cams), support_plane=TABLE, backgrounds=empty)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert np.mean(ious) > 0.95 and min(ious) > 0.93, ious


def test_a_shadow_alone_is_no_object():
    """The object is out of the pictures (held above them, say) and only its shadow is on the table."""
    images, _, cams = render_scan(Scene(shadow_only=True), seed=3)
    with pytest.raises(SilhouetteError, match=r"^view \d: nothing stands on the table near the views' aim"):
        auto_silhouettes(images, _cameras(cams), support_plane=TABLE)


def test_an_empty_table_names_the_view():
    empty, _, cams = render_scan(Scene(with_object=False), seed=0)
    with pytest.raises(SilhouetteError, match="^view 0: nothing stands on the table near the views' aim"):
        auto_silhouettes(empty, _cameras(cams), support_plane=TABLE)


def _views_with_backgrounds(scene, images, cams, seed):
    empty = Scene(**{**scene.__dict__, "with_object": False})
    size = images[0].shape[1::-1]
    return [View(camera, image=image, background=render_view(empty, camera.T_world_cam, camera.K, size,
                                                             seed * 100 + 50 + index)[0])
            for index, (camera, image) in enumerate(zip(_cameras(cams), images))]


def test_backgrounds_whose_silhouettes_fail_the_reconstruction_are_set_aside():
    # A box of its table's colour and light, seen from 60-80 degrees up with the empty workspace: its top does
    # not change against the table, and the silhouettes cut against the empty workspace put the object under
    # the table. From the images alone they are found (the plane's parallax of its sides and of the shadow
    # behind its top), and the result says why the backgrounds were set aside.
    scene = Scene(size=(0.045, 0.032, 0.036), position=(-0.01, 0.009), yaw=0.31, object_bgr=(169, 164, 196),
                  table_bgr=(172, 169, 202), light=(0.22, 0.40, 0.89), ambient=0.3, noise=2.5)
    images, truths, cams = render_scan(scene, seed=0, size=(640, 480), elevations=(60.0, 80.0))
    result = reconstruct(_views_with_backgrounds(scene, images, cams, 0), support_plane=TABLE)
    assert result.backgrounds_set_aside.startswith("the support plane puts the object under the table")
    assert result.to_dict()["backgrounds_set_aside"] == result.backgrounds_set_aside
    assert result.timings_ms["total"] > result.timings_ms["with_backgrounds"] > 0
    ious = [_iou(silhouette, truth) for silhouette, truth in zip(result.silhouettes, truths)]
    assert min(ious) > 0.9, ious


def test_backgrounds_are_not_set_aside_for_a_shadow_alone():
    # Found from the images alone, a shadow is no object either: the first error stands, naming the view.
    scene = Scene(shadow_only=True)
    images, _, cams = render_scan(scene, seed=3)
    with pytest.raises(SilhouetteError, match=r"^view \d: nothing stands on the table near the views' aim"):
        reconstruct(_views_with_backgrounds(scene, images, cams, 3), support_plane=TABLE)


def test_a_reconstruction_that_uses_its_backgrounds_says_none_was_set_aside(scans):
    images, truths, cams = scans["printed can on wood"]
    scene = SCENES["printed can on wood"]
    result = reconstruct(_views_with_backgrounds(scene, images, cams, 1), support_plane=TABLE)
    assert result.backgrounds_set_aside is None and "backgrounds_set_aside" not in result.to_dict()
    assert min(_iou(silhouette, truth) for silhouette, truth in zip(result.silhouettes, truths)) > 0.9


@pytest.mark.parametrize("name", ["printed can on wood", "white box on a dark mat"])
def test_backgrounds_taken_with_another_exposure_and_white_balance(scans, name):
    # A camera sets its exposure and white balance anew for each picture, and the object changes what it
    # meters: each view's empty workspace here is 0.8, 1.2 to 1.4 or 0.9 to 1.1 times as bright per channel as
    # its picture's table. Compared as it was, the whole table changed (the can's worst view 0.92, the white
    # box's 0.85 before); each background is brought to its picture's gain first.
    images, truths, cams = scans[name]
    gains = [(0.8, 0.8, 0.8), (1.25 * 1.1, 1.25, 1.25 * 0.9), (0.9, 1.0, 1.1)]
    empty = Scene(**{**SCENES[name].__dict__, "with_object": False})
    seed = list(SCENES).index(name)
    backgrounds = [np.clip(render_view(empty, T, K, (320, 240), seed * 100 + 50 + i)[0] * np.array(gain), 0, 255)
                   .astype(np.uint8) for i, ((K, T), gain) in enumerate(zip(cams, gains))]
    found = auto_silhouettes(images, _cameras(cams), support_plane=TABLE, backgrounds=backgrounds)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert min(ious) > 0.95, ious


def test_a_background_of_another_size_names_the_view(scans):
    images, _, cams = scans["red box on a beige table"]
    backgrounds = [None, np.zeros((10, 10, 3), np.uint8), None]
    with pytest.raises(ImageError, match="^view 1: the background is 10x10 pixels, but its image is 320x240"):
        auto_silhouettes(images, _cameras(cams), support_plane=TABLE, backgrounds=backgrounds)


def test_parallel_axes_converge_nowhere():
    T = np.eye(4)
    shifted = np.eye(4)
    shifted[0, 3] = 0.1
    K = [[300, 0, 159.5], [0, 300, 119.5], [0, 0, 1]]
    with pytest.raises(GeometryError, match="parallel"):
        aim_point([Camera(K=K, T_world_cam=T), Camera(K=K, T_world_cam=shifted)])


def _write_bundle(directory, images, cams, *, backgrounds=None, plane=TABLE):
    directory.mkdir(parents=True)
    views = []
    for index, (image, (K, T)) in enumerate(zip(images, cams)):
        cv2.imwrite(str(directory / f"view{index}.jpg"), image, [cv2.IMWRITE_JPEG_QUALITY, 95])
        view = {"image": f"view{index}.jpg", "K": np.asarray(K).tolist(), "T_world_cam": np.asarray(T).tolist()}
        if backgrounds is not None:
            cv2.imwrite(str(directory / f"bg{index}.jpg"), backgrounds[index], [cv2.IMWRITE_JPEG_QUALITY, 95])
            view["background"] = f"bg{index}.jpg"
        views.append(view)
    scan = {"views": views}
    if plane is not None:
        scan["support_plane"] = plane
    (directory / "scan.json").write_text(json.dumps(scan))
    return directory


def test_masks_out_are_what_the_fit_used(tmp_path, scans):
    images, truths, cams = scans["printed can on wood"]
    bundle = _write_bundle(tmp_path / "can", images, cams)
    process = robocell("reconstruct", bundle, "--masks-out", tmp_path / "masks")
    assert process.returncode == 0, process.stderr
    line = json.loads(process.stdout.splitlines()[0])
    masks = [cv2.imread(str(tmp_path / "masks" / "can" / f"mask{i}.png"), cv2.IMREAD_GRAYSCALE) for i in range(3)]
    from robocell.core_cy.superquadric import Superquadric

    fitted = Superquadric.from_dict(line["superquadric"])
    for camera, mask, reported, truth in zip(_cameras(cams), masks, line["silhouette_iou"], truths):
        assert set(np.unique(mask)) == {0, 255}
        assert silhouette_iou(fitted, camera, mask, cv2.boundingRect(mask)) == pytest.approx(reported, abs=2e-4)
        assert _iou(mask, truth) > 0.9


def test_a_bundle_background_is_read_and_checked(tmp_path, scans):
    scene = SCENES["red box on a beige table"]
    images, truths, cams = scans["red box on a beige table"]
    empty, _, _ = render_scan(Scene(**{**scene.__dict__, "with_object": False}), seed=0)
    bundle = _write_bundle(tmp_path / "box", images, cams, backgrounds=empty)
    loaded = load_bundle(bundle)
    assert all(view.background is not None for view in loaded.views)
    result = reconstruct(loaded.views, segmentation=loaded.segmentation, support_plane=loaded.support_plane)
    assert min(_iou(s, t) for s, t in zip(result.silhouettes, truths)) > 0.93

    cv2.imwrite(str(bundle / "bg1.jpg"), cv2.resize(empty[1], (304, 228)))  # near enough for K, not its image
    with pytest.raises(BundleError, match="^view 1: background file 'bg1.jpg' is 304x228 pixels, but its image"):
        load_bundle(bundle)
    (bundle / "bg1.jpg").unlink()
    with pytest.raises(BundleError, match="^view 1: background file 'bg1.jpg' not found"):
        load_bundle(bundle)


def test_reconstruct_defaults_to_auto(scans):
    images, truths, cams = scans["white box on a dark mat"]
    views = [View(camera, image=cv2.imencode(".jpg", image)[1].tobytes())
             for camera, image in zip(_cameras(cams), images)]
    result = reconstruct(views, support_plane=TABLE)
    assert min(_iou(s, t) for s, t in zip(result.silhouettes, truths)) > 0.9


def test_a_background_keeps_what_only_looks_like_a_shadow(printed_scene):
    """A yellow bottle, a white-and-blue box and a white box on white laminate under one lamp (the
    simulator's printed scenes): their faces turned from the lamp are darker than the empty laminate with
    about its chromaticity, as a shadow is. Another view that sees the same table point unhidden does not
    see it darkened alike, so they stand above the table and are kept; the cast shadow is left out."""
    for name, least in (("laminate-mustard-bottle", 0.95), ("laminate-sugar-box-tall-box", 0.88),
                        ("laminate-white-box", 0.78)):
        ious = _printed_scene_ious(printed_scene, 0, name, backgrounds=True)
        assert np.mean(ious) > least, (name, ious)


def test_a_background_does_not_take_a_top_that_two_views_see_over_one_table_point_for_a_shadow():
    # From 60-80 degrees up, two views see a box's top in front of the same table points. A dark teal top on a
    # blue mat changes against the empty mat alike in both, as a shadow there would, and each view that had
    # lost its top took the other's for that confirmation (0.89, 0.87 and 0.65 before). It is darker than the
    # mat, but its colour changed, which a shadow's does not: no other view's likeness makes it a shadow.
    scene = Scene(size=(0.058, 0.022, 0.036), yaw=2.22, object_bgr=(86, 59, 19), table_bgr=(175, 116, 93),
                  table_texture="grid", light=(0.24, 0.77, 0.59), ambient=0.38, noise=3.0)
    # 1.5 times as far as render_scan's own distance at this size: the box fills about 3 % of each picture.
    distance = 1.53 * float(np.linalg.norm(scene.size)) / np.sin(np.arctan(0.8 * 240 / 600) - np.radians(2.0))
    images, truths, cams = render_scan(scene, seed=5, size=(640, 480), distance=distance, elevations=(60.0, 80.0))
    empty = Scene(**{**scene.__dict__, "with_object": False})
    backgrounds = [render_view(empty, T, K, (640, 480), 550 + i)[0] for i, (K, T) in enumerate(cams)]
    found = auto_silhouettes(images, _cameras(cams), support_plane=TABLE, backgrounds=backgrounds)
    ious = [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]
    assert min(ious) > 0.9, ious


def _printed_scene_ious(printed_scene, seed, name, *, backgrounds, jpeg_again=None):
    """Silhouette IoU per view of one of the simulator's printed scenes (``printed_set(seed)``, its true masks
    rendered with it; the ``printed_scene`` fixture), segmented by ``auto`` from its images alone or with its
    empty workspace's; with ``jpeg_again``, its images compressed once more at that JPEG quality."""
    _, directory = printed_scene(seed, name)
    bundle = load_bundle(directory)
    images = [cv2.imdecode(np.frombuffer(view.image, np.uint8), cv2.IMREAD_COLOR) for view in bundle.views]
    if jpeg_again is not None:
        images = [cv2.imdecode(cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, jpeg_again])[1], cv2.IMREAD_COLOR)
                  for image in images]
    empty = [cv2.imdecode(np.frombuffer(view.background, np.uint8), cv2.IMREAD_COLOR)
             for view in bundle.views] if backgrounds else None
    truths = [cv2.imread(str(directory / f"truth_mask{i}.png"), cv2.IMREAD_GRAYSCALE)
              for i in range(len(images))]
    found = auto_silhouettes(images, [view.camera for view in bundle.views], support_plane=bundle.support_plane,
                             backgrounds=empty)
    return [_iou(mask, truth) for (mask, _), truth in zip(found, truths)]


def _jpeg_scene_ious(scene, seed):
    """Silhouette IoU per view of a scene of tests/seg_scenes.py, three 640x480 views as JPEG (quality 92),
    segmented by ``auto`` with the table's plane."""
    images, truths, cams = render_scan(scene, size=(640, 480), seed=seed)
    images = [cv2.imdecode(cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 92])[1], cv2.IMREAD_COLOR)
              for image in images]
    found = auto_silhouettes(images, _cameras(cams), support_plane=TABLE)
    return [_iou(silhouette, truth) for (silhouette, _), truth in zip(found, truths)]


def test_a_view_that_misses_what_the_others_agree_on_is_cut_again(printed_scene):
    """A dark can on a dark rubber mat: from one view its top is of the mat's colour and light, and the
    other views see the mat there through the plane, so that view's own evidence leaves the top out (0.57
    before). The two others agree on the can; without that view none of them reaches out of the others'
    hull, with it they do: it holds too little, and is cut again with the others' hull added to its own."""
    ious = _printed_scene_ious(printed_scene, 2, "rubber-mat-dark-can", backgrounds=False)
    assert min(ious) > 0.88, ious


def test_the_table_under_a_lying_can_is_table_where_the_can_has_none_of_its_colour(printed_scene):
    """A blue-and-yellow tin lying on wood: the strip of table under its belly, which the tin hides from every
    other view and from the sky, is darker than any shadow in the open, but was seeded only probably table,
    and the colour models, holding the tin's blue side in shade, kept it (views 0.857 and 0.854 before). Where
    the view surely sees the tin it has none of the wood's colour, so no face of it looks like the strip:
    table for sure."""
    ious = _printed_scene_ious(printed_scene, 17, "wood-tin-lying-can", backgrounds=False)
    assert min(ious) > 0.95, ious


def test_an_object_has_none_of_the_table_s_colour_while_under_a_fiftieth_of_it_has_it_lit_or_in_shade():
    oak = np.array([90.0, 140.0, 190.0])  # BGR
    tin = np.tile([[40.0, 40.0, 200.0], [30.0, 160.0, 220.0], [200.0, 80.0, 40.0]], (100, 1))  # red, yellow, blue
    # The oak's colour as it is, in shade (half as bright) and lit (a third brighter): each passes for it.
    oak_like = np.array([oak, oak / 2, oak * 1.3])

    def none_of_it(pixels, seen=None):
        seen = np.ones((len(pixels), 1), bool) if seen is None else seen
        return auto_segment._none_of_the_table_s_colour(pixels[:, None, :], oak, seen)

    assert none_of_it(tin)
    assert none_of_it(np.vstack([tin, oak_like]))  # 3 of 303
    assert not none_of_it(np.vstack([tin[:294], oak_like, oak_like]))  # 6 of 300: a fiftieth
    assert not none_of_it(tin, seen=np.zeros((300, 1), bool))  # nothing surely seen: nothing said


def test_the_shadow_in_the_bend_of_an_object_in_parts_is_not_taken_for_a_face_it_missed(tmp_path):
    """A white hammer lying on wood (``printed_products_set(1)``): its handle's shadow falls in the bend between
    handle and head, within the silhouette's convex outline and within the other views' hull, which holds the
    space under the raised handle: where a box's lost top would leave a bay. The bay was cut again and the
    shadow taken (views 0.864 and 0.811 before). The hammer has none of the wood's colour, so the shadow the
    other views confirm there, or that looks like it hidden from them, is no face of it."""
    from robocell.workers.sim.scans import printed_products_set

    spec = {spec.name: spec for spec in printed_products_set(1)}["wood-white-ycb-hammer"]
    written = spec, spec.write(tmp_path, backgrounds=True)
    ious = _printed_scene_ious(lambda seed, name: written, 1, spec.name, backgrounds=False)
    assert min(ious) > 0.93, ious


def test_the_table_seen_through_a_gap_in_the_object_is_table_where_it_keeps_the_grain(tmp_path):
    """A drill standing on wood, with the empty workspace (``printed_products_set(2)``): the table lit between
    its barrel and its battery lies within the other views' hull, which holds the space under the barrel, and
    the colour models gave it to the drill (views 0.856 and 0.858 before). It keeps the empty workspace's
    grain as the table round it does, which a face, even one of the table's colour, hides."""
    from robocell.workers.sim.scans import printed_products_set

    spec = {spec.name: spec for spec in printed_products_set(2)}["wood-printed-power-drill"]
    written = spec, spec.write(tmp_path, backgrounds=True)
    ious = _printed_scene_ious(lambda seed, name: written, 2, spec.name, backgrounds=True)
    assert min(ious) > 0.95, ious


def test_a_band_of_the_table_s_look_below_a_dark_label_is_kept(tmp_path):
    """A soup can on white laminate, no empty workspace (``printed_products_set(10)``): below its red label a
    white band, lit as the laminate and of its colour, goes on down to the foot. Below a side turned from the
    lamp nothing of the object is lit as the table, and the band, hidden from the other views by the can, was
    dropped as the table before the foot (view 1 0.744 before). But the label is darker than the table by its
    print, not its light, and the can wears the laminate's look elsewhere (its white top): the side above the
    band is no shade of the laminate's colour."""
    from robocell.workers.sim.scans import printed_products_set

    spec = {spec.name: spec for spec in printed_products_set(10)}["laminate-soup-can-soup-can"]
    written = spec, spec.write(tmp_path)
    ious = _printed_scene_ious(lambda seed, name: written, 10, spec.name, backgrounds=False)
    assert min(ious) > 0.92, ious


def test_a_shadow_that_no_other_view_sees_is_table_where_it_keeps_the_grain(printed_scene):
    """The strip of shadow under a lying can on a cutting mat: the can hides it from every other view, so
    no view can confirm it as a shadow on the table, and it was taken for the can's foot (0.84 before).
    Against the empty workspace it is darker, of the mat's colour, and keeps the mat's grid: table."""
    ious = _printed_scene_ious(printed_scene, 2, "cutting-mat-printed-lying-can", backgrounds=True)
    assert min(ious) > 0.9, ious


def test_a_top_of_the_table_s_colour_that_one_view_missed_is_looked_for_between_its_faces(printed_scene):
    """A white box on white laminate, with the empty workspace: from one view its top is as bright as the
    laminate and of its tint, and that view's evidence finds only the sides (0.81 before). The top leaves a
    bay in that silhouette's convex outline, inside the other views' hull: the graph cut looks for the
    object there too."""
    ious = _printed_scene_ious(printed_scene, 3, "laminate-white-box", backgrounds=True)
    assert min(ious) > 0.87, ious


def test_a_white_top_that_two_of_three_views_miss_is_found_within_the_others_hull(printed_scene):
    """A white box on white laminate: the two side views' evidence leaves its top out (0.68 and 0.60
    before), and three views' hull holds a box with or without its top, so no view reaches out of the
    others'. Cut again within the other views' hull, each side view finds the top, and its own evidence
    there, faint but over the table's noise across most of the face, keeps it."""
    ious = _printed_scene_ious(printed_scene, 3, "laminate-white-box", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_a_top_of_the_table_s_colour_on_a_side_is_kept_with_the_empty_workspace_too(printed_scene):
    """A white box on white laminate, with the empty workspace: from one view its top changes the empty
    laminate by no more than its noise, and the table point behind it looks as the top does, so neither cue
    finds it (0.65 before), and three views' hull holds the box with or without it. Cut again within the
    other views' hull the view finds it; lit as the table, seen alike by the others and sitting on the
    box's side in shade, it is the top, as from the images alone."""
    ious = _printed_scene_ious(printed_scene, 60, "laminate-white-box", backgrounds=True)
    assert min(ious) > 0.9, ious


def test_a_view_that_alone_sees_a_box_of_the_table_s_colour_surely_is_not_cut_back_to_the_others(printed_scene):
    """A tall white-and-blue box on white laminate, with the empty workspace: one view misses part of it (0.76
    at first), and another, which found it (0.93 at first), alone reaches out of the hull the two others
    carve. It was cut back to that hull (0.877 at the end). What reaches out changed against its empty
    workspace beyond any tint or noise over most of it (0.76 of it): the others missed it, and the view
    keeps its silhouette."""
    ious = _printed_scene_ious(printed_scene, 30, "laminate-sugar-box-tall-box", backgrounds=True)
    assert ious[1] > 0.91, ious


def test_hidden_table_alone_near_the_aim_is_not_taken_for_where_the_object_stands(printed_scene):
    """A white box on white laminate whose front face, in shade, stands out from the table in three stripes
    only, none of them under the aim. A larger stretch of table near the aim is hidden from the other views
    (behind the other views' first look at the object and its shadow), and differs from nothing: it was
    taken for where the object stands, and the scan failed ("view 0: nothing stands on the table near the
    views' aim"). Only a region that differs from the table somewhere is where something stands."""
    ious = _printed_scene_ious(printed_scene, 37, "laminate-white-box", backgrounds=False)
    assert min(ious) > 0.8, ious


def test_a_view_that_told_the_object_from_the_table_in_the_wrong_place_is_an_error_naming_it(printed_scene):
    """A box wearing its oak table's own grain, lit as the table: from the images alone one view tells only a
    corner of it from the table, 29 x 23 px, which puts the object's centre off the other views' rays. The
    reconstruction failed blaming the poses ("the views disagree about where the object is ... check the
    poses' direction"), which are right. The silhouettes were found in the images: the error says so, and
    what to give; with the empty workspace's pictures the same scan is found."""
    _, directory = printed_scene(42, "oak-table-colour-box")
    bundle = load_bundle(directory)
    plain = [View(view.camera, image=view.image) for view in bundle.views]
    with pytest.raises(SilhouetteError, match=r"^view 0: the views disagree about where the object is: .*"
                                              r"silhouette found in this view's image may have missed the object: "
                                              r"give the views pictures of the empty workspace, or masks"):
        reconstruct(plain, support_plane=bundle.support_plane)
    assert min(_printed_scene_ious(printed_scene, 42, "oak-table-colour-box", backgrounds=True)) > 0.7


def test_a_dark_can_s_top_stays_found_once_its_cast_shadow_is_dropped(printed_scene):
    """A dark can on its dark mat: every view found its top, and two took in some of its shadow. With the
    shadow dropped first (the lamp fitted to the scan), the silhouettes the top's height is read from changed,
    and the can's found top was taken for a lost box top: a section of mat was added above it in two views
    (0.79 and 0.71). A lost top is looked for first, and the lamp is fitted to the object as whole as the
    views give it."""
    ious = _printed_scene_ious(printed_scene, 33, "rubber-mat-dark-can", backgrounds=False)
    assert min(ious) > 0.83, ious


DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def test_a_view_cut_again_without_a_plane_keeps_what_looks_like_the_object_elsewhere():
    """Real photographs, no support plane: ../shared/data/dtu65/six, a skull on a brown board, every camera
    on one side. Seeded by the aim alone, two views find only an eye socket; cut again within the other
    views' hull, which from one side reaches far down onto the board, they took the board too, and the
    views that had been right were cut again to agree (0.39 worst, 0.73 mean against the masks supplied
    with the set). Within the hull, only what the other views' silhouettes hold more often than the rest
    of their pictures seeds the object."""
    path = DATA / "dtu65" / "six"
    if not (path / "scan.json").exists():
        pytest.skip(f"no test data at {path}")
    bundle = load_bundle(path)
    names = json.loads((path / "scan.json").read_text())["views"]
    images = [cv2.imread(str(path / view["image"])) for view in names]
    masks = [cv2.imread(str(path / view["mask"]), cv2.IMREAD_GRAYSCALE) for view in names]
    found = auto_silhouettes(images, [view.camera for view in bundle.views])
    ious = [_iou(silhouette, mask) for (silhouette, _), mask in zip(found, masks)]
    assert min(ious) > 0.85 and np.mean(ious) > 0.93, ious


@pytest.mark.parametrize("name, floor", [
    # 0.95 of the model's silhouette IoU with the masks the sets come with (0.880, 0.954, 0.961): no loss
    # where robocell already worked (issue 20).
    ("bunny", 0.836), ("dtu65/three", 0.906), ("dtu65/six", 0.913)])
def test_real_photographs_with_auto_lose_little_against_their_masks(name, floor):
    """The model reconstructed with ``auto`` from the photographs alone, projected by the judge
    (workers/sim/judge.py) and scored against the masks the set comes with (0.870, 0.930, 0.821 before a
    view cut again within the hull was kept to the object's colours; 0.894, 0.932, 0.936 after). The
    parts search makes these figures move by a few hundredths with the edge samples' small changes."""
    from robocell.workers.sim.judge import Part, union_silhouette_iou

    path = DATA / name
    if not (path / "scan.json").exists():
        pytest.skip(f"no test data at {path}")
    bundle = load_bundle(path)
    named = json.loads((path / "scan.json").read_text())["views"]
    masks = [cv2.imread(str(path / view["mask"]), cv2.IMREAD_GRAYSCALE) for view in named]
    # The bundle names its masks: the same cameras with the photographs alone.
    result = reconstruct([View(view.camera, image=(path / files["image"]).read_bytes())
                          for view, files in zip(bundle.views, named)])
    parts = [Part.from_dict(part.to_dict()) for part in (result.parts or [result.superquadric])]
    ious = [union_silhouette_iou(parts, view.camera.K, view.camera.T_world_cam, mask)
            for view, mask in zip(bundle.views, masks)]
    assert np.mean(ious) >= floor, ious


def test_a_noisy_camera_s_noise_is_no_grain(tmp_path):
    """A printed box on wood through a camera at high gain (sensor noise of 6 grey levels a channel added to
    the pictures, twice to four times the simulator's): in a flat window the noise passed for a grain that no
    other view shares, and flat table beside the box stood out (0.65 worst, 0.78 mean). A window's texture
    now counts only where it stands clear of the picture's own noise, estimated from the picture."""
    from robocell.workers.sim.scans import printed_set

    spec = {spec.name: spec for spec in printed_set(0)}["wood-printed-box"]
    spec.write(tmp_path)
    bundle = load_bundle(tmp_path / spec.name)
    rng = np.random.default_rng(0)
    images = [np.clip(cv2.imdecode(np.frombuffer(view.image, np.uint8), cv2.IMREAD_COLOR)
                      + rng.normal(0.0, 6.0, (480, 640, 3)), 0, 255).astype(np.uint8) for view in bundle.views]
    truths = [cv2.imread(str(tmp_path / spec.name / f"truth_mask{i}.png"), cv2.IMREAD_GRAYSCALE)
              for i in range(len(images))]
    found = auto_silhouettes(images, [view.camera for view in bundle.views], support_plane=bundle.support_plane)
    ious = [_iou(mask, truth) for (mask, _), truth in zip(found, truths)]
    assert min(ious) > 0.88, ious


def test_a_face_of_the_table_s_own_grain_that_the_colour_models_drop_is_kept(printed_scene):
    """A box printed with its oak table's own pattern: from one view its top is of the table's colour and
    light, and stands out through the plane by its grain alone (another stretch of the oak than the table
    point behind it). The colour models give it to the table, and the view lost its top (0.614 before). A
    piece that the grain alone carries, wider than the band the grain's window leaves along any edge and
    touching the silhouette, is a face: kept."""
    ious = _printed_scene_ious(printed_scene, 97, "oak-table-colour-box", backgrounds=False)
    assert ious[1] > 0.8 and min(ious) > 0.88, ious


def test_a_shadow_that_no_other_view_sees_keeps_a_grain_too_faint_for_one_pixel(printed_scene):
    """The strip of shadow under a lying tin on wood, with the empty workspace: the tin hides it from every
    other view, and the wood's weave, dimmed in the shadow, is too faint against the sensor's noise for any
    pixel's own window to say that it is kept, so the strip was taken for the tin's foot (0.73 before).
    Told over the strip whole, the image is the empty workspace's grain dimmed, and nothing else: table."""
    ious = _printed_scene_ious(printed_scene, 2, "wood-tin-lying-can", backgrounds=True)
    assert min(ious) > 0.9, ious


def test_a_shadow_that_no_other_view_sees_is_table_from_the_images_alone(printed_scene):
    """The strip of shadow under a lying tin on wood, from the images alone: the tin hides it from every
    other view, so only its look tells it from the tin, and the graph cut, seeded with it as the tin, kept
    it for the tin's dark foot (0.83 before). It is of the wood's colour darkened, and no brighter than the
    shadow the other views see beside the tin: seeded as table, the colour models leave it there."""
    ious = _printed_scene_ious(printed_scene, 2, "wood-tin-lying-can", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_a_shadow_on_a_gridded_mat_looks_like_a_shadow_though_its_pixels_vary_in_colour():
    """A cutting mat: green with lighter green grid lines, each pixel's colour between the two by how much of
    a line it holds, and a shadow over a third of it. The shadow keeps each of the mat's colours, darkened:
    its pixels lie as far from the mat's median colour as the lit mat's own do, and are a shadow's still
    (0.81 of them; 0.40 before, when a pixel had to lie within a fixed distance of the median colour)."""
    rng = np.random.default_rng(0)
    height, width = 60, 90
    line_share = np.array([1.0, 0.4, 0.0, 0.0, 0.0, 0.0, 0.0, 0.4], np.float32)
    cover = np.maximum(line_share[np.arange(height) % 8][:, None], line_share[np.arange(width) % 8][None, :])
    mat, line = np.array([55.0, 130.0, 45.0], np.float32), np.array([90.0, 165.0, 75.0], np.float32)
    image = (1 - cover)[..., None] * mat + cover[..., None] * line
    image[:, 60:] *= 0.4
    image = (image + rng.normal(0.0, 1.5, image.shape)).astype(np.float32)
    found = auto_segment._shadow_like(image, np.ones((height, width), bool))
    assert found[:, 60:].mean() > 0.75 and not found[:, :60].any(), found[:, 60:].mean()


def test_a_lying_can_s_shadow_on_a_gridded_mat_is_table_from_the_images_alone(printed_scene):
    """A printed can lying on a cutting mat, from the images alone: most of its shadow lies behind and
    under it, where the can hides the mat from the other views. The open part of it that they confirm
    holds the mat's grid: pixel by pixel its colours lie as far from the mat's median colour as the lit
    mat's own do (medians 0.13-0.18 and 0.09-0.12), and a shadow's were allowed 0.12, so no view saw a
    shadow region in the open to tell the hidden one by, and the cut kept it for the can (0.74 before).
    Allowed as far as the lit mat's own colours lie, the shadow in the open is seen, and the hidden part
    is left to the table."""
    ious = _printed_scene_ious(printed_scene, 49, "cutting-mat-printed-lying-can", backgrounds=False)
    assert ious[2] > 0.9, ious


def test_the_table_under_a_lying_tin_darker_than_any_shadow_in_the_open_is_dropped(printed_scene):
    """The table under a lying navy tin on wood, from the images alone: the tin hides it from every other
    view, and the graph cut kept it for the tin's shaded underside, whose dark navy a colour model cannot
    tell from dark grey, though it was seeded as probably table (0.775 before). The tin hides the sky from it
    as well as the lamp, so it is darker than the deepest shadow the other views see in the open: dropped."""
    ious = _printed_scene_ious(printed_scene, 1, "wood-tin-lying-can", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_the_table_under_a_lying_tin_is_dropped_with_the_empty_workspace_too(printed_scene):
    """The same lying navy tin on wood, with the empty workspace: the strip under the tin changed as a
    shadow does, but the graph cut kept it for the tin's dark underside (0.759 before)."""
    ious = _printed_scene_ious(printed_scene, 1, "wood-tin-lying-can", backgrounds=True)
    assert min(ious) > 0.9, ious


def test_a_dark_can_whose_foot_is_its_mat_s_shadow_s_colour_keeps_it(printed_scene):
    """A grey can on a dark rubber mat, from the images alone: its lower body, in its own shade, is of the
    mat's shadow's colour and as dark as the table under a lying can, and hidden from the other views too.
    But a point of the other views' hull on its ray, above the table, looks alike from another view: the
    can, kept (0.72 when the darkness alone decided)."""
    ious = _printed_scene_ious(printed_scene, 3, "rubber-mat-dark-can", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_a_view_cut_back_to_the_others_hull_still_finds_the_face_it_missed(printed_scene):
    """A grey can on a dark rubber mat, from the images alone: in one view the can's top is of the mat's
    colour and light, so its evidence missed it, and its silhouette reached out of the other views' hull
    beside the can's foot; cut back to the hull, it kept no top (0.61 before). The others' hull holds the
    top: looked for there, as in a view not corrected, it is found."""
    ious = _printed_scene_ious(printed_scene, 7, "rubber-mat-dark-can", backgrounds=False)
    assert ious[1] > 0.9 and min(ious) > 0.85, ious


def test_a_dark_band_of_another_colour_than_the_shadow_is_kept_from_the_images_alone(printed_scene):
    """A blue tin on a dark rubber mat, from the images alone: its lower band, in its own shade, stands in
    front of table points that the tin hides from the other views, and the graph cut gave it to the mat,
    whose colour model holds the tin's dark shadow (0.83 before). It is darker than the mat, but dark blue,
    far from the grey of the mat's shadow: no shadow, the tin."""
    ious = _printed_scene_ious(printed_scene, 0, "rubber-mat-tin-tin", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_a_dark_band_of_another_colour_than_the_shadow_is_kept_with_the_empty_workspace(printed_scene):
    """The same with the empty workspace: a blue tin's lower band on a dark rubber mat, darker than the
    empty mat at its pixels but dark blue, far from the mat's colour darkened (0.92 before)."""
    ious = _printed_scene_ious(printed_scene, 3, "rubber-mat-tin-tin", backgrounds=True)
    assert min(ious) > 0.94, ious


def test_clumps_of_the_mat_s_noise_near_a_tin_do_not_join_it_with_the_empty_workspace(printed_scene):
    """A blue tin on a dark rubber mat, with the empty workspace: against it the flat mat's change rounds to
    nothing in over half its pixels, and with no noise to read, two fifths of the mat far from the tin passed
    for changed. Clumps of it near the tin stood out through the plane too, joined the tin within their convex
    outline and took in the mat between them (0.49, 0.29 and 0.90 before). None holds a change beyond the
    mat's noise read before the rounding."""
    ious = _printed_scene_ious(printed_scene, 34, "rubber-mat-tin-tin", backgrounds=True)
    assert min(ious) > 0.9, ious


def test_a_dark_top_of_the_mat_s_brightness_is_found_by_its_tint_through_the_plane(printed_scene):
    """A dark can on a dark rubber mat, with the empty workspace: in one view the can's slightly reddish top
    changes against the empty mat by little more than its noise, and, a little darker than the mat, its tint
    is set aside as maybe a coloured shadow's, so the first cut lost the top (0.47 after every step before).
    The table point behind the top, seen from the other views, has the mat's tint: through the plane the
    top's tint stands out, as it does for the first cut without an empty workspace."""
    ious = _printed_scene_ious(printed_scene, 54, "rubber-mat-dark-can", backgrounds=True)
    assert min(ious) > 0.85, ious


def test_a_shadow_of_another_colour_than_the_table_is_not_taken_for_a_dark_face():
    """A blue box on a green grid mat whose shadow is not the mat's colour darkened (the ambient light's
    colour is not the lamp's): a dark pixel hidden from the other views and of another colour than the
    table's is no sure face there, or the graph cut, seeded with the box's dark blue, takes in the shadow
    (0.46 when asked anyway)."""
    scene = Scene(size=(0.03, 0.045, 0.06), object_print="label", object_bgr=(160, 90, 30), table_bgr=(70, 120, 60),
                  table_texture="grid", yaw=0.7)
    ious = _jpeg_scene_ious(scene, seed=2)
    assert min(ious) > 0.8, ious


def test_a_foot_that_two_views_took_for_the_shadow_is_looked_for_below_the_floating_hull(printed_scene):
    """A dark can on a dark rubber mat, with the empty workspace: in two views its lower body in the shade
    is of the shadow's darkness and tint beside it, and each view's table point behind it is darkened
    alike in the other, so both left it out (0.655 and 0.669 before). The hull of the three silhouettes
    then stops short of the table, which what stands on it cannot: each view is looked into again down
    to the plane below the hull."""
    ious = _printed_scene_ious(printed_scene, 1, "rubber-mat-dark-can", backgrounds=True)
    assert min(ious) > 0.78, ious


def test_a_top_hidden_from_the_other_views_table_is_kept_where_they_see_it_alike(printed_scene):
    """A tall white-and-blue box on white laminate: from one view its white top is of the laminate's colour
    and light, and its table points lie behind the box from the other views, so the view has no evidence
    there and its graph cut gave the top to the table (0.81 before). The other views see the top, and a
    point of it looks alike from them and from this view: the piece is the box's."""
    ious = _printed_scene_ious(printed_scene, 3, "laminate-sugar-box-tall-box", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_a_white_top_lost_beyond_the_sides_is_the_section_the_other_views_see(printed_scene):
    """A tall box, white above a blue band, on white laminate, from three views: two of them lose its top
    (23: 0.74 and 0.84 before; 30: 0.85 and 0.77; 10: 0.88 and 0.87), lit by the lamp as the laminate and of
    its white, no texture on either. Their silhouettes end at the top's near edge, with a side just below it;
    the third view found the top, lit as the table, below its rim. The rays through the near edge leave the
    other views' silhouettes swept down to the table at the top's height, where the third view sees the top's
    section within its silhouette: projected into the two views, it lies beyond their rims."""
    for seed in (23, 30, 10):
        ious = _printed_scene_ious(printed_scene, seed, "laminate-sugar-box-tall-box", backgrounds=False)
        assert min(ious) > 0.92, (seed, ious)


def test_a_dark_can_s_top_found_in_every_view_is_no_lost_top(printed_scene):
    """A dark can on its dark mat, with the empty workspace: every view found its top, but from two of them
    the top's far rim is dark, as a box's side below a lost top is, and the rays through it leave the other
    views' side outlines well above the top. The section there is no lost top: the view that sees the top lit
    as the mat holds less than :data:`_FITS_WHOLE` of it, its near part (0.54; with a share of a half, the
    view lost 0.96 -> 0.76 to table added beyond its rim)."""
    ious = _printed_scene_ious(printed_scene, 18, "rubber-mat-dark-can", backgrounds=True)
    assert min(ious) > 0.9, ious


def test_a_top_of_the_table_s_colour_brighter_than_the_lit_table_is_kept(printed_scene):
    """A white box on white laminate: from one view its top is of the laminate's colour, and the table
    point behind it, which the other views see, looks as it does, so the parallax says table there and the
    view left the top out (0.64 before). But the top stands nearer the lamp than the table and sees all of
    the sky: it is brighter than the lit laminate round the box, beyond the laminate's own spread, and the
    other views see a point of the box there alike."""
    ious = _printed_scene_ious(printed_scene, 10, "laminate-white-box", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_a_top_that_the_cut_gives_the_table_stands_out_by_its_light(printed_scene):
    """A tall white-and-blue box on white laminate: from one view its white top is of the laminate's colour
    and the graph cut within the other views' hull gives it to the table, nor does its parallax stand out
    (0.81 before). Its pixels are brighter than the lit laminate round the box beyond the laminate's own
    spread, and the other views see a point of the box there alike over all of it."""
    ious = _printed_scene_ious(printed_scene, 5, "laminate-sugar-box-tall-box", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_a_lit_top_that_the_others_missed_too_stands_out_by_its_light_where_they_see_most_of_it_alike(printed_scene):
    """A tall white-and-blue box on white laminate, with the empty workspace: from one view its white top
    changes hardly at all against it and the cut gives it to the table (0.83 before). It is brighter than
    the lit laminate round the box, but the other views' hull, carved by a view that missed its own view of
    the top, holds only the near part of it, so they see it alike over most of it, not all but its rim."""
    ious = _printed_scene_ious(printed_scene, 5, "laminate-sugar-box-tall-box", backgrounds=True)
    assert ious[2] > 0.93 and min(ious) > 0.9, ious


def test_a_lit_top_that_two_side_views_miss_stands_out_in_both_even_the_one_cut_again(printed_scene):
    """A tall white-and-blue box on white laminate seen low from two sides: each side view's top is of the
    laminate's colour, a little brighter than the lit laminate, and both leave it out (0.51 and 0.62
    before). One of them, blamed for holding too little, was cut again within the others' hull, by colour
    models that cannot tell the top from the table, and no more was looked for there; the top's light
    stands out in both."""
    ious = _printed_scene_ious(printed_scene, 18, "laminate-sugar-box-tall-box", backgrounds=False)
    assert min(ious[1], ious[2]) > 0.8 and ious[0] > 0.93, ious


def test_the_shadow_by_the_foot_that_a_view_cut_again_took_in_is_left_out(printed_scene):
    """A white box on white laminate, from the images alone: one view, blamed for holding too little, is cut
    again within the other views' hull, and the colour models of its seeds, whose faces in shade are of the
    shadow's colour, take the shadow by the box's foot that the loose hull holds (0.78 before). That piece
    looks like a shadow, the other views confirm the table behind it, and it is darker than the shadow
    cast in the open, as a face lit by the sky is not: left out."""
    ious = _printed_scene_ious(printed_scene, 18, "laminate-white-box", backgrounds=False)
    assert ious[0] > 0.93 and min(ious) > 0.83, ious


def test_a_top_of_the_mat_s_colour_is_found_by_the_grain_it_hides(printed_scene):
    """A dark can on a dark rubber mat, with the empty workspace: from one view its top is of the mat's
    colour and light, changed against the empty workspace in nothing but the mat's speckle, too faint for
    a pixel's window (0.60 before). The other views see the top, alike, within their hull beyond this
    view's silhouette; told over the piece whole, the image there has lost the grain that the mat round it
    keeps: the can's top."""
    ious = _printed_scene_ious(printed_scene, 2, "rubber-mat-dark-can", backgrounds=True)
    assert min(ious) > 0.9, ious


def test_a_tint_that_one_view_alone_puts_on_the_table_is_cut_away(printed_scene):
    """A white-and-blue box on white laminate, each picture compressed once more by JPEG (quality 75, as a
    camera's stream re-encoded): in one view a patch of the laminate behind the box took a tint, which
    stands out against the other views' laminate through the plane (0.63 before). That view alone reaches
    out of the others' hull there, and the two others agree with each other and with it elsewhere: what
    lies outside their hull is table."""
    ious = _printed_scene_ious(printed_scene, 0, "laminate-sugar-box-tall-box", backgrounds=False, jpeg_again=75)
    assert min(ious) > 0.9, ious


def test_a_view_cut_back_to_the_others_hull_keeps_what_they_agree_on():
    """A box of its wooden table's colour: one view alone reaches out of the other two views' hull, but
    one of those two missed part of the box, and the cut within their hull keeps under a third of what the
    view and the hull agree on (the view fell from 0.65 to 0.19). Such a cut is given up: the view keeps its
    silhouette."""
    ious = _jpeg_scene_ious(Scene(object_bgr=(150, 170, 190), table_texture="wood"), seed=6)
    assert min(ious) > 0.5, ious


def test_unsure_pixels_are_the_table_s_shade_about_the_silhouette():
    """A grained blue-grey table, a red square on it, a shadow (the table at 40 % of its light) beside the
    square, part of it inside the silhouette, and a dark blue face on the square's other side that the
    silhouette leaves out: the shadow is unsure on either side of the silhouette's edge and the dark face
    outside it; the square, a dark face of its own colour inside it, and the table's own grain are sure."""
    from robocell.core_cy.auto_segment import unsure_pixels

    table = np.array([150, 140, 120], np.float64)
    grain = np.random.default_rng(0).normal(1.0, 0.04, (200, 300, 1))
    image = np.clip(np.round(table * grain), 0, 255).astype(np.uint8)
    image[60:140, 60:140] = (30, 40, 200)  # the object
    image[60:140, 140:190] = np.round(0.4 * table).astype(np.uint8)  # its shadow
    image[60:140, 45:60] = (70, 20, 10)  # its dark face, left out
    image[140:150, 60:140] = (70, 20, 10)  # another, taken in
    silhouette = np.zeros((200, 300), np.uint8)
    silhouette[60:150, 60:170] = 255  # the object, a dark face and the shadow's near half
    unsure = unsure_pixels(image, silhouette)
    assert not unsure[60:150, 60:140].any()
    assert unsure[60:140, 140:170].all()  # the shadow taken in
    assert unsure[60:140, 170:190].all()  # the shadow left out, within a quarter of the size of the silhouette
    assert unsure[60:140, 45:60].all()  # the dark face left out
    lit = np.ones((200, 300), bool)
    lit[60:150, 45:190] = False
    # The grain's darkest few hundredths lie beyond three of its median absolute deviations (two standard
    # deviations) as a shadow does; taking every pixel darker than the table's median, half of them, for a
    # shadow set aside the table seen between a dumbbell's weights, which no longer paid for its carving.
    assert unsure[lit].mean() < 0.05
    with pytest.raises(ImageError):
        unsure_pixels(image[:, :, 0], silhouette)


def test_an_outline_across_which_the_image_shows_no_step_is_unsure():
    """A grained table and a face of its own colour, brighter (lit from above), with a strip of the table
    beside it taken in: the strip's false edge has table on both sides, and is unsure; the face's own
    edges, a step from the table, are sure, the face's inside too (issue 20)."""
    from robocell.core_cy.auto_segment import unsure_pixels

    table = np.array([150, 140, 120], np.float64)
    grain = np.random.default_rng(0).normal(1.0, 0.04, (200, 300, 1))
    image = np.clip(np.round(table * grain), 0, 255).astype(np.uint8)
    image[60:140, 60:140] = np.clip(np.round(1.25 * table * grain[60:140, 60:140]), 0, 255).astype(np.uint8)
    silhouette = np.zeros((200, 300), np.uint8)
    silhouette[60:140, 60:170] = 255  # the face and a strip of table 30 px wide
    unsure = unsure_pixels(image, silhouette)
    assert unsure[70:130, 167:173].all()  # the strip's false edge, either side
    # The face's true edge, either side, and the face: sure but for the grain's darkest few hundredths,
    # which lie as far below the table's median as a shadow does (as in the test above).
    assert unsure[60:140, 54:66].mean() < 0.05 and unsure[60:140, 60:140].mean() < 0.05


def test_a_shadow_darker_than_the_table_s_deepest_taken_in_is_unsure():
    """Under a lying can's side the table gets almost no light: a band there darker than any shadow the
    table's colour is kept in (nearly black) that the silhouette took in is unsure, as a dark face would be
    (no colour is left to tell them apart); a dark face with colour of its own inside stays sure."""
    from robocell.core_cy.auto_segment import unsure_pixels

    table = np.array([150, 140, 120], np.float64)
    grain = np.random.default_rng(0).normal(1.0, 0.04, (200, 300, 1))
    image = np.clip(np.round(table * grain), 0, 255).astype(np.uint8)
    image[60:130, 60:140] = (30, 40, 200)  # the object
    image[130:140, 60:140] = (70, 20, 10)  # its dark face
    image[140:150, 60:140] = (6, 8, 10)  # the shadow under it, nearly black, taken in
    silhouette = np.zeros((200, 300), np.uint8)
    silhouette[60:150, 60:140] = 255
    unsure = unsure_pixels(image, silhouette)
    assert unsure[140:150, 60:140].all()
    assert not unsure[60:140, 60:140].any()
    # Asked about some pixels only (those about the fit's edge samples), each is judged as among all.
    asked = np.zeros((200, 300), bool)
    asked[130:160, 50:100] = True
    np.testing.assert_array_equal(unsure_pixels(image, silhouette, asked), unsure & asked)


def test_a_top_of_the_table_s_colour_and_light_is_found_with_the_empty_workspace_too(printed_scene):
    """A tall white-and-blue box on white laminate, with the empty workspace: from one view the box's white
    top changed hardly at all against the empty laminate, and the view left it out (0.88 before; 0.97 from
    its images alone). The two other views' hull holds the top; the graph cut finds it there, and the
    plane's parallax, as without the empty workspace, says it is no table (issue 20)."""
    ious = _printed_scene_ious(printed_scene, 0, "laminate-sugar-box-tall-box", backgrounds=True)
    assert min(ious) > 0.93, ious


def test_a_dark_face_that_changed_like_its_shadow_stands_out_by_its_colour(printed_scene):
    """A printed box on wood, with the empty workspace: from one view the box's lower band in the shade
    changed against the empty workspace as the shadow beside it did, and another view sees that shadow at
    the band's table point, so the band was taken for the shadow (0.89 before; 0.96 from the images alone).
    Its colour is not that of the shadowed table point: the plane's parallax shows it clearly standing
    above the table (issue 20)."""
    ious = _printed_scene_ious(printed_scene, 1, "wood-printed-box", backgrounds=True)
    assert ious[0] > 0.93 and min(ious) > 0.85, ious


def test_a_face_that_one_view_of_six_missed_is_looked_for_beyond_its_outline(printed_scene):
    """A printed ellipsoid on a dark rubber mat, six views with the empty workspace: from two views its dark
    lower band in the shade changed as its shadow did and was left out (0.83 and 0.89 before). The hull of
    five views forgives one view's miss, so no other view reaches out of it; but it holds the band beyond
    the view's outline, where the graph cut finds it, the plane's parallax says it stands, and the other
    views see it alike (issue 20)."""
    ious = _printed_scene_ious(printed_scene, 3, "rubber-mat-printed-ellipsoid", backgrounds=True)
    assert min(ious) > 0.9, ious


def test_a_shadow_under_a_lying_tin_darker_than_the_open_shadow_is_table_with_the_empty_workspace(printed_scene):
    """A lying tin on wood, with the empty workspace: the strip of shadow under it, hidden from the other
    views by the tin, was seeded as the tin, and the graph cut kept it for the tin's dark blue foot (0.76
    and 0.85 before in two views; the images alone do no better). Against its own empty workspace it is
    the wood darkened with its colour kept, and darker than the darkest of the open shadow: the table.
    The open shadow is every view's where the lamp behind the tin hides all of it in one (seed 5)."""
    for seed in (1, 5):
        ious = _printed_scene_ious(printed_scene, seed, "wood-tin-lying-can", backgrounds=True)
        assert min(ious) > 0.95, (seed, ious)


def test_the_shadow_under_an_ellipsoid_s_belly_is_table_with_the_empty_workspace(printed_scene):
    """A printed ellipsoid on fabric, with the empty workspace: the shadow under its belly, hidden from the
    other views, stayed in two views' silhouettes (0.75 and 0.85 before; 0.99 and 0.97 from the images
    alone). It is the fabric darkened as the open shadow, its colour kept: seeded as table."""
    ious = _printed_scene_ious(printed_scene, 5, "fabric-printed-ellipsoid", backgrounds=True)
    assert min(ious) > 0.93, ious


def test_a_near_black_can_s_lower_body_is_not_taken_for_the_table_it_hides_with_the_empty_workspace(printed_scene):
    """A grey can on a dark rubber mat, with the empty workspace: from one view its near-black lower body is
    hidden from the other views, darker than the darkest of the open shadow, and of the mat's colour
    darkened within the colour test's floor (a few grey levels a channel: noise), so it was seeded as the
    table the can hides from the sky, for sure (0.58 before). So dark, the can's own faces pass that test
    too, and a face in shade, lit by the sky, is no darker than the can's darkest face in sight dimmed as
    the open shadow is: nothing tells it for table, and the colour models keep it for the can."""
    ious = _printed_scene_ious(printed_scene, 9, "rubber-mat-dark-can", backgrounds=True)
    assert min(ious) > 0.95, ious


def test_a_dark_can_a_little_darker_than_its_near_black_mat_is_found_with_the_empty_workspace(printed_scene):
    """A dark grey can on a near-black rubber mat (24 grey levels a channel), with the empty workspace: its
    lit side and top are 0.85 of the mat, four grey levels a channel. The coarse change against the empty
    workspace is 0 or one grey level over most of the mat, and the noise read from so few values was
    twice the sensor's, so only the can's stripes and shaded side changed, and the views kept a third to a
    half of it (0.47, 0.50, 0.29 before). The noise is read before the rounding where the rounding made it."""
    ious = _printed_scene_ious(printed_scene, 11, "rubber-mat-dark-can", backgrounds=True)
    assert min(ious) > 0.85, ious


def test_a_dark_can_s_body_in_shade_on_its_dark_mat_is_kept_with_the_empty_workspace(printed_scene):
    """A dark can on a dark rubber mat, with the empty workspace: its lower body in shade is a dozen grey
    levels a channel, as dark as the shadow beside it that the other views see at its table points. Compared
    through the plane after the coarse pictures' rounding to whole grey levels, half a grey level is a step
    of several times the lit table's noise in the log of so dark a pixel: the body's change and the shadow's
    could not be told apart, and one view gave the body to the table (0.78 before). Compared before the
    rounding, the body stands out."""
    ious = _printed_scene_ious(printed_scene, 17, "rubber-mat-dark-can", backgrounds=True)
    assert min(ious) > 0.82, ious


def test_a_white_box_s_face_turned_from_the_lamp_is_kept_with_the_empty_workspace(printed_scene):
    """A white box on white laminate, with the empty workspace: from one view its two faces turned from the
    lamp look like the shadow beside them and hide their table points from the other views, so the
    parallax says nothing of them, and the view lost them (0.61 before; 0.94 from the images alone). The
    other views see them alike: they are kept, as without the empty workspace; nor are they taken for the
    table in the box's shadow, the box's faces having the table's colour."""
    ious = _printed_scene_ious(printed_scene, 5, "laminate-white-box", backgrounds=True)
    assert min(ious) > 0.93, ious


def test_a_white_box_s_face_in_shade_over_its_shadow_is_kept_from_the_images_alone(printed_scene):
    """A white box on white laminate, from the images alone: in one view the cut within the other views'
    hull finds the box's shaded front face, but its grey matches the table in the shadow behind it, so the
    colour evidence called it table (0.70 before). The face stands over the box's shadow and the dark rim
    round its foot, so most of what lies round it beyond the silhouette is darker than it, which a shadow
    on the table never is: kept."""
    ious = _printed_scene_ious(printed_scene, 7, "laminate-white-box", backgrounds=False)
    assert ious[2] > 0.77 and min(ious) > 0.77, ious


def test_a_view_whose_excess_its_own_evidence_puts_on_the_plane_is_the_one_cut_back(printed_scene):
    """A box of its table's colour, from the images alone: one view's first cut took in the box's shadow and
    reaches out of the others' hull. With three views, leaving any one out of the carving clears the others'
    excess, so another view was blamed for holding too little and cut again within the others' hull, shadow
    and all (0.79 before). The reaching view's own evidence puts all of its excess on the plane: it is the
    one cut back."""
    ious = _printed_scene_ious(printed_scene, 5, "oak-table-colour-box", backgrounds=False)
    assert ious[1] > 0.84 and min(ious[0], ious[2]) > 0.78, ious


def test_a_lit_top_of_the_table_s_colour_is_kept_where_it_stands_out_and_the_others_see_it_alike(printed_scene):
    """A white box on white laminate, from the images alone: from one view its lit top has the laminate's
    colour and light, so the cut within the other views' hull gives it to the table (0.65 before). The
    plane's parallax stands out over the top above what the table round the hull shows, and the other
    views see the top alike there: kept."""
    ious = _printed_scene_ious(printed_scene, 6, "laminate-white-box", backgrounds=False)
    assert ious[0] > 0.93 and min(ious) > 0.88, ious


def test_a_lit_top_of_the_table_s_colour_is_kept_where_it_stands_out_with_the_empty_workspace_too(printed_scene):
    """The same white box, with the empty workspace: the top of another view changes hardly at all against
    it (0.85 before); the plane's parallax, standing out over the top, and the other views seeing it alike
    keep it."""
    ious = _printed_scene_ious(printed_scene, 6, "laminate-white-box", backgrounds=True)
    assert ious[1] > 0.93 and min(ious) > 0.82, ious


def test_a_face_in_shade_that_hides_the_table_s_grain_is_kept_against_the_empty_workspace(printed_scene):
    """A box of its table's colour with its empty workspace: one view's face turned from the lamp is as dark
    as the cast shadow and of its chromaticity, so it has a shadow's look, the other views' feet hide the
    table behind most of it, and they see the lit face there, not alike (0.65 before). The oak's grain,
    which a shadow keeps and the table round the piece keeps, is gone from it: a face, kept."""
    ious = _printed_scene_ious(printed_scene, 5, "oak-table-colour-box", backgrounds=True)
    assert ious[2] > 0.95 and min(ious) > 0.85, ious


def test_a_face_in_shade_that_hides_the_grain_the_other_views_see_is_kept_from_the_images_alone(printed_scene):
    """A box of its table's colour, from the images alone: in one view the cut within the other views' hull
    finds the box's faces turned from the lamp, bordered by lit table, but their colour matches the table
    in the box's shadow behind them, which the other views see, so the colour evidence called them table
    (0.76 before). The other views see the oak's grain at those table points; mapped through the plane it
    is gone from the faces, which a shadow on the table keeps: faces, kept."""
    ious = _printed_scene_ious(printed_scene, 270, "oak-table-colour-box", backgrounds=False)
    assert ious[1] > 0.85 and min(ious) > 0.85, ious


def test_a_face_in_shade_as_dark_as_the_shadow_is_kept_where_the_others_see_the_table_behind_it(printed_scene):
    """A box of its table's colour, from the images alone: in one view only its lit top was found (0.61
    before). The cut within the other views' hull finds its two faces turned from the lamp, which hide the
    oak's grain the other views see at the table points behind them, but they are as dark as the box's
    shadow, most of which lies within that hull too, so the open shadow left beside it was a strip of its
    soft edge, and the faces were taken for the table under an overhang. That table is hidden from the
    other views by the object above it; the table behind these faces is not: kept."""
    ious = _printed_scene_ious(printed_scene, 110, "oak-table-colour-box", backgrounds=False)
    assert ious[0] > 0.76 and min(ious[1:]) > 0.88, ious


def test_a_face_in_shade_that_the_cut_gave_to_the_shadow_beside_it_is_split_off_by_the_grain(printed_scene):
    """A box of its table's colour, from the images alone: in one view its face turned from the lamp is of
    the colour and darkness of the box's shadow beside it, and the cut within the other views' hull gave
    both to the table, so no piece of the cut held the face (0.78 without the split). The grain the other
    views see at the table points tells them apart pixel by pixel: the shadow keeps it, the face hides it."""
    ious = _printed_scene_ious(printed_scene, 15, "oak-table-colour-box", backgrounds=False)
    assert ious[1] > 0.85 and min(ious) > 0.85, ious


def test_a_face_in_shade_that_the_cut_gave_to_the_shadow_is_split_off_by_the_empty_workspace_s_grain(printed_scene):
    """The same with the empty workspace: in one view of a box of its table's colour the face turned from
    the lamp is as dark as the box's shadow beside it and changes against the empty workspace as the shadow
    does, so the cut gave the two to the table (0.61 without the split). The empty workspace's grain, which
    the shadow keeps and the face hides, tells them apart pixel by pixel."""
    ious = _printed_scene_ious(printed_scene, 35, "oak-table-colour-box", backgrounds=True)
    assert ious[1] > 0.85 and min(ious) > 0.8, ious


def test_a_lit_face_of_the_table_s_colour_that_hides_the_grain_whole_is_kept_with_the_empty_workspace(printed_scene):
    """A box of its table's colour with its empty workspace: in one view its lit face is the oak's colour and
    light, and changes against the empty workspace only by the grain it hides. It hides all of it, but on a
    table whose grain the noise blurs that reads under a sure change, so the graph cut's colour models, which
    cannot tell the face from the table, gave it to the table (0.57 before). A grain lost whole is no shadow
    and no noise: the face is seeded as the object for sure."""
    ious = _printed_scene_ious(printed_scene, 9, "oak-table-colour-box", backgrounds=True)
    assert ious[1] > 0.85 and min(ious) > 0.85, ious


def test_a_shadow_beside_a_lying_can_that_keeps_the_grain_is_left_out_with_the_empty_workspace(printed_scene):
    """A lying can on a cutting mat with its empty workspace: in one view the cut within the other views'
    hull took in the can's shadow beside it, whose table points the can hides from the other views, and
    which they see alike with the can above it (0.78 before). Against the empty workspace it keeps the
    mat's grain as the mat round it does, as a shadow does and a face does not: left out."""
    ious = _printed_scene_ious(printed_scene, 15, "cutting-mat-printed-lying-can", backgrounds=True)
    assert ious[0] > 0.92 and min(ious) > 0.92, ious


def test_the_shadow_a_view_cut_again_took_in_with_its_face_in_shade_is_left_out_by_the_grain(printed_scene):
    """A box of its table's colour with its empty workspace: one view missed the box's face in shade, and cut
    again within the other views' hull it found the face joined to the box's shadow by the foot, of the same
    colour (0.74 without the split). Split where each pixel's window has lost the grain, the part that keeps
    it as the table round it does is the shadow: left out, the face kept."""
    ious = _printed_scene_ious(printed_scene, 102, "oak-table-colour-box", backgrounds=True)
    assert ious[0] > 0.85 and min(ious) > 0.85, ious


def test_a_face_that_hides_the_grain_is_kept_without_the_lit_table_joined_to_it(printed_scene):
    """A box of its table's colour with its empty workspace: beyond one view's silhouette, within the other
    views' hull, a piece that hides the grain told whole was the box's face and the lit table beside it, of
    the same colour and light (0.77 without the split, 1600 px of table taken in). The pixels whose own
    window keeps the grain as the table round it does, a part that keeps it told whole, are the table: left
    out."""
    ious = _printed_scene_ious(printed_scene, 58, "oak-table-colour-box", backgrounds=True)
    assert ious[2] > 0.83 and min(ious) > 0.8, ious


def test_lit_table_that_stands_out_no_more_than_the_table_round_the_hull_is_left_out(printed_scene):
    """A mustard bottle on oak, from the images alone: the cut within the other views' hull took a stretch of
    lit oak beside the bottle, and its plane parallax (1.45 times its noise over the stretch, the median) was
    over 1, so it was kept for a face (0.93 before). The oak round the hull stands out by more there (1.79,
    its 0.9 quantile): a piece is a face where it stands out over what the table round it does."""
    ious = _printed_scene_ious(printed_scene, 13, "oak-mustard-bottle", backgrounds=False)
    assert ious[1] > 0.955, ious


def test_the_table_beside_a_lying_can_that_the_others_see_alike_over_half_of_it_is_left_out(printed_scene):
    """A printed can lying on a cutting mat, from the images alone: the cut within the other views' hull took
    a stretch of the mat beside the can, which the can hides from the other views, and they saw it alike over
    0.56 of it (where the can behind it is green), so it was kept for a face (0.79 before). Their likeness is
    all that speaks for such a piece without an empty workspace: it must hold over most of it."""
    ious = _printed_scene_ious(printed_scene, 15, "cutting-mat-printed-lying-can", backgrounds=False)
    assert ious[0] > 0.9, ious


def test_the_part_of_a_piece_that_stands_out_is_kept_where_the_piece_as_a_whole_does_not(printed_scene):
    """A dark can on a dark rubber mat, from the images alone: the cut within the other views' hull gave the
    can's side in shade and its shadow beside it as one piece, whose parallax stands out over the mat's
    (the table round the hull) on the side and not on the shadow. Weighed whole it was all kept (0.933) or,
    against the mat's level, all dropped (0.912); the part over the mat's level is the can's side."""
    ious = _printed_scene_ious(printed_scene, 8, "rubber-mat-dark-can", backgrounds=False)
    assert ious[2] > 0.945, ious


def test_the_shadow_the_others_confirm_is_left_out_of_a_piece_that_stands_out_as_a_whole(printed_scene):
    """A dark can on a dark rubber mat, from the images alone: the cut within the other views' hull gave a strip
    of the can's side in shade and its shadow cast on the mat beside it as one piece, whose parallax stands
    out over most of it, on the side; kept whole, the shadow came with it (0.838). The shadow's table points
    the other views see and confirm through the plane, which maps a shadow exactly from view to view and a
    face above the plane not: that part of the piece is the table."""
    ious = _printed_scene_ious(printed_scene, 6, "rubber-mat-dark-can", backgrounds=False)
    assert ious[2] > 0.88, ious


def test_a_lying_can_s_shadow_that_every_other_view_sees_behind_it_is_table_from_the_images_alone(printed_scene):
    """A printed can lying on a cutting mat, the lamp behind it from one view: that view's share of the
    can's shadow lies all in front of the can, where the can hides the mat from every other view, so it
    saw no shadow in the open to tell the hidden one by, and the cut kept it for the can's side in shade
    (0.73 before). The shadow's depth is the light's, the same from any view: cut again knowing how deep
    the other views see theirs, the view leaves the mat's colour darkened so to the table."""
    ious = _printed_scene_ious(printed_scene, 6, "cutting-mat-printed-lying-can", backgrounds=False)
    assert ious[1] > 0.9, ious


def test_a_top_of_the_mat_s_colour_and_light_that_the_others_see_alike_is_kept(printed_scene):
    """A dark can on a dark rubber mat, from the images alone: from one view its top is of the mat's colour
    and light, so the mat the other views see behind it through the plane matches it and the parallax says
    nothing either way; the cut within the other views' hull found the top, but it was dropped for not
    standing out (0.528). The other views see it alike over all of it but its rim, and it is lit as the mat
    round the can is (the can's shadow, which they may see alike too where the can behind it is as dark,
    is not): a face turned up to the lamp, kept."""
    ious = _printed_scene_ious(printed_scene, 17, "rubber-mat-dark-can", backgrounds=False)
    assert ious[1] > 0.9 and min(ious) > 0.9, ious


def test_the_table_beyond_a_box_s_own_top_that_the_others_see_alike_is_not_taken_for_a_top(printed_scene):
    """An oak-coloured box on oak, from the images alone: beyond the box's top, as one view sees it, lies a
    stretch of lit oak that the other views see alike (the box behind it in theirs has the oak's colour) and
    that is lit as the table, because it is the table; taken for a top of the table's colour, it lowered the
    view to 0.867. A top seen from above sits on the object's side, which the lamp above lights less than a
    face turned up; the silhouette below this stretch is the box's own top, lit as the table: not a top."""
    ious = _printed_scene_ious(printed_scene, 221, "oak-table-colour-box", backgrounds=False)
    assert ious[0] > 0.9, ious


def test_faces_in_shade_whose_table_points_the_object_hides_from_the_others_are_kept(printed_scene):
    """An oak-coloured box on oak, from the images alone: from one view the box's face in shade is the oak
    darkened, as its shadow is, and the colour models gave it to the table (0.567). The table points behind
    it lie behind the box from the other views, so neither the plane's parallax nor the grain they map says
    anything there; but those views see the face alike (over 0.6 of it), where a shadow on the table at a
    point they cannot see would stand in the air before the box's other faces, and the face is as dark as
    the shadow cast in the open, neither lighter (its soft edge) nor darker (under an overhang),
    and darker than the lit table by more than the light varies over a table (not so on fabric, whose shadow
    is faint and whose table seen alike beside an ellipsoid was taken)."""
    ious = _printed_scene_ious(printed_scene, 26, "oak-table-colour-box", backgrounds=False)
    assert ious[0] > 0.73, ious


def test_a_lit_top_parted_from_the_silhouette_by_the_box_s_edge_is_kept(printed_scene):
    """A tall white-and-blue box on white laminate, seen low: the view's top is the laminate's colour, its
    table points lie out of the other views' pictures, and the cut again within their hull gave it to the
    table (0.78 before). The top stands out by its light, brighter than the lit laminate round the box, but
    the box's edges part it from the silhouette by a coarse pixel or two (the front edge's rounding, the
    side face in shade): it is within the blur of the silhouette's edge, and kept with the edge."""
    ious = _printed_scene_ious(printed_scene, 12, "laminate-sugar-box-tall-box", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_a_face_found_in_one_view_widens_the_hull_the_others_look_into_again(printed_scene):
    """A white box on white laminate, from the images alone: two views each missed part of a lit face. The
    first looked into its bays within a hull that the second, still missing its own, had carved too small
    (0.82 before); once the second found its face, the first looks again within the hull as it is now."""
    ious = _printed_scene_ious(printed_scene, 11, "laminate-white-box", backgrounds=False)
    assert min(ious) > 0.9, ious


def test_a_look_again_does_not_take_the_table_beyond_a_top_for_a_face_standing_out(printed_scene):
    """An oak box of the oak's colour, from the images alone: looked into again after another view grew, one
    view took a stretch of the oak behind the box's top for a face standing out (0.83 when faces are looked
    for again). Faces standing out are looked for by the view's own light and parallax, which a look again
    does not change, so they are looked for once."""
    ious = _printed_scene_ious(printed_scene, 226, "oak-table-colour-box", backgrounds=False)
    assert ious[0] > 0.9, ious


def test_a_look_again_does_not_keep_lit_table_hidden_only_by_another_view_s_new_part(printed_scene):
    """A soup can on fabric, from the images alone: one view's look took a stretch of lit fabric before the
    can's foot, and that hid from it the table points of the fabric before the foot in another view. Looked
    into again, that view kept the fabric there as a lit face whose table points the others cannot see,
    seen alike (0.939); only what hid them before the looks says they are hidden."""
    ious = _printed_scene_ious(printed_scene, 14, "fabric-soup-can-can", backgrounds=False)
    assert ious[2] > 0.96, ious


def test_a_lit_top_is_looked_for_in_a_view_cut_again_with_the_empty_workspace_too(printed_scene):
    """The tall box of the test above, with the empty workspace: the white top changes hardly at all against
    it, the view was cut again within the others' hull by colour models that cannot tell the top from the
    table (0.78 before), and no more was looked for there. The top's light and its parallax stand out as
    they do without the empty workspace."""
    ious = _printed_scene_ious(printed_scene, 12, "laminate-sugar-box-tall-box", backgrounds=True)
    assert min(ious) > 0.9, ious


def test_the_shadow_by_the_foot_joined_to_a_face_in_shade_is_left_out(printed_scene):
    """A white box on white laminate, from the images alone: one view, cut again within the other views'
    hull, took the box's missing face in shade and the shadow by its foot that the loose hull holds, in one
    piece (0.84 before). The face's table points lie behind the box from the other views, the shadow's
    they see and confirm, so the piece as a whole is mostly hidden from them and was not asked; asked
    alone, the part they see has a shadow's look and is darker than the shadow cast in the open: left out."""
    ious = _printed_scene_ious(printed_scene, 7, "laminate-white-box", backgrounds=False)
    assert ious[1] > 0.9 and min(ious) > 0.9, ious


def test_a_lit_face_whose_table_points_the_object_hides_from_the_others_is_kept(printed_scene):
    """An oak-coloured box on oak, from the images alone: from one view the box's face lit by the lamp is of
    the oak's colour and light, and the colour models gave it to the table with the face in shade beside it
    (0.789). The table points behind the face lie behind the box from the other views, so neither the plane's
    parallax nor the grain they map says anything there; but they see the face alike over 0.6 of it, as a
    face standing on the object is seen, where the table at a point they cannot see would stand in the air
    before the box's other faces: kept, as a face in shade as dark as the open shadow is, for it is lit by
    the lamp, brighter than the open shadow, and lies below the box's top, not beyond it."""
    ious = _printed_scene_ious(printed_scene, 254, "oak-table-colour-box", backgrounds=False)
    assert ious[2] > 0.85, ious


def test_the_lit_table_before_a_side_s_foot_is_not_taken_for_the_object(printed_scene):
    """An oak-coloured box on oak, from the images alone: from one view the lit oak just before the foot of
    the box's side lies behind the box from the other views, so nothing but its look tells it from the box,
    and the colour models, holding the box's top lit as the oak, took it (0.666). Below a side (darker than the
    lit table), at the silhouette's rim, the box's surface goes on down to its foot, turned from the lamp:
    what lies there lit as the table and of its colour is the table before the side's foot."""
    ious = _printed_scene_ious(printed_scene, 18, "oak-table-colour-box", backgrounds=False)
    assert ious[2] > 0.81, ious


def test_the_table_behind_a_top_that_the_others_confirm_with_its_grain_is_not_taken(printed_scene):
    """An oak-coloured box on oak, from the images alone: from one view a stretch of lit oak beyond the box's
    top, up the plane's normal, is of the oak's colour and light, and the colour models, holding the top,
    took it (0.781), though the other views see its table point and confirm its colour and its grain. Above
    a top the object ends: a stretch there that the others confirm, grain and all, is the table behind."""
    ious = _printed_scene_ious(printed_scene, 2, "oak-table-colour-box", backgrounds=False)
    assert ious[2] > 0.85, ious


def test_the_cast_shadow_no_view_confirms_is_dropped_where_the_fitted_lamp_puts_it(printed_scene):
    """A dark can on a dark rubber mat, from the images alone: two views each see the stretch of the can's
    shadow that the other has behind the can, and the third has it all behind the can, so no view confirms
    either stretch through the plane; the can is of its shadow's colour, and both views kept their shadow
    (0.857 and 0.728). The lamp is one and distant: its light, fitted so that the can's upper part, projected
    along it, casts the silhouettes' low part beyond the can's footprint and not the lit mat the views
    confirm, puts the shadow on the mat, and what of it no part of the can stands in front of is the mat."""
    ious = _printed_scene_ious(printed_scene, 18, "rubber-mat-dark-can", backgrounds=False)
    assert ious[0] > 0.9 and ious[2] > 0.9, ious


def _standing_column() -> tuple[np.ndarray, np.ndarray]:
    """A column's tall voxels on a plane grid of unit cells: feet at cells (50..52, 50..52), heights 5 to 10."""
    feet = np.array([(x, y) for x in range(50, 53) for y in range(50, 53)] * 6, np.int64)
    heights = np.repeat(np.arange(5.0, 11.0), 9)
    return feet, heights


def test_the_lamp_is_fitted_to_the_shadow_beyond_the_footprint_and_not_to_the_lit_table():
    """Under a lamp at azimuth 0 and 45 degrees up, the column's top (height 10) casts its shadow 10 cells
    towards -x: the shadow beyond its footprint covers x = 40..49; the table lit beyond the shadow's end
    (x = 30..39) and on the lamp's side (x = 53..60) is not shadow. Each unit of height moves the shadow
    by (-1, 0)."""
    from robocell.core_cy.auto_segment import _light_fitted

    feet, heights = _standing_column()
    shown = np.array([(x, y) for x in range(40, 50) for y in range(50, 53)], np.int64)
    lit = np.array([(x, y) for x in [*range(30, 40), *range(53, 61)] for y in range(46, 57)], np.int64)
    offset = _light_fitted(feet, heights, shown, lit, side=101, cell=1.0)
    assert offset is not None and np.allclose(offset, [-1.0, 0.0], atol=1e-9), offset


def test_no_lamp_is_fitted_to_a_low_ring_round_the_footprint():
    """A low part all round the column's footprint (a wide base, not a shadow) is no one lamp's shadow: a
    shadow falls to one side. No light explains half of it."""
    from robocell.core_cy.auto_segment import _light_fitted

    feet, heights = _standing_column()
    ring = np.array([(x, y) for x in range(45, 58) for y in range(45, 58)
                     if max(abs(x - 51), abs(y - 51)) >= 4], np.int64)
    lit = np.array([(x, y) for x in range(20, 83) for y in range(20, 83)
                    if max(abs(x - 51), abs(y - 51)) >= 8], np.int64)
    assert _light_fitted(feet, heights, ring, lit, side=101, cell=1.0) is None


def test_no_lamp_is_fitted_to_a_hull_that_a_view_missing_the_object_carved_short(printed_scene):
    """A box of its oak table's colour, from the images alone: one view's colour models gave most of the box
    to the table (0.37; it misses 0.80 of the other views' hull), and the hull it carved holds only part of
    the box. Another view's face in shade beyond that part lies low under the hull, where a shadow taken in
    would, and a lamp fitted to it (azimuth 335 degrees, elevation 48; the scene's lamp 272, 66) dropped it
    (0.954 fell to 0.867). A view that misses much of the other views' hull says the hull's tall part is not
    the object's: no lamp is fitted to it."""
    ious = _printed_scene_ious(printed_scene, 82, "oak-table-colour-box", backgrounds=False)
    assert ious[1] > 0.91, ious

