"""The shrink step on a sphere seen by three ideal cameras, against answers worked out by hand."""

import cv2
import numpy as np
import pytest

from robocell.core_cy.carve import carve, check_support_plane, clip_to_plane, lift_above_plane, occupancy
from robocell.core_cy.errors import GeometryError
from robocell.core_cy.sphere import enclosing_sphere, fibonacci_sphere

from tests.helpers import orthogonal_cameras, sphere_silhouette

CENTRE = np.array([0.6, 0.05, 0.1])
RADIUS = 0.05
DISTANCE = 0.5


@pytest.fixture(scope="module")
def scene():
    cameras = orthogonal_cameras(CENTRE, DISTANCE)
    silhouettes = [sphere_silhouette(camera, CENTRE, RADIUS) for camera in cameras]
    return cameras, silhouettes


def test_enclosing_sphere_finds_the_centre_and_encloses(scene):
    cameras, silhouettes = scene
    centre, radius = enclosing_sphere(silhouettes, cameras)
    # Pixel-centre sampling moves each silhouette's centroid by well under a pixel (0.001 here).
    np.testing.assert_allclose(centre, CENTRE, atol=2e-4)
    # The bounding box corners of a disc lie sqrt(2) further out than its rim.
    assert RADIUS * 1.25 <= radius <= RADIUS * 1.25 * np.sqrt(2) * 1.05


def test_carving_along_the_axes_meets_the_tangent_cones(scene):
    # Along +x the sphere is bounded by the cameras on the y and z axes; each sees the sphere's
    # tangent cone, which crosses the x direction at D r / sqrt(D^2 - r^2) from the centre.
    cameras, silhouettes = scene
    axes = np.vstack([np.eye(3), -np.eye(3)])
    radii, observed = carve(axes, CENTRE, 2 * RADIUS, cameras, [occupancy(s) for s in silhouettes])
    assert observed.all()
    expected = DISTANCE * RADIUS / np.sqrt(DISTANCE**2 - RADIUS**2)
    # Half a pixel at this depth is 0.5 * 0.5 / 600 = 0.0004.
    np.testing.assert_allclose(radii, expected, atol=4e-4)


def test_carved_points_lie_on_the_visual_hull(scene):
    cameras, silhouettes = scene
    directions = fibonacci_sphere(500)
    radii, _ = carve(directions, CENTRE, 2 * RADIUS, cameras, [occupancy(s) for s in silhouettes])
    points = CENTRE + radii[:, None] * directions
    # Outside the sphere (the hull contains the object) ...
    assert np.all(np.linalg.norm(points - CENTRE, axis=1) >= RADIUS - 4e-4)
    # ... inside or on every silhouette, and on the edge of at least one: the hull is tight.
    edge_distance = []
    for camera, silhouette in zip(cameras, silhouettes):
        uv, _ = camera.project(points)
        contour = max(cv2.findContours(silhouette, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0],
                      key=len).astype(np.float32)
        signed = np.array([cv2.pointPolygonTest(contour, (float(u), float(v)), True) for u, v in uv])
        assert signed.min() > -1.0  # no point more than a pixel outside a silhouette
        edge_distance.append(np.abs(signed))
    assert np.max(np.min(edge_distance, axis=0)) < 1.0


def test_points_out_of_the_image_are_not_carved_by_that_view(scene):
    cameras, silhouettes = scene
    # Straight up from the centre is on camera 2's optical axis; a huge start radius takes it
    # behind that camera and far outside the others' images: nobody may carve it.
    radii, observed = carve([[0.0, 0.0, 1.0]], CENTRE, 10.0, cameras, [occupancy(s) for s in silhouettes])
    assert radii[0] == 10.0 and not observed[0]


def test_support_plane_pulls_points_back_onto_the_table():
    directions = np.array([[0.0, 0.0, -1.0], [0.6, 0.0, -0.8], [0.0, 0.0, 1.0]])
    centre = np.array([0.0, 0.0, 0.03])
    plane = check_support_plane([0, 0, 2.0, 0], centre)  # any normal length
    radii = clip_to_plane(directions, np.full(3, 0.1), centre, plane)
    np.testing.assert_allclose(radii, [0.03, 0.0375, 0.1])


def test_support_plane_above_the_object_is_an_error():
    with pytest.raises(GeometryError, match="under the table"):
        check_support_plane([0, 0, 1, -0.2], [0.6, 0.0, 0.05])
    with pytest.raises(GeometryError, match="normal"):
        check_support_plane([0, 0, 0, 1], [0.6, 0.0, 0.05])


def test_a_centre_a_little_below_the_plane_is_a_flat_object_lifted_onto_it():
    table = [0.0, 0.0, 1.0, 0.0]
    plane = check_support_plane(table, [0.6, 0.0, -0.002], radius=0.1)  # 2 % of the radius: a low centre
    centre = lift_above_plane([0.6, 0.0, -0.002], 0.1, plane)
    assert plane[:3] @ centre + plane[3] > 0
    with pytest.raises(GeometryError, match="under the table"):  # half the radius: the plane is wrong
        check_support_plane(table, [0.6, 0.0, -0.05], radius=0.1)


def test_parallel_views_are_an_error():
    cameras = orthogonal_cameras(CENTRE, DISTANCE)[:1] * 2
    silhouettes = [sphere_silhouette(cameras[0], CENTRE, RADIUS)] * 2
    with pytest.raises(GeometryError, match="parallel"):
        enclosing_sphere(silhouettes, cameras)
