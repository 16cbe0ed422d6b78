"""The ``auto`` segmentation's kernel against plain NumPy on random inputs."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robocell.core_cy import auto_segment
from robocell.core_cy.camera import Camera

from robocell.core_cy._auto_segment_cy import (add_relit_grain, any_within, channel_sum, columns_meet_mask, median,
                                               median_and_spread, plane_homography_maps, project_into_mask,
                                               ratio_disagreement, shadow_like_pixels, shadow_look,
                                               windowed_correlation)


def _reference(values: np.ndarray) -> tuple[float, float] | None:
    finite = values[np.isfinite(values)]
    if not len(finite):
        return None
    median = float(np.median(finite))
    return median, float(np.median(np.abs(finite - median)))


def _evidence_like(rng: np.random.Generator, trial: int, dtype, finite: bool = False) -> np.ndarray:
    """Random values with ties (the many exact zeros of an evidence map) and, unless ``finite``, values
    that carry no evidence (NaN, infinity)."""
    values = rng.normal(size=int(rng.integers(1, 60))).astype(dtype)
    values[rng.random(len(values)) < 0.3 * (trial % 2)] = 0.0
    if not finite:
        values[rng.random(len(values)) < 0.1 * (trial % 3)] = np.nan
        values[rng.random(len(values)) < 0.1 * (trial % 5 == 0)] = np.inf
    return values


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_median_and_spread_is_numpys_median_of_the_finite_values(dtype):
    rng = np.random.default_rng(0)
    for trial in range(2000):
        values = _evidence_like(rng, trial, dtype)
        assert median_and_spread(values) == _reference(values)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_median_is_numpys_and_leaves_its_input_alone(dtype):
    rng = np.random.default_rng(1)
    for trial in range(500):
        values = _evidence_like(rng, trial, dtype, finite=True)
        before = values.copy()
        assert median(values) == float(np.median(values))
        np.testing.assert_array_equal(values, before)
    with pytest.raises(ValueError):
        median(np.zeros(0))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_median_of_whole_numbers_is_numpys(dtype):
    # Whole numbers (a grey image filtered by an integer kernel) are counted, not selected: many ties, odd and
    # even counts, one value, a large one, and a fraction or a negative zero among them (selected again).
    rng = np.random.default_rng(3)
    for trial in range(500):
        values = rng.integers(0, [3, 40, 5000][trial % 3], size=int(rng.integers(1, 80))).astype(dtype)
        if trial % 7 == 0:
            values[rng.integers(len(values))] = 65535.0
        if trial % 11 == 0:
            values[rng.integers(len(values))] = [0.5, -0.0, 65536.0][trial % 3]
        before = values.copy()
        found = median(values)
        assert found == float(np.median(values))
        assert np.signbit(found) == np.signbit(np.median(values))
        np.testing.assert_array_equal(values, before)


def test_median_and_spread_of_nothing_finite_is_none():
    assert median_and_spread(np.array([np.nan, np.inf, -np.inf], np.float32)) is None
    assert median_and_spread(np.zeros(0)) is None


def test_median_and_spread_by_hand():
    # Sorted: 0, 1, 2, 4 -> median 1.5; distances 1.5, 0.5, 0.5, 2.5 -> median 1.0.
    assert median_and_spread(np.array([4.0, np.nan, 0.0, 2.0, 1.0])) == (1.5, 1.0)


def test_plane_homography_maps_is_the_numpy_formula_on_random_homographies():
    rng = np.random.default_rng(0)
    for _ in range(50):
        H, across = rng.normal(size=(3, 3)), rng.normal(size=3)
        height, column0, row0 = float(rng.normal()), int(rng.integers(0, 50)), int(rng.integers(0, 50))
        unit = rng.uniform(0.5, 4.0, size=2)
        maps = np.empty((int(rng.integers(1, 30)), int(rng.integers(1, 30)), 2), np.float32)
        valid = np.empty(maps.shape[:2], np.uint8)
        plane_homography_maps(H, across, height, column0, row0, unit[0], unit[1], maps, valid)
        i = np.arange(column0, column0 + maps.shape[1], dtype=np.float64)[None, :]
        j = np.arange(row0, row0 + maps.shape[0], dtype=np.float64)[:, None]
        x, y, z = (H[k, 0] * i + H[k, 1] * j + H[k, 2] for k in range(3))
        meets = across[0] * i + across[1] * j + across[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -height / meets
            expected_valid = np.isfinite(t) & (t > 0) & (z / meets > 0)
            expected_u = ((x / z + 0.5) / unit[0] - 0.5).astype(np.float32)
            expected_v = ((y / z + 0.5) / unit[1] - 0.5).astype(np.float32)
        np.testing.assert_array_equal(valid.astype(bool), expected_valid)
        np.testing.assert_array_equal(maps[..., 0], expected_u)
        np.testing.assert_array_equal(maps[..., 1], expected_v)


def test_plane_homography_maps_of_the_identity_by_hand():
    # H the identity, the plane met everywhere (n . d = 1 > 0 with height -1): each pixel maps onto
    # itself; in units of 2 px, pixel 3 (centre on 3) is at (3 + 0.5) / 2 - 0.5 = 1.25.
    maps = np.empty((1, 2, 2), np.float32)
    valid = np.empty((1, 2), np.uint8)
    plane_homography_maps(np.eye(3), np.array([0.0, 0.0, 1.0]), -1.0, 3, 5, 2.0, 1.0, maps, valid)
    assert maps.tolist() == [[[1.25, 5.0], [1.75, 5.0]]]
    assert valid.tolist() == [[1, 1]]


def test_project_into_mask_is_the_numpy_projection_and_lookup_on_random_points():
    rng = np.random.default_rng(0)
    for _ in range(30):
        projection = rng.normal(size=(3, 4))
        projection[2, 3] += 3.0  # most points in front of the camera, some behind
        points = rng.normal(size=(int(rng.integers(1, 400)), 3))
        mask = np.where(rng.random((int(rng.integers(1, 20)), int(rng.integers(1, 20)))) < 0.5, 255, 0).astype(np.uint8)
        sx, sy = rng.uniform(0.05, 0.3, size=2)
        n = len(points)
        pixels, seen = np.empty((n, 2), np.int64), np.empty(n, np.uint8)
        depth, hit = np.empty(n), np.empty(n, np.uint8)
        project_into_mask(points, projection, sx, sy, mask, pixels, seen, depth, hit)
        homogeneous = points @ projection[:, :3].T + projection[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = homogeneous[:, :2] / homogeneous[:, 2:]
        coarse = np.rint(np.column_stack([(uv[:, 0] + 0.5) / sx - 0.5, (uv[:, 1] + 0.5) / sy - 0.5]))
        height, width = mask.shape
        expected_seen = ((homogeneous[:, 2] > 0) & (coarse[:, 0] >= 0) & (coarse[:, 1] >= 0)
                         & (coarse[:, 0] < width) & (coarse[:, 1] < height))
        expected_hit = np.ones(n, bool)
        inside = coarse[expected_seen].astype(np.int64)
        expected_hit[expected_seen] = mask[inside[:, 1], inside[:, 0]] > 0
        np.testing.assert_allclose(depth, homogeneous[:, 2], rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(seen.astype(bool), expected_seen)
        np.testing.assert_array_equal(hit.astype(bool), expected_hit)
        np.testing.assert_array_equal(pixels[expected_seen], inside)


def _columns_meet_by_numpy(points, plane, projection, sx, sy, mask, shares):
    """Every sample of every column, projected and looked up one share after another."""
    normal = plane[:3]
    drop = points @ normal + plane[3]
    met = np.zeros(len(points), bool)
    height, width = mask.shape
    for share in shares:
        samples = points - (share * drop)[:, None] * normal
        homogeneous = samples @ projection[:, :3].T + projection[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            coarse = np.rint((homogeneous[:, :2] / homogeneous[:, 2:] + 0.5) / [sx, sy] - 0.5)
            seen = ((homogeneous[:, 2] > 0) & (coarse[:, 0] >= 0) & (coarse[:, 1] >= 0) & (coarse[:, 0] < width)
                    & (coarse[:, 1] < height))
        inside = coarse[seen].astype(np.int64)
        met[np.flatnonzero(seen)[mask[inside[:, 1], inside[:, 0]] > 0]] = True
    return met


def test_columns_meet_mask_is_every_sample_looked_up_on_random_columns():
    # Cameras over a table, masks of a few blobs (or none), columns from random points down to the table: some
    # far from the mask (passed over by its bounding box), some behind the camera in part.
    rng = np.random.default_rng(1)
    met_somewhere = missed_somewhere = 0
    for trial in range(40):
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        plane = np.append(normal, rng.normal())
        projection = rng.normal(size=(3, 4))
        projection[2, 3] += 2.0 * (trial % 4 != 0)  # every fourth camera has half the columns behind it
        mask = np.zeros((int(rng.integers(4, 40)), int(rng.integers(4, 40))), np.uint8)
        for _ in range(int(rng.integers(0, 4))):
            centre = (int(rng.integers(0, mask.shape[1])), int(rng.integers(0, mask.shape[0])))
            cv2.circle(mask, centre, int(rng.integers(0, 15)), 255, -1)
        sx, sy = rng.uniform(0.02, 0.3, size=2)
        points = rng.normal(size=(int(rng.integers(1, 500)), 3))
        shares = np.linspace(0.0, 1.0, int(rng.integers(1, 60)))
        met = np.empty(len(points), np.uint8)
        columns_meet_mask(points, plane, projection, sx, sy, mask, shares, met)
        expected = _columns_meet_by_numpy(points, plane, projection, sx, sy, mask, shares)
        np.testing.assert_array_equal(met.astype(bool), expected)
        met_somewhere += expected.sum()
        missed_somewhere += (~expected).sum()
    assert met_somewhere > 100 and missed_somewhere > 100  # both answers were asked for


def test_columns_meet_mask_of_a_column_standing_over_a_pixel_by_hand():
    # A camera looking down the z axis from z = 2 (f = 1, principal point 0) at the plane z = 0, normal up;
    # coarse pixels of 0.1, so that image coordinate u is coarse (u + 0.5) / 0.1 - 0.5. The column over
    # (0.5, 0, 1) runs down to (0.5, 0, 0): u = 0.5 / (2 - z) from 0.5 to 0.25, coarse 9.5 to 7.0, rounded half
    # to even 10 to 7; v = 0 everywhere, coarse row 4.5, rounded 4.
    projection = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 2.0]])
    plane = np.array([0.0, 0.0, 1.0, 0.0])
    shares = np.linspace(0.0, 1.0, 11)
    point = np.array([[0.5, 0.0, 1.0]])
    met = np.empty(1, np.uint8)
    for (row, column), expected in (((4, 10), 1), ((4, 7), 1), ((4, 9), 1), ((4, 6), 0), ((4, 11), 0),
                                    ((5, 8), 0), ((3, 8), 0)):
        mask = np.zeros((10, 12), np.uint8)
        mask[row, column] = 255
        columns_meet_mask(point, plane, projection, 0.1, 0.1, mask, shares, met)
        assert met[0] == expected, (row, column)


def test_windowed_correlation_is_the_numpy_formula_on_random_window_means():
    rng = np.random.default_rng(0)
    for _ in range(20):
        shape = (int(rng.integers(1, 40)), int(rng.integers(1, 40)))
        mean_a, mean_b = (rng.uniform(0, 255, size=shape).astype(np.float32) for _ in range(2))
        # Variances and sums of squares about the means' scale, some below the means' square (flat windows).
        variance_a = np.maximum(rng.normal(20, 40, size=shape), 0).astype(np.float32)
        flat_a = rng.uniform(0, 60, size=shape).astype(np.float32)
        square_mean_b = (mean_b * mean_b + rng.normal(20, 40, size=shape)).astype(np.float32)
        product_mean = (mean_a * mean_b + rng.normal(0, 30, size=shape)).astype(np.float32)
        correlation, textured = np.empty(shape, np.float32), np.empty(shape, np.uint8)
        windowed_correlation(mean_a, variance_a, flat_a, mean_b, square_mean_b, product_mean, 0.03, 9.0,
                             correlation, textured)
        variance_b = np.maximum(square_mean_b - mean_b * mean_b, 0.0)
        expected = (product_mean - mean_a * mean_b) / np.sqrt(variance_a * variance_b + 1e-6)
        expected_textured = (variance_a > flat_a) & (variance_b > np.maximum((0.03 * mean_b) ** 2, 9.0))
        np.testing.assert_array_equal(correlation, expected)
        np.testing.assert_array_equal(textured.astype(bool), expected_textured)


def test_windowed_correlation_of_a_window_with_itself_is_one():
    # b = a: the product's mean is the mean square, so the correlation is var / sqrt(var^2 + 1e-6).
    mean, square_mean = np.array([[10.0]], np.float32), np.array([[116.0]], np.float32)  # variance 16
    correlation, textured = np.empty((1, 1), np.float32), np.empty((1, 1), np.uint8)
    windowed_correlation(mean, np.array([[16.0]], np.float32), np.array([[9.0]], np.float32), mean, square_mean,
                         square_mean, 0.03, 9.0, correlation, textured)
    assert abs(float(correlation[0, 0]) - 1.0) < 1e-6
    assert textured[0, 0] == 1


def test_add_relit_grain_is_the_numpy_formula_where_the_other_view_sees():
    rng = np.random.default_rng(2)
    floored = False
    for _ in range(20):
        shape = (int(rng.integers(1, 40)), int(rng.integers(1, 40)))
        coarse = (int(rng.integers(1, 12)), int(rng.integers(1, 12)))
        own, theirs = (rng.normal(0, 8, size=shape).astype(np.float32) for _ in range(2))
        # Lights from black to bright, so that the ratio of lights falls under its floor of 0.05 somewhere.
        own_light = rng.uniform(0, 255, size=shape).astype(np.float32)
        their_light = (own_light * rng.uniform(0, 40, size=shape)).astype(np.float32)
        inside = rng.random(coarse) < 0.6
        rows = np.sort(rng.integers(0, coarse[0], shape[0])).astype(np.intp)
        columns = np.sort(rng.integers(0, coarse[1], shape[1])).astype(np.intp)
        sums = rng.normal(0, 50, size=shape + (3,)).astype(np.float32)
        seeing = rng.integers(0, 3, size=shape).astype(np.float32)
        expected_sums, expected_seeing = sums.copy(), seeing.copy()
        # The formula as _plane_grain_sums wrote it in NumPy.
        lit = np.maximum((own_light + 1.0) / (their_light + 1.0), 0.05)
        relit = own / lit
        sees = inside[rows][:, columns]
        expected_sums[sees] += np.stack([relit * theirs, theirs * theirs, relit * relit], axis=-1)[sees]
        expected_seeing[sees] += 1.0
        add_relit_grain(own, own_light, theirs, their_light, inside.view(np.uint8), rows, columns, sums, seeing)
        floored |= bool((lit[sees] == np.float32(0.05)).any())
        np.testing.assert_array_equal(sums, expected_sums)
        np.testing.assert_array_equal(seeing, expected_seeing)
    assert floored, "the floor of the lights' ratio was never tried"


def _looking_at_origin(position) -> Camera:
    z = -np.asarray(position, float) / np.linalg.norm(position)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = position
    return Camera(K=[[520, 0, 318], [0, 515, 243], [0, 0, 1]], T_world_cam=T)


def test_the_planes_closed_form_maps_are_those_of_each_table_point_projected():
    # Two views of a table (z = 0) from either side: the homography's maps against finding each coarse
    # pixel's table point and projecting it into the other view, the way a lens with distortion still goes.
    image = np.zeros((480, 640, 3), np.uint8)
    views = [auto_segment._View(i, image, _looking_at_origin(p), None)
             for i, p in enumerate([[0.5, -0.1, 0.45], [-0.2, 0.5, 0.6]])]
    plane = np.array([0.0, 0.0, 1.0, 0.0])
    for view, other in [(views[0], views[1]), (views[1], views[0])]:
        maps, inside = auto_segment._plane_homography_maps(view, other, plane)
        points, valid = auto_segment._plane_points(view, plane)
        expected_maps, expected_inside = auto_segment._plane_maps(other, points, valid, view.coarse_size)
        assert inside.any() and not inside.all()
        np.testing.assert_array_equal(inside, expected_inside)
        np.testing.assert_allclose(maps[inside.reshape(maps.shape[:2])],
                                   expected_maps[expected_inside.reshape(maps.shape[:2])], atol=1e-3)


@pytest.mark.parametrize("size, to", [((200, 150), (640, 480)), ((200, 150), (800, 600)), ((197, 133), (777, 523)),
                                      ((150, 200), (480, 640)), ((8, 8), (30, 30))])
def test_nearest_indices_pick_what_cv2_resize_picks(size, to):
    import cv2
    image = np.random.default_rng(1).integers(0, 256, (size[1], size[0]), dtype=np.uint8)
    rows, columns = auto_segment._nearest_indices(size, to)
    resized = cv2.resize(image, to, interpolation=cv2.INTER_NEAREST)
    assert np.array_equal(image[rows][:, columns], resized)
    assert np.array_equal(image[rows[5:40]][:, columns[3:17]], resized[5:40, 3:17])


def _within(off: np.ndarray) -> np.float32:
    """How far from the table's median colour a shadow's may lie: 0.12, or as far as nine in ten of the lit
    table's colours lie (``off``, their distances; the value nine tenths up them sorted), whichever is more,
    up to 0.3."""
    spread = np.sort(off)[(len(off) - 1) * 9 // 10] if len(off) else np.float32(0.0)
    return min(max(np.float32(0.12), spread), np.float32(0.3))


def test_shadow_like_asks_only_the_table_pixels_what_the_whole_image_formula_says():
    rng = np.random.default_rng(2)
    for trial in range(50):
        image = (rng.random((30, 40, 3)) * 255).astype(np.float32)
        image[rng.random((30, 40)) < 0.4] *= 0.5  # some of it darkened alike: a shadow's look
        table = rng.random((30, 40)) < 0.6 * (trial % 5 > 0)
        brightness = image.sum(axis=2) + 3.0
        chroma = image / brightness[..., None]
        expected = np.zeros((30, 40), bool)
        if table.any():
            table_chroma = np.array([np.median(chroma[..., k][table]) for k in range(3)], np.float32)
            off = np.abs(chroma - table_chroma).sum(axis=2) * np.float32(3.0)
            dark = brightness < 0.92 * np.float32(np.median(brightness[table]))
            expected = (off < _within(off[table & ~dark])) & dark
        assert np.array_equal(auto_segment._shadow_like(image, table), expected & table)


def test_shadow_like_pixels_is_the_numpy_it_replaced_on_a_crop():
    rng = np.random.default_rng(5)
    for trial in range(200):
        whole = (rng.random((50, 60, 3)) * 255).astype(np.float32)
        if trial % 3 == 0:  # a plain table, whose colours lie within 0.12 of their median
            whole = (rng.uniform(40, 220, 3) + rng.normal(0.0, 2.0, (50, 60, 3))).astype(np.float32)
        elif trial % 3 == 1:  # a textured one, whose colours lie farther, and not all beyond 0.3
            whole = (rng.uniform(40, 220, 3) * rng.uniform(0.85, 1.15, (50, 60, 3))).astype(np.float32)
        shade = rng.random((50, 60)) < 0.5
        whole[shade] *= rng.uniform(0.3, 1.0)  # darkened alike: a shadow's look
        crop = (slice(int(rng.integers(0, 10)), int(rng.integers(20, 50))),
                slice(int(rng.integers(0, 10)), int(rng.integers(20, 60))))
        image = whole[crop]  # a strided view, as the graph cut's box of the coarse image is
        table = rng.random(image.shape[:2]) < [0.0, 0.01, 0.5, 1.0][trial % 4]
        # _shadow_like as it was written in NumPy, with the kernel's median.
        expected = np.zeros(table.shape, bool)
        pixels = image[table]
        if len(pixels):
            brightness = pixels.sum(axis=1) + 3.0
            chroma = pixels / brightness[:, None]
            table_chroma = np.array([median(np.ascontiguousarray(chroma[:, k])) for k in range(3)], chroma.dtype)
            off = np.abs(chroma - table_chroma).sum(axis=1) * np.float32(3.0)
            dark = brightness < 0.92 * median(brightness)
            expected[table] = (off < _within(off[~dark])) & dark
        found = np.zeros(table.shape, bool)
        shadow_like_pixels(image, table.view(np.uint8), 0.92, found.view(np.uint8))
        np.testing.assert_array_equal(found, expected)


def test_ratio_disagreement_is_the_numpy_it_replaced():
    rng = np.random.default_rng(6)
    for _ in range(20):
        shape = (int(rng.integers(1, 40)), int(rng.integers(1, 40)), 3)
        # Log ratios over a wide range, the other view's range about them, some of it exactly on them.
        own = (rng.normal(0, 1, size=shape) * np.exp(rng.normal(0, 3, size=shape))).astype(np.float32)
        low = (own - np.abs(rng.normal(0, 1, size=shape)) * (rng.random(shape) < 0.7)
               + rng.normal(0, 0.3, size=shape) * (rng.random(shape) < 0.3)).astype(np.float32)
        high = (low + np.abs(rng.normal(0, 1, size=shape))).astype(np.float32)
        found = np.empty(shape[:2], np.float32)
        ratio_disagreement(own, low, high, found)
        np.testing.assert_array_equal(found, (np.maximum(low - own, 0) + np.maximum(own - high, 0)).sum(axis=2))


def test_shadow_look_is_the_numpy_it_replaced():
    rng = np.random.default_rng(7)
    for trial in range(50):
        shape = (int(rng.integers(1, 40)), int(rng.integers(1, 40)), 3)
        empty = rng.uniform(0, 255, size=shape).astype(np.float32)
        # The empty workspace darkened alike (a shadow) or not, a tint added here and there, some black.
        image = (empty * rng.uniform(0.0, 1.1, size=shape[:2])[..., None]
                 + rng.normal(0, 8, size=shape) * (rng.random(shape[:2]) < 0.3)[..., None]).astype(np.float32)
        image = np.maximum(image, 0).astype(np.float32)
        # _shadow_of_table as it was written in NumPy (_darkening's ratio inside).
        a, b = image + 12.0, empty + 12.0
        hue_shift = np.abs(a / a.sum(axis=2)[..., None] - b / b.sum(axis=2)[..., None]).sum(axis=2)
        ratio = (image.sum(axis=2) + 3 * 12.0) / (empty.sum(axis=2) + 3 * 12.0)
        expected = (ratio < 0.97) & (ratio > 0.1) & (hue_shift < 0.12)
        found = np.empty(shape[:2], np.uint8)
        shadow_look(image, empty, 12.0, 0.1, 0.97, 0.12, found)
        np.testing.assert_array_equal(found.view(bool), expected)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_channel_sum_is_numpys_sum_over_the_channels(dtype):
    rng = np.random.default_rng(8)
    for _ in range(20):
        # Values of many magnitudes, so that the order of the additions shows in the last bit.
        whole = (rng.normal(size=(40, 50, 3)) * np.exp(rng.normal(0, 4, size=(40, 50, 3)))).astype(dtype)
        rows = slice(int(rng.integers(0, 10)), int(rng.integers(10, 40)))
        image = whole[rows, int(rng.integers(0, 10)):int(rng.integers(10, 50))]
        brightness = np.empty(image.shape[:2], dtype)
        channel_sum(image, brightness)
        np.testing.assert_array_equal(brightness, image.sum(axis=2))
        np.testing.assert_array_equal(auto_segment._brightness(image), image.sum(axis=2))


def test_grown_by_colour_is_the_brute_force_distances():
    """The k-d tree searches stopped at their thresholds decide as every colour's distance to every sample."""
    from types import SimpleNamespace

    import cv2
    rng = np.random.default_rng(3)
    for trial in range(20):
        ch, cw = 60, 80
        coarse = np.full((ch, cw, 3), 120.0, np.float32) + rng.normal(0, 20, (ch, cw, 3)).astype(np.float32)
        # A piece near the aim of one colour, some of the same colour beside it, and colours at the thresholds.
        coarse[25:35, 35:45] = [30.0, 60.0, 200.0]
        coarse[20:40, 45:55] = np.float32([30.0, 60.0, 200.0]) + rng.integers(-9, 10, (20, 10, 3)).astype(np.float32)
        standing = np.zeros((ch, cw), np.uint8)
        standing[27:33, 37:43] = 255
        view = SimpleNamespace(coarse_size=(cw, ch), coarse=coarse)
        centre = np.array([40.0, 30.0])
        found = auto_segment._grown_by_colour(view, standing, centre)
        # The same by every distance.
        reach = 0.25 * np.hypot(cw, ch)
        near = auto_segment._components_near(standing, centre, reach)
        yy, xx = np.mgrid[0:ch, 0:cw]
        distance = np.hypot(xx - centre[0], yy - centre[1])
        table = coarse[(distance > reach) & (standing == 0)]
        seeds = coarse[near > 0]
        table = table[:: max(1, len(table) // auto_segment._COLOUR_SAMPLES)]
        seeds = seeds[:: max(1, len(seeds) // auto_segment._COLOUR_SAMPLES)]
        inside = distance <= reach
        colours = coarse[inside].astype(np.float64)
        to_seed = np.sqrt(((colours[:, None] - seeds[None]) ** 2).sum(axis=2)).min(axis=1)
        to_table = np.sqrt(((colours[:, None] - table[None]) ** 2).sum(axis=2)).min(axis=1)
        from_shade = auto_segment._unlike_table(coarse[inside][None], np.median(table, axis=0)[None])[0]
        like = np.zeros((ch, cw), np.uint8)
        like[inside] = np.where((to_seed < auto_segment._SEED_NEAR)
                                & (np.minimum(to_table, from_shade) > auto_segment._TABLE_FAR), 255, 0)
        count, labels = cv2.connectedComponents(cv2.bitwise_or(like, near), connectivity=8)
        chosen = np.zeros(count, bool)
        chosen[np.unique(labels[near > 0])] = True
        chosen[0] = False
        expected = cv2.bitwise_or(standing, np.where(chosen[labels], 255, 0).astype(np.uint8))
        assert np.array_equal(found, expected)
        assert cv2.countNonZero(found) > cv2.countNonZero(standing)


def test_any_within_is_the_nearest_samples_distance_against_the_radius():
    """As scipy's cKDTree's nearest distance compared with the radius, ties at whole grey levels included."""
    from scipy.spatial import cKDTree
    rng = np.random.default_rng(5)
    for trial in range(200):
        points = (rng.random((int(rng.integers(1, 2000)), 3)) * 255).astype(np.float32)
        samples = (rng.random((int(rng.integers(0, 300)), 3)) * 120 + 60).astype(np.float32)
        if trial % 3 == 0:
            points, samples = np.round(points), np.round(samples)
        if trial % 7 == 0:
            samples *= 1000.0  # spread far: the grid's cells widen
        radius = [8.0, 40.0, 1.0, 3.0][trial % 4]
        for inclusive in (False, True):
            found = np.empty(len(points), np.uint8)
            any_within(points, np.ascontiguousarray(samples), radius, inclusive, found)
            if len(samples):
                nearest = cKDTree(samples).query(points)[0]
                expected = nearest <= radius if inclusive else nearest < radius
            else:
                expected = np.zeros(len(points), bool)
            assert np.array_equal(found.view(bool), expected)


def test_any_within_by_hand():
    samples = np.array([[0.0, 0.0, 0.0], [100.0, 100.0, 100.0]], np.float32)
    points = np.array([[8.0, 0.0, 0.0], [7.9, 0.0, 0.0], [100.0, 100.0, 108.0], [50.0, 50.0, 50.0]], np.float32)
    found = np.empty(4, np.uint8)
    any_within(points, samples, 8.0, False, found)
    assert found.tolist() == [0, 1, 0, 0]
    any_within(points, samples, 8.0, True, found)
    assert found.tolist() == [1, 1, 1, 0]
    with pytest.raises(ValueError):
        any_within(points, samples, 0.0, True, found)


def test_the_region_near_the_aim_is_the_object_beside_a_speck_on_the_aim():
    """A white face differs from the table only at its edges and print: the aim may fall on a speck of
    its print, which is not the object; the large region around it is (a tall sugar box on laminate was
    "nothing stands on the table" for it)."""
    binary = np.zeros((150, 200), np.uint8)
    binary[60:110, 80:115] = 255
    binary[70:100, 90:105] = 0                    # the face's plain middle
    binary[78:81, 99:102] = 255                   # a speck of print on the aim
    binary[0:40, 0:40] = 255                      # a larger region, out of reach
    region = auto_segment._component_near(binary, np.array([100.0, 79.0]), reach=40.0)
    assert region is not None
    expected = binary.copy()
    expected[78:81, 99:102] = 0
    expected[0:40, 0:40] = 0
    assert np.array_equal(region, expected)
    # A region on the aim that is no speck is the object.
    binary[70:100, 90:105] = 255
    region = auto_segment._component_near(binary, np.array([100.0, 79.0]), reach=40.0)
    assert region is not None and region[79, 100] and not region[10, 10] and region[60, 80]
    binary[:] = 0
    binary[78:81, 99:102] = 255                   # a speck alone is what there is (the caller judges it)
    region = auto_segment._component_near(binary, np.array([100.0, 79.0]), reach=40.0)
    assert region is not None and np.count_nonzero(region) == 9
    assert auto_segment._component_near(np.zeros((150, 200), np.uint8), np.array([100.0, 79.0]), 40.0) is None


def test_window_sums_are_the_box_filters_at_the_pixels_asked():
    """The outline's sums, taken at its pixels alone, are what cv2.boxFilter gives there (its reflected
    border too), on images smaller than the window as well."""
    rng = np.random.default_rng(3)
    for trial in range(300):
        h, w = (int(n) for n in rng.integers(1, 40, 2))
        side = (rng.random((h, w)) < 0.5).astype(np.uint8)
        colours = rng.integers(0, 256, (h, w, 3), dtype=np.uint8) * side[..., None]
        rows, columns = np.nonzero(rng.random((h, w)) < 0.3)
        count, total = auto_segment._window_sums(side, colours, rows, columns, 5)
        box_count = cv2.boxFilter(side.astype(np.float32), -1, (11, 11), normalize=False)
        box_total = cv2.boxFilter(colours.astype(np.float32), -1, (11, 11), normalize=False)
        assert count.dtype == total.dtype == np.float32
        assert np.array_equal(count, box_count[rows, columns])
        assert np.array_equal(total, box_total[rows, columns])


def test_unstepped_outline_is_the_whole_images_box_filtered_means():
    """The outline without a step, from sums at the outline alone, is the one from box filters over the
    whole window: every mean and step alike, to the bit."""
    def reference(image, inside, spread):
        within = cv2.erode(inside, auto_segment._SMALL)
        beyond = 1 - cv2.dilate(inside, auto_segment._SMALL)
        means, counts = [], []
        for side in (within, beyond):
            count = cv2.boxFilter(side.astype(np.float32), -1, (11, 11), normalize=False)
            total = cv2.boxFilter(image.astype(np.float32) * side[..., None], -1, (11, 11), normalize=False)
            means.append(total / np.maximum(count, 1.0)[..., None])
            counts.append(count)
        step = np.abs(means[0] - means[1]).sum(axis=2)
        flat = (inside > 0) & (within == 0) & (counts[0] >= 5) & (counts[1] >= 5)
        return flat, step

    rng = np.random.default_rng(4)
    for trial in range(200):
        h, w = (int(n) for n in rng.integers(8, 60, 2))
        image = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        inside = np.zeros((h, w), np.uint8)
        cv2.circle(inside, (int(rng.integers(0, w)), int(rng.integers(0, h))), int(rng.integers(2, 30)), 1, -1)
        flat, step = reference(image, inside, 0.0)
        if not flat.any():
            continue
        # Spreads that put the threshold exactly on some outline pixel's step, and just either side of it.
        edge = float(rng.choice(step[flat])) / auto_segment._STEP_CLEAR
        for spread in (np.nextafter(edge, 0.0), edge, np.nextafter(edge, np.inf), 1e9):
            wanted = cv2.dilate((flat & (step < auto_segment._STEP_CLEAR * spread)).astype(np.uint8),
                                cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (11, 11))) > 0
            assert np.array_equal(auto_segment._unstepped_outline(image, inside, spread), wanted)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_median_of_many_values_is_numpys_whether_or_not_the_sample_brackets_it(dtype):
    """Many values (the evidence of a whole view) are selected between two of a sample's first: the median
    is NumPy's all the same, with ties, sorted values, a middle at the bracket's edge, and a sample that
    misses the middle (the selection then runs over all)."""
    rng = np.random.default_rng(5)

    def sampled(count):
        return (np.arange(1024) * count) // 1024

    def cases():
        for count in (4096, 4097, 9000, 30001):
            yield rng.normal(size=count)
            yield np.where(rng.random(count) < 0.6, 0.0, np.abs(rng.normal(size=count)))  # most of a map is 0
            yield np.sort(rng.normal(size=count))
            yield np.sort(rng.normal(size=count))[::-1].copy()
            yield np.full(count, 2.5)
            yield np.round(rng.normal(size=count) * 3)  # few distinct values, many ties
            missed = rng.normal(size=count)
            missed[sampled(count)] = 1e6  # the sample sees only the largest value
            yield missed
        for count in (4096, 10000):
            # Half zeros, half ones, the sample all ones: the bracket starts at the middle, and the value just
            # below it is the largest under the bracket.
            edge = np.ones(count)
            rest = np.setdiff1d(np.arange(count), sampled(count))
            edge[rng.choice(rest, count // 2, replace=False)] = 0.0
            yield edge

    for values in cases():
        values = values.astype(dtype)
        with_nan = values.copy()
        with_nan[rng.random(len(values)) < 0.05] = np.nan
        assert median_and_spread(values) == _reference(values)
        assert median_and_spread(with_nan) == _reference(with_nan)
        assert median(values) == float(np.median(values))


def test_dilated_over_the_pieces_box_is_the_whole_images_dilation():
    """The dilation worked out over the pieces' box grown by its reach is cv2.dilate's over the whole image,
    pieces on the image's edges, none at all, and reaches wider than the image included."""
    rng = np.random.default_rng(6)
    for trial in range(300):
        h, w = (int(n) for n in rng.integers(1, 50, 2))
        binary = np.zeros((h, w), np.uint8)
        for _ in range(int(rng.integers(0, 4))):
            x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
            binary[y:y + int(rng.integers(1, 8)), x:x + int(rng.integers(1, 8))] = rng.choice([1, 255])
        reach = int(rng.integers(0, 30))
        whole = cv2.dilate(binary, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1)))
        assert np.array_equal(auto_segment._dilated(binary, reach), whole)


def test_what_hides_the_table_is_read_through_the_float_maps_rounded():
    """The maps rounded to whole pixels once per pair of views read what hides the table as cv2.remap
    reads it through the float maps, looks after looks: the table from two sides, and maps with half-pixel
    ties, points far out of the picture and NaN."""
    rng = np.random.default_rng(7)
    image = np.zeros((480, 640, 3), np.uint8)
    views = [auto_segment._View(i, image, _looking_at_origin(p), None)
             for i, p in enumerate([[0.5, -0.1, 0.45], [-0.2, 0.5, 0.6]])]
    plane = np.array([0.0, 0.0, 1.0, 0.0])
    for view, other in [(views[0], views[1]), (views[1], views[0])]:
        maps, inside = view.mapping(other, plane)
        inside = inside.reshape(maps.shape[:2])
        for _ in range(3):
            hidden = np.where(rng.random((150, 200)) < 0.3, 255, 0).astype(np.uint8)
            _, seen, behind = view.sees(other, plane, hidden)
            expected = inside & (cv2.remap(hidden, maps, None, cv2.INTER_NEAREST, borderValue=0) > 0)
            np.testing.assert_array_equal(behind, expected)
            np.testing.assert_array_equal(seen, inside & ~expected)
    maps = rng.uniform(-3, 12, (9, 11, 2)).astype(np.float32)
    maps[::2] = np.round(maps[::2]) + 0.5
    maps[1, :3] = [[1e9, 3.0], [np.nan, 2.0], [-7e4, np.inf]]
    hidden = rng.integers(0, 256, (10, 10), dtype=np.uint8)
    rounded = cv2.convertMaps(maps, None, cv2.CV_16SC2, nninterpolation=True)[0]
    np.testing.assert_array_equal(auto_segment._remapped(hidden, rounded, cv2.INTER_NEAREST, borderValue=0),
                                  cv2.remap(hidden, maps, None, cv2.INTER_NEAREST, borderValue=0))


def test_the_shadow_in_a_box_kept_is_the_one_its_box_and_evidence_give():
    """The shadow a view keeps for its last graph cut's box is what the box's image and evidence give
    afresh, and another evidence, another box or an evened image is worked out anew."""
    rng = np.random.default_rng(8)
    image = np.full((480, 640, 3), 150, np.uint8)
    image[200:300, 300:400] = 90                                # the table in shadow
    image += rng.integers(0, 6, image.shape, dtype=np.uint8)    # the table's grain
    view = auto_segment._View(0, image, _looking_at_origin([0.5, -0.1, 0.45]), None)

    def afresh(crop, score):
        picture, low = view.coarse[crop], score[crop] < 1.0
        shadow = low & auto_segment._shadow_like(picture, low)
        return shadow, auto_segment._shadow_seen(picture, low, shadow, score[crop] == auto_segment._HIDDEN)

    def same(kept, wanted):
        assert np.array_equal(kept[0], wanted[0])
        assert (kept[1] is None) == (wanted[1] is None)
        if wanted[1] is not None:
            for a, b in zip(kept[1], wanted[1]):
                assert np.array_equal(a, b)

    score = rng.uniform(0.0, 0.9, (150, 200)).astype(np.float32)
    score[70:90, 90:110] = auto_segment._HIDDEN
    crop = (slice(40, 120), slice(60, 160))
    first = auto_segment._shadow_in_box(view, crop, score)
    assert first[1] is not None and first[0].any()
    same(first, afresh(crop, score))
    same(auto_segment._shadow_in_box(view, crop, score), first)
    other = score.copy()
    other[60:70, 95:125] = 3.0                                  # part of the shadow stands out now
    same(auto_segment._shadow_in_box(view, crop, other), afresh(crop, other))
    smaller = (slice(50, 110), slice(70, 150))
    same(auto_segment._shadow_in_box(view, smaller, score), afresh(smaller, score))
    view.coarse = view.coarse * np.float32(0.5)                 # the light evened
    same(auto_segment._shadow_in_box(view, smaller, score), afresh(smaller, score))
