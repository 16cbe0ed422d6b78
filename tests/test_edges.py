"""Edge samples: points on a silhouette's outline, placed to a fraction of a pixel."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robocell.core_cy.camera import Camera
from robocell.core_cy.edges import edge_samples, silhouette_outline
from robocell.core_cy.segment import segment_with_outline

RED, TABLE = np.array([30.0, 30.0, 200.0]), np.array([150.0, 170.0, 180.0])


def _square_scene(angle_deg: float, centre=(160.3, 120.7), half=50.0):
    """A red square turned by ``angle_deg`` on a pale table, each pixel (centres on integers) the
    mix of the two colours by the exact share of it the square covers; returns the BGR image, the
    square's corners and a function giving the signed distance (px, positive outside) of points
    from its true outline."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    corners = (np.array([[-half, -half], [half, -half], [half, half], [-half, half]]) @ [[c, s], [-s, c]]
               + centre).astype(np.float32)
    rows, cols = np.mgrid[0:240, 0:320]
    du, dv = cols - centre[0], rows - centre[1]
    # A pixel whose centre lies more than a pixel inside (outside) every side is covered (not at all).
    depth = half - np.maximum(np.abs(du * c + dv * s), np.abs(-du * s + dv * c))
    coverage = (depth > 1.0).astype(np.float64)[..., None]
    for row, col in zip(*np.nonzero(np.abs(depth) <= 1.0)):
        pixel = np.array([[col - 0.5, row - 0.5], [col + 0.5, row - 0.5], [col + 0.5, row + 0.5],
                          [col - 0.5, row + 0.5]], np.float32)
        coverage[row, col] = cv2.intersectConvexConvex(pixel, corners)[0]

    image = np.clip(coverage * RED + (1 - coverage) * TABLE, 0, 255).round().astype(np.uint8)

    def distance(uv):
        return np.array([-cv2.pointPolygonTest(corners, (float(u), float(v)), True) for u, v in uv])

    return image, corners, distance


@pytest.mark.parametrize("angle", [0.0, 17.0, 45.0])
def test_samples_sit_on_the_true_edge_to_a_tenth_of_a_pixel(angle):
    image, corners, distance = _square_scene(angle)
    silhouette, outline = segment_with_outline(image)
    samples = edge_samples(outline, silhouette, image, count=64)
    assert len(samples) == 64
    # Away from the corners (which anti-aliasing rounds), every sample is on the edge. Reading the
    # crossing between pixel centres misses it by up to 1/8 px where nothing but the pixels' own
    # area blurs the edge (as here); a lens blurs more, and the error shrinks.
    errors = distance(samples)
    on_sides = np.linalg.norm(samples[:, None] - corners[None], axis=2).min(axis=1) > 3.0
    assert on_sides.mean() > 0.8
    assert np.abs(errors[on_sides]).max() < 0.1
    assert np.abs(errors[on_sides].mean()) < 0.03
    # The segmented outline alone is off by up to a pixel: what the samples gain.
    assert np.abs(distance(outline)).max() > 0.4


def test_an_edge_placed_on_the_image_s_step_keeps_it_where_the_image_shows_another():
    """A silhouette whose edge was placed on the image's own step (``auto`` places it so) is refined by
    the image where the two agree, to the image's precision, and kept where the image's nearest
    crossing is another step (a print, a shadow): here the square's left side is printed with a white band
    from 2 px inside its edge, and the crossing between the table's colour and the band's is the band's."""
    image, corners, distance = _square_scene(0.0)
    silhouette, outline = segment_with_outline(image)
    left = int(round(corners[:, 0].min()))
    printed = image.copy()
    printed[70:170, left + 2:left + 12] = 255  # a white band, away from the corners
    samples = {on_edge: edge_samples(outline, silhouette, printed, count=64, on_edge=on_edge)
               for on_edge in (False, True)}
    band = (samples[True][:, 0] < left + 1) & (samples[True][:, 1] > 75) & (samples[True][:, 1] < 165)
    assert band.sum() >= 4
    assert np.abs(distance(samples[False][band])).min() > 1.0  # the image alone takes the band's step
    assert np.abs(distance(samples[True][band])).max() < 0.55  # the silhouette's own edge, to its pixel
    # On the other sides the image's crossing agrees, and is kept: as precise as without the silhouette's say.
    others = np.linalg.norm(samples[True][:, None] - corners[None], axis=2).min(axis=1) > 3.0
    others &= samples[True][:, 0] > left + 10
    assert others.sum() > 30
    assert np.array_equal(samples[True][others], samples[False][others])
    assert np.abs(distance(samples[True][others])).max() < 0.1


def test_a_mask_is_read_half_way_between_its_pixels():
    mask = np.zeros((60, 80), np.uint8)
    mask[10:40, 20:61] = 255
    samples = edge_samples(silhouette_outline(mask), mask, count=20)
    on_edge = (np.isclose(samples[:, 0], 19.5, atol=0.02) | np.isclose(samples[:, 0], 60.5, atol=0.02)
               | np.isclose(samples[:, 1], 9.5, atol=0.02) | np.isclose(samples[:, 1], 39.5, atol=0.02))
    assert on_edge.mean() > 0.75  # the rest sit on the blurred corners


def test_samples_on_the_image_border_are_dropped():
    mask = np.zeros((60, 80), np.uint8)
    mask[0:30, 20:60] = 255  # cut off by the top border
    samples = edge_samples(silhouette_outline(mask), mask, count=40)
    # None lies on the cut at the top; those near it belong to the sides.
    assert len(samples) < 40 and samples[:, 1].min() > 1.5


def test_distorted_views_give_samples_of_the_ideal_camera():
    mask = np.zeros((240, 320), np.uint8)
    cv2.circle(mask, (220, 160), 40, 255, -1)
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    camera = Camera(K=K, T_world_cam=np.eye(4), dist=[-0.2, 0.05, 0, 0, 0])
    raw = edge_samples(silhouette_outline(mask), mask, count=16)
    ideal = edge_samples(silhouette_outline(mask), mask, count=16, camera=camera)
    expected = cv2.undistortPoints(raw.reshape(-1, 1, 2), K, camera.dist, P=K).reshape(-1, 2)
    np.testing.assert_allclose(ideal, expected, atol=1e-9)
    assert np.abs(ideal - raw).max() > 1.0  # the lens moved them


def test_too_short_an_outline_gives_no_samples():
    assert edge_samples(np.array([[5, 5], [6, 5], [6, 6]]), np.zeros((10, 10), np.uint8)).shape == (0, 2)
