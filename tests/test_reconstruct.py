"""The whole algorithm on exact scenes and on simulated scans, scored against the truth."""

import dataclasses

import cv2
import numpy as np
import pytest

from robocell.wire.bundle import load_bundle
from robocell.workers.sim.objects import box, cylinder, ellipsoid, rounded_box
from robocell.workers.sim.scans import BROAD_FAMILIES, default_K, plan_views, write_scan
from robocell.core_cy.errors import CoreError, GeometryError, ImageError, SilhouetteError
from robocell.core_cy.plan import look_at
from robocell.core_cy.reconstruct import Options, View, reconstruct
from robocell.core_cy.scoring import volumetric_iou
from robocell.core_cy.segment import RED_HSV
from robocell.core_cy.superquadric import Superquadric

from tests.bundles import SPHERE_CENTRE, SPHERE_RADIUS, write_sphere_bundle


def _run(bundle_dir, **kwargs):
    bundle = load_bundle(bundle_dir)
    return reconstruct(bundle.views, **{"segmentation": bundle.segmentation, "support_plane": bundle.support_plane,
                                        **kwargs})


def _truth(bundle_dir):
    return Superquadric.from_dict(__import__("json").loads((bundle_dir / "truth.json").read_text()))


def test_sphere_on_the_table(sphere_bundle):
    result = _run(sphere_bundle)
    fit = result.superquadric
    assert volumetric_iou(fit, _truth(sphere_bundle)) > 0.85
    np.testing.assert_allclose(fit.T_world_object[:3, 3], SPHERE_CENTRE, atol=0.1 * SPHERE_RADIUS)
    assert min(result.silhouette_iou) > 0.9
    # Every carved point is on or outside the sphere: the hull contains the object.
    distances = np.linalg.norm(result.points - SPHERE_CENTRE, axis=1)
    assert distances.min() > SPHERE_RADIUS * 0.97
    assert set(result.timings_ms) == {"decode", "segment", "edges", "centroid", "carve", "start", "fit", "quality",
                                      "total"}


def test_units_do_not_matter(tmp_path, sphere_bundle):
    metres = _run(sphere_bundle).superquadric
    millimetres = _run(write_sphere_bundle(tmp_path / "mm", scale=1000.0)).superquadric
    np.testing.assert_allclose(np.sort(millimetres.size), np.sort(metres.size) * 1000, rtol=0.02)
    np.testing.assert_allclose(millimetres.T_world_object[:3, 3], metres.T_world_object[:3, 3] * 1000,
                               atol=0.5)


def test_supplied_masks_give_the_same_answer(tmp_path, sphere_bundle):
    # The images segmented by the colour that names the object: the same silhouettes as the masks.
    from_images = _run(sphere_bundle, segmentation=RED_HSV).superquadric
    from_masks = _run(write_sphere_bundle(tmp_path / "masks", masks=True)).superquadric
    assert volumetric_iou(from_images, from_masks) > 0.98


def test_auto_on_a_sphere_on_a_plain_table_is_one_part(sphere_bundle):
    # Once a known limit (beside the sphere's foot auto took for object the table under its overhang, which
    # no other view sees, and the fit added a flat part: 0.94): the first look's pieces now take in their
    # own colour, hiding that table from the other views.
    result = _run(sphere_bundle)  # the bundle names no segmentation: auto
    assert len(result.parts) == 1 and volumetric_iou(result.superquadric, _truth(sphere_bundle)) > 0.95


def test_two_views_are_enough(sphere_bundle):
    bundle = load_bundle(sphere_bundle)
    result = reconstruct(bundle.views[:2], support_plane=bundle.support_plane)
    assert volumetric_iou(result.superquadric, _truth(sphere_bundle)) > 0.7


FAMILIES = {
    "box": lambda: box([0.05, 0.03, 0.025], [0.6, 0.02], yaw_deg=25),
    "cylinder": lambda: cylinder([0.03, 0.03, 0.06], [0.58, -0.03], yaw_deg=0),
    "ellipsoid": lambda: ellipsoid([0.045, 0.035, 0.03], [0.62, 0.0], yaw_deg=60),
    "rounded-box": lambda: rounded_box([0.04, 0.04, 0.03], [0.6, 0.05], yaw_deg=-30),
    "lying-cylinder": lambda: cylinder([0.025, 0.025, 0.07], [0.6, 0.0], yaw_deg=-40, lying=True),
    # The broad benchmark's own families, drawn as it draws them.
    "flat-box": lambda: BROAD_FAMILIES["flat-box"](np.random.default_rng(11), (0.6, 0.0), 20.0),
    "standing plate": lambda: BROAD_FAMILIES["plate"](np.random.default_rng(12), (0.6, 0.0), 70.0),
}


@pytest.mark.parametrize("family", FAMILIES)
def test_simulated_objects_against_the_truth(tmp_path, family):
    obj = FAMILIES[family]()
    target = obj.T_world_object[:3, 3]
    # Cameras anywhere from 20 to 60 degrees up, a dim shaded side, JPEG at 80.
    cameras = plan_views(target, elevation_deg=(20.0, 60.0), rng=np.random.default_rng(3))
    bundle = write_scan(tmp_path / family, [obj], cameras, default_K(), seed=3, jpeg_quality=80, ambient=0.2)
    result = _run(bundle)
    assert volumetric_iou(result.superquadric, Superquadric.from_dict(obj.truth())) > 0.95
    assert min(result.silhouette_iou) > 0.9  # a thin object seen edge-on is a few pixels wide


def test_views_along_one_line_leave_the_object_s_depth_to_the_fit(tmp_path):
    """Three views from one side, along a box's length, a degree or two apart: the enclosing sphere's radius
    says how far the box reaches across their lines of sight, not along them, and the fit, from the views'
    little spread, finds the length beyond it (held within the radius, 0.78)."""
    obj = box([0.07, 0.03, 0.025], (0.6, 0.0))
    target = obj.T_world_object[:3, 3]
    poses = [look_at(target + 0.4 * np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                                              np.sin(elevation)]), target)
             for azimuth, elevation in np.radians([(179.0, 10.0), (180.0, 11.0), (181.0, 12.0)])]
    result = _run(write_scan(tmp_path / "along", [obj], poses, default_K(), seed=3, write_masks=True, name_masks=True))
    assert max(result.superquadric.size) > result.radius
    assert volumetric_iou(result.superquadric, Superquadric.from_dict(obj.truth())) > 0.9


def test_distorted_lens(tmp_path):
    obj = FAMILIES["box"]()
    truth = Superquadric.from_dict(obj.truth())
    # Aimed beside the object, so that it sits where the lens bends most.
    cameras = plan_views(obj.T_world_object[:3, 3] + [0.08, 0.0, 0.06], distance=(0.4, 0.45),
                         rng=np.random.default_rng(5))
    dist = [-0.3, 0.1, 0.0, 0.0, 0.0]
    bundle = write_scan(tmp_path / "distorted", [obj], cameras, default_K(), dist=dist, seed=5)
    handled = volumetric_iou(_run(bundle).superquadric, truth)
    assert handled > 0.78
    assert volumetric_iou(_run_without_distortion(bundle), truth) < handled - 0.02


def _run_without_distortion(bundle_dir):
    bundle = load_bundle(bundle_dir)
    views = [View(type(v.camera)(K=v.camera.K, T_world_cam=v.camera.T_world_cam), image=v.image)
             for v in bundle.views]
    return reconstruct(views, segmentation=bundle.segmentation, support_plane=bundle.support_plane).superquadric


# --- bad input ---------------------------------------------------------------------------------


def test_fewer_than_two_views(sphere_bundle):
    bundle = load_bundle(sphere_bundle)
    with pytest.raises(GeometryError, match="need at least 2 views, got 1"):
        reconstruct(bundle.views[:1])


def test_corrupt_and_truncated_jpeg(sphere_bundle):
    bundle = load_bundle(sphere_bundle)
    views = list(bundle.views)
    views[1] = View(views[1].camera, image=views[1].image[: len(views[1].image) // 2])
    with pytest.raises(ImageError, match="^view 1: the JPEG is truncated"):
        reconstruct(views)
    views[1] = View(views[1].camera, image=b"definitely not an image")
    with pytest.raises(ImageError, match="^view 1: the image is not a decodable image"):
        reconstruct(views)


def test_empty_silhouette_names_the_view(sphere_bundle):
    bundle = load_bundle(sphere_bundle)
    views = list(bundle.views)
    grey = cv2.imencode(".jpg", np.full((480, 640, 3), 128, np.uint8))[1].tobytes()
    views[2] = View(views[2].camera, image=grey)
    with pytest.raises(SilhouetteError, match="^view 2: the silhouette is empty"):
        reconstruct(views, segmentation=RED_HSV)


def test_support_plane_above_the_object(sphere_bundle):
    bundle = load_bundle(sphere_bundle)
    with pytest.raises(GeometryError, match="under the table"):
        reconstruct(bundle.views, support_plane=[0, 0, 1, -0.5])


def test_poses_that_disagree_about_the_object(sphere_bundle):
    bundle = load_bundle(sphere_bundle)
    views = list(bundle.views)
    flipped = views[0].camera.T_world_cam.copy()
    flipped[:3, :3] = flipped[:3, :3] @ np.diag([-1.0, -1.0, 1.0])  # rolled half a turn: still rigid
    flipped[:3, 3] += [0.3, -0.3, 0.0]
    views[0] = View(type(views[0].camera)(K=views[0].camera.K, T_world_cam=flipped, view=0), image=views[0].image)
    with pytest.raises(CoreError, match="view"):
        reconstruct(views, segmentation=RED_HSV)


def test_options_are_checked():
    with pytest.raises(ValueError, match="n_points"):
        Options(n_points=3)


def test_a_box_of_its_oak_table_s_colour_is_held_by_its_true_edges(printed_scene):
    """A box cut from its oak table's own wood, images and the support plane only: one view's silhouette took
    in a strip of lit table beside the box's foot, whose false edge has table on both sides, while the
    box's true edges, beside its faces in shade, were unsure. The fit followed the strip (0.930 before,
    against the true object by the simulator's judge); an outline across which the image shows no step
    is unsure too, and the true edges hold the model (issue 20)."""
    assert _judged_from_images(printed_scene, 0, "oak-table-colour-box") > 0.95


def _judged_from_images(printed_scene, seed: int, name: str) -> float:
    """The volumetric IoU of the model of one of the simulator's printed scenes (the ``printed_scene``
    fixture), reconstructed from its images and the support plane alone, against the true object by the
    simulator's judge (workers/sim/judge.py, written apart from the fit)."""
    from robocell.workers.sim.judge import Part, parts_from_truth, union_iou

    spec, directory = printed_scene(seed, name)
    bundle = load_bundle(directory)
    views = [dataclasses.replace(view, background=None) for view in bundle.views]  # the images alone
    result = reconstruct(views, segmentation=bundle.segmentation, support_plane=bundle.support_plane)
    parts = [Part.from_dict(part.to_dict()) for part in result.parts]
    return union_iou(parts, parts_from_truth(spec.objects[0].truth()))


def test_a_thin_strip_of_foot_shadow_that_the_views_contradict_does_not_pull_the_fit(printed_scene):
    """A white box on white laminate, images and the support plane only: the box's faces in shade and its
    shadow are alike, so the samples along its lower outline are doubtful, and the views took in a thin strip
    of the shadow at the box's foot (its samples 5-7 px outside the true outline in two views, 2 in the
    third). The fading loss still pulls at a few pixels, the views agreed, and the model followed them
    half-way (0.914 against the true object by the simulator's judge). A doubtful sample that the views
    contradict (over 3 px from the model they hold) has nothing left to speak for it and is set aside."""
    assert _judged_from_images(printed_scene, 16, "laminate-white-box") > 0.945


def _images_alone(printed_scene, seed: int, name: str):
    """A printed scene's bundle, its views from their images alone (no empty workspace), and its true
    silhouettes (0/255), one a view."""
    _, directory = printed_scene(seed, name)
    bundle = load_bundle(directory)
    views = [dataclasses.replace(view, background=None) for view in bundle.views]
    truths = [cv2.imread(str(directory / f"truth_mask{i}.png"), cv2.IMREAD_GRAYSCALE) for i in range(len(views))]
    return bundle, views, truths


def _auto_finds(monkeypatch, silhouettes) -> None:
    """Within ``reconstruct``, auto finds ``silhouettes`` (0/255, one a view) whatever the images show."""
    import robocell.core_cy.reconstruct as reconstruct_module
    from robocell.core_cy.segment import mask_with_outline

    monkeypatch.setattr(reconstruct_module, "auto_silhouettes", lambda images, cameras, **_: [
        mask_with_outline(mask, view=index) for index, mask in enumerate(silhouettes)])


def test_silhouettes_that_contradict_each_other_are_an_error_not_a_model_of_the_table(printed_scene, monkeypatch):
    """Two views that took in a stretch of table beside the object agree with each other on a slab over it,
    and against the third view, which found the object: a model fitted to the three agrees with none of them
    (a sheet 0.37 m long and a hundredth of a millimetre thick, 0.15 / 0.42 / 0.50 of its silhouettes, on a
    scene where auto did just that). It is an error saying so, not a model."""
    bundle, views, truths = _images_alone(printed_scene, 3, "oak-mustard-bottle")
    silhouettes = [truth.copy() for truth in truths]
    for mask in silhouettes[1:]:  # the table from the object's foot down to the image's bottom, the object within it
        ys, _ = np.nonzero(mask)
        mask[int(ys.max()) - 5:, :] = 255
        mask[int(ys.min()):, int(0.2 * mask.shape[1]):int(0.8 * mask.shape[1])] = 255
    _auto_finds(monkeypatch, silhouettes)
    with pytest.raises(SilhouetteError, match=r"^the views' silhouettes contradict each other: the model agrees "
                                              r"with them only [0-9.]+, [0-9.]+, [0-9.]+ \(at least 0.3"):
        reconstruct(views, segmentation=bundle.segmentation, support_plane=bundle.support_plane)
    monkeypatch.undo()
    # The same views with the silhouettes auto finds: a model, as before.
    assert reconstruct(views, segmentation=bundle.segmentation, support_plane=bundle.support_plane).parts


def test_a_silhouette_found_apart_from_the_others_is_an_error_naming_its_view_not_blaming_the_poses(
        printed_scene, monkeypatch):
    """One view's silhouette, found in its image, is a patch of table beside the object (an object of the
    table's colour it could not tell): the views disagree about where the object is. The poses are right;
    the error names the view whose silhouette was found apart and says what to give, where it blamed the
    poses. The same silhouettes given as masks are the user's own: the poses are what to check."""
    bundle, views, truths = _images_alone(printed_scene, 3, "oak-mustard-bottle")
    beside = np.zeros_like(truths[1])
    ys, xs = np.nonzero(truths[1])
    beside[int(ys.max()) + 40:int(ys.max()) + 70, int(xs.max()) + 40:int(xs.max()) + 80] = 255  # table only
    silhouettes = [truths[0], beside, *truths[2:]]
    _auto_finds(monkeypatch, silhouettes)
    with pytest.raises(SilhouetteError, match=r"^view 1: the views disagree about where the object is: .*silhouette"
                                              r" found in this view's image may have missed the object: give the "
                                              r"views pictures of the empty workspace, or masks"):
        reconstruct(views, segmentation=bundle.segmentation, support_plane=bundle.support_plane)
    as_masks = [View(view.camera, mask=cv2.imencode(".png", mask)[1].tobytes())
                for view, mask in zip(views, silhouettes)]
    with pytest.raises(GeometryError, match=r"^view 1: the views disagree .*check the poses' direction"):
        reconstruct(as_masks, support_plane=bundle.support_plane)

