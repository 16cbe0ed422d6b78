import cv2
import numpy as np
import pytest

from robocell.core_cy.camera import Camera, undistort_mask
from robocell.core_cy.errors import CameraError

from tests.helpers import intrinsics, look_at, sphere_silhouette


def test_target_projects_to_the_principal_point():
    camera = Camera(K=intrinsics(), T_world_cam=look_at([0.3, -0.4, 0.5], [0.6, 0.0, 0.05]))
    uv, depth = camera.project([[0.6, 0.0, 0.05]])
    np.testing.assert_allclose(uv[0], [319.5, 239.5], atol=1e-9)
    np.testing.assert_allclose(depth[0], np.linalg.norm([0.3, 0.4, -0.45]))


def test_opencv_axes_x_right_y_down():
    # Camera at the origin looking along world +z with identity pose: world +x is image right,
    # world +y is image down.
    camera = Camera(K=intrinsics(), T_world_cam=np.eye(4))
    uv, _ = camera.project([[0.1, 0.0, 1.0], [0.0, 0.1, 1.0]])
    np.testing.assert_allclose(uv, [[319.5 + 60, 239.5], [319.5, 239.5 + 60]])


def test_project_and_pixel_rays_round_trip():
    rng = np.random.default_rng(3)
    camera = Camera(K=[[610, 0.5, 330], [0, 590, 250], [0, 0, 1]],
                    T_world_cam=look_at([0.5, 0.5, 0.6], [0.6, 0.0, 0.0]))
    points = rng.uniform([0.5, -0.1, 0.0], [0.7, 0.1, 0.1], size=(50, 3))
    uv, depth = camera.project(points)
    rays = camera.pixel_rays(uv)
    to_points = points - camera.center
    np.testing.assert_allclose(to_points, rays * np.linalg.norm(to_points, axis=1, keepdims=True), atol=1e-12)
    assert np.all(depth > 0)


def test_units_do_not_matter():
    pose = look_at([0.3, -0.4, 0.5], [0.6, 0.0, 0.05])
    millimetres = pose.copy()
    millimetres[:3, 3] *= 1000
    point = np.array([[0.62, 0.01, 0.07]])
    uv_m, _ = Camera(K=intrinsics(), T_world_cam=pose).project(point)
    uv_mm, _ = Camera(K=intrinsics(), T_world_cam=millimetres).project(point * 1000)
    np.testing.assert_allclose(uv_m, uv_mm, atol=1e-9)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(K=np.eye(2)), "K must have shape (3, 3)"),
        (dict(K=[[600, 0, 320], [0, np.nan, 240], [0, 0, 1]]), "K contains NaN"),
        (dict(K=[[-600, 0, 320], [0, 600, 240], [0, 0, 1]]), "fx, fy > 0"),
        (dict(T_world_cam=np.diag([2.0, 2.0, 2.0, 1.0])), "not orthonormal"),
        (dict(T_world_cam=np.diag([1.0, 1.0, -1.0, 1.0])), "reflection (determinant < 0)"),
        (dict(T_world_cam=np.zeros((4, 4))), "last row"),
        (dict(T_world_cam=np.full((4, 4), np.nan)), "T_world_cam contains NaN"),
        (dict(dist=[0.1, 0.2, 0.3]), "dist must have one of"),
    ],
)
def test_malformed_matrices_are_named(change, message):
    arguments = dict(K=intrinsics(), T_world_cam=np.eye(4), view=2) | change
    with pytest.raises(CameraError, match="^view 2: ") as info:
        Camera(**arguments)
    assert message in str(info.value)
    assert info.value.view == 2


def test_zero_distortion_is_no_distortion():
    assert Camera(K=intrinsics(), T_world_cam=np.eye(4), dist=[0, 0, 0, 0, 0]).dist is None


def test_undistort_mask_recovers_the_ideal_silhouette():
    K = intrinsics()
    dist = np.array([-0.25, 0.08, 0.001, -0.002, 0.0])
    pose = look_at([0.0, -0.5, 0.3], [0.25, 0.1, 0.12])
    ideal_camera = Camera(K=K, T_world_cam=pose)
    ideal = sphere_silhouette(ideal_camera, [0.1, 0.1, 0.05], 0.06)
    # Distort: each distorted pixel shows what the ideal pixel at its undistorted position shows.
    rows, cols = np.mgrid[0:480, 0:640].astype(np.float32)
    undistorted = cv2.undistortPoints(np.stack([cols.ravel(), rows.ravel()], 1)[:, None], K, dist, P=K)
    map_xy = undistorted.reshape(480, 640, 2)
    distorted = cv2.remap(ideal, map_xy[..., 0], map_xy[..., 1], cv2.INTER_NEAREST)
    assert _iou(distorted, ideal) < 0.95  # the lens really bends this view

    recovered = undistort_mask(distorted, Camera(K=K, T_world_cam=pose, dist=dist))
    assert _iou(recovered, ideal) > 0.98


@pytest.mark.parametrize("dist", [
    [-0.45, 0.25, 0.0, 0.0, -0.08],               # strong barrel (a 100-degree lens)
    [0.05, -0.01, 0.002, -0.001],                   # mild pincushion, decentred
    [30.0, 20.0, 0.0, 0.0, 1.0, 30.5, 22.0, 2.0],   # the rational model: large terms that cancel
])
def test_real_lenses_distortion_is_accepted(dist):
    assert Camera(K=intrinsics(), T_world_cam=np.eye(4), dist=dist).dist is not None


@pytest.mark.parametrize("dist, moved", [
    ([1e300, 0, 0, 0, 0], "to infinity"),            # overflows once squared
    ([0, 0, 1e6, 0], "by up to 1.31e+06 times"),     # a tangential term in the wrong units
    ([-10.0, 0, 0, 0], "by up to 4.43 times"),       # the corners fold back through the centre
])
def test_distortion_no_lens_has_is_named(dist, moved):
    with pytest.raises(CameraError, match=r"^view 1: dist \[.*\] moves pixels of the image ") as info:
        Camera(K=intrinsics(), T_world_cam=np.eye(4), dist=dist, view=1)
    assert moved in str(info.value)


def test_undistortion_that_loses_the_silhouette_is_an_error_not_an_empty_view():
    mask = np.zeros((480, 640), np.uint8)
    mask[0:3, 0:3] = 255  # in the corner, where barrel distortion pulls the ideal image's edge from
    camera = Camera(K=intrinsics(), T_world_cam=np.eye(4), dist=[-0.4, 0, 0, 0], view=0)
    with pytest.raises(CameraError, match="^view 0: dist .* moves the whole silhouette out of the image"):
        undistort_mask(mask, camera)


def _iou(a, b):
    return np.count_nonzero(a & b) / np.count_nonzero(a | b)
