import json
import re
from pathlib import Path

import numpy as np
import pytest

from robocell.wire.bundle import load_bundle
from robocell.wire.errors import BundleError
from robocell.core_cy.segment import Segmentation

from tests.bundles import edit_scan, write_sphere_bundle


@pytest.fixture
def bundle(sphere_bundle):
    return sphere_bundle


def test_a_valid_bundle_loads_with_encoded_images(bundle):
    loaded = load_bundle(bundle)
    assert len(loaded.views) == 3
    assert loaded.views[0].image[:2] == b"\xff\xd8"  # still JPEG: decoding is the core's, timed
    assert loaded.support_plane == [0, 0, 1, 0]
    assert loaded.segmentation == Segmentation("auto")  # default: auto, any colour


def test_the_mask_wins_over_the_image(tmp_path):
    loaded = load_bundle(write_sphere_bundle(tmp_path / "scan", masks=True))
    assert loaded.views[1].image is None and loaded.views[1].mask[:4] == b"\x89PNG"


def test_segmentation_from_scan_json(bundle):
    edit_scan(bundle, lambda s: s.update(segmentation={"method": "threshold", "value": 90, "invert": True}))
    assert load_bundle(bundle).segmentation == Segmentation("threshold", value=90, invert=True)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda s: s["views"][1].update(K=[[600, 0], [0, 600]]), r"views\.1\.K"),
        (lambda s: s["views"][2].pop("T_world_cam"), r"views\.2\.T_world_cam: Field required"),
        (lambda s: s["views"][0].pop("image"), r"views\.0: Value error, a view needs an 'image' or a 'mask'"),
        (lambda s: s.update(suport_plane=[0, 0, 1, 0]), r"suport_plane: Extra inputs are not permitted"),
        (lambda s: s.update(segmentation={"method": "magic"}), r"segmentation"),
        (lambda s: s.update(support_plane=[0, 0, 1]), r"support_plane"),
        (lambda s: s["views"][1]["K"][0].__setitem__(0, "NaN"), r"view 1: K contains NaN"),
        (lambda s: s["views"][1].update(T_world_cam=np.diag([1, 1, 1, 1]).tolist()), None),
        (lambda s: s["views"][0].update(T_world_cam=np.diag([0.0, 0, 0, 1]).tolist()),
         r"view 0: T_world_cam is not a rigid transform: its rotation is not orthonormal"),
        (lambda s: s["views"][2].update(image="missing.jpg"), r"view 2: image file 'missing.jpg' not found"),
        (lambda s: s.update(segmentation={"method": "hsv", "lower": [200, 0, 0], "upper": [10, 255, 255]}),
         r"segmentation lower must be"),
    ],
)
def test_invalid_bundles_name_the_problem(bundle, change, message):
    edit_scan(bundle, change)
    if message is None:  # a valid change: no error
        load_bundle(bundle)
        return
    with pytest.raises(BundleError, match=message):
        load_bundle(bundle)


def test_missing_and_malformed_scan_json(tmp_path):
    with pytest.raises(BundleError, match="no scan.json in path"):
        load_bundle(tmp_path / "nowhere")
    (tmp_path / "scan.json").write_text("{not json")
    with pytest.raises(BundleError, match="scan.json is not valid JSON: .*line 1 column 2"):
        load_bundle(tmp_path)
    (tmp_path / "scan.json").write_text(json.dumps([1, 2]))
    with pytest.raises(BundleError, match="scan.json: Input should be a valid dictionary"):
        load_bundle(tmp_path)


DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.mark.parametrize("name", ["bunny", "dtu65/three", "dtu65/six"])
def test_real_photographs_have_the_size_their_K_was_calibrated_for(name):
    if not (DATA / name / "scan.json").exists():
        pytest.skip(f"no test data at {DATA / name}")
    assert len(load_bundle(DATA / name).views) in (3, 6)


def test_symlinks_within_the_bundle_are_followed(bundle, tmp_path):
    (bundle / "pictures").mkdir()
    (bundle / "view1.jpg").rename(bundle / "pictures" / "first.jpg")
    (bundle / "view1.jpg").symlink_to("pictures/first.jpg")
    edit_scan(bundle, lambda s: s["views"][2].update(image="pictures/first.jpg"))
    (tmp_path / "latest").symlink_to(bundle)  # the bundle's own directory may be a link
    loaded = load_bundle(tmp_path / "latest")
    assert loaded.views[1].image == loaded.views[2].image == (bundle / "pictures" / "first.jpg").read_bytes()


@pytest.mark.parametrize("name", ["pictures/../view0.jpg", "./../sphere/view0.jpg"])
def test_no_name_climbs_out_even_to_come_back(bundle, name):
    edit_scan(bundle, lambda s: s["views"][0].update(image=name))
    with pytest.raises(BundleError, match=f"^view 0: image file '{re.escape(name)}' is outside the bundle"):
        load_bundle(bundle)
