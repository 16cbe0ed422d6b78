import cv2
import numpy as np
import pytest

from robocell.core_cy.errors import CoreError, ImageError, SilhouetteError
from robocell.core_cy.segment import RED_HSV, Segmentation, segment, segment_with_outline, silhouette_from_mask


def _hsv_image(patches, shape=(120, 160)):
    """A grey image with HSV-coloured rectangles: patches = [((x, y, w, h), (h, s, v)), ...]."""
    hsv = np.zeros((*shape, 3), np.uint8)
    hsv[..., 2] = 128  # grey background: saturation 0
    for (x, y, w, h), colour in patches:
        hsv[y : y + h, x : x + w] = colour
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)


def test_red_hue_range_wraps_around_zero():
    # Two touching red patches, one on each side of hue 0, and a green one further away.
    image = _hsv_image([((20, 20, 30, 40), (176, 200, 200)), ((50, 20, 30, 40), (4, 200, 200)),
                        ((110, 70, 20, 20), (60, 200, 200))])
    silhouette = segment(image)
    assert np.count_nonzero(silhouette) == 60 * 40
    assert silhouette[40, 30] == 255 and silhouette[40, 70] == 255 and silhouette[80, 120] == 0


def test_hsv_range_without_wrap():
    image = _hsv_image([((20, 20, 30, 40), (60, 200, 200)), ((100, 20, 30, 40), (4, 200, 200))])
    silhouette = segment(image, Segmentation("hsv", lower=(50, 90, 40), upper=(70, 255, 255)))
    assert np.count_nonzero(silhouette) == 30 * 40 and silhouette[40, 30] == 255


@pytest.mark.parametrize("invert", [False, True])
def test_threshold_bright_or_dark_object(invert):
    image = np.full((100, 100, 3), 200 if invert else 30, np.uint8)
    image[30:60, 40:80] = 40 if invert else 220
    silhouette = segment(image, Segmentation("threshold", value=128, invert=invert))
    assert np.count_nonzero(silhouette) == 30 * 40


def test_largest_component_with_its_holes_filled():
    mask = np.zeros((100, 100), np.uint8)
    mask[10:60, 10:60] = 7  # any nonzero value is object
    mask[30:40, 30:40] = 0  # a hole
    mask[80:90, 80:90] = 255  # a smaller blob
    silhouette = silhouette_from_mask(mask)
    assert np.count_nonzero(silhouette) == 50 * 50
    assert silhouette[35, 35] == 255 and silhouette[85, 85] == 0


def test_empty_silhouette_names_the_view_and_the_segmentation():
    with pytest.raises(SilhouetteError, match=r"^view 1: the silhouette is empty.*hsv lower=\[170, 90, 20\]"):
        segment(np.full((50, 50, 3), 128, np.uint8), view=1)


def test_silhouette_touching_every_border_is_an_error():
    with pytest.raises(SilhouetteError, match="^view 0: the silhouette touches all four image borders"):
        silhouette_from_mask(np.full((50, 50), 255, np.uint8), view=0)


def test_wrong_image_types_are_refused():
    with pytest.raises(ImageError, match=r"\(H, W, 3\) uint8"):
        segment(np.zeros((10, 10), np.uint8))
    with pytest.raises(ImageError, match=r"\(H, W\) uint8 mask"):
        silhouette_from_mask(np.zeros((10, 10), np.float32))


@pytest.mark.parametrize("spec", [dict(method="grabcut"), dict(lower=(180, 0, 0)), dict(value=300)])
def test_invalid_segmentation_is_refused(spec):
    with pytest.raises(CoreError, match="segmentation"):
        Segmentation(**spec)


def test_a_shaded_face_stays_in_the_silhouette():
    """A red box lit from one side, its far faces in shadow (V about 30), on a pale table."""
    from robocell.workers.sim.objects import box
    from robocell.workers.sim.render import render
    from robocell.workers.sim.scans import default_K, look_at

    obj = box([0.05, 0.03, 0.025], (0.6, 0.0), yaw_deg=35)
    # Looking from the side away from the light, at the shaded faces.
    pose = look_at([0.6 - 0.35, 0.35, 0.3], obj.T_world_object[:3, 3])
    image, mask = render(obj, pose, default_K(), noise_sigma=2.0, ambient=0.15)
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    inside = cv2.erode(mask, np.ones((5, 5), np.uint8)) > 0
    assert np.percentile(hsv[..., 2][inside], 10) < 40  # a tenth of the object is darker than V = 40
    silhouette = segment(image)
    truth = mask > 0
    assert np.count_nonzero(truth & (silhouette == 0) & inside) == 0  # no pixel inside is lost
    iou = np.count_nonzero(truth & (silhouette > 0)) / np.count_nonzero(truth | (silhouette > 0))
    assert iou > 0.95


def test_looking_in_a_box_first_gives_the_same_silhouette():
    """The coarse pass only saves work: a small object, an object cut by the border, and a
    speck far from the object give the same silhouette as segmenting the whole image."""
    from robocell.core_cy.segment import _cleaned, _matches, _opened

    image = _hsv_image([((120, 70, 6, 5), (2, 200, 200))])  # 6 x 5 px
    cut = _hsv_image([((0, 30, 40, 30), (2, 200, 200)), ((140, 100, 3, 3), (2, 200, 200))])
    for picture in (image, cut):
        whole = _cleaned(_opened(_matches(picture, RED_HSV)), picture.shape, (0, 0, 160, 120))
        silhouette, outline = segment_with_outline(picture)
        np.testing.assert_array_equal(silhouette, whole[0])
        np.testing.assert_array_equal(outline, whole[1])
