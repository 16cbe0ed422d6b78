"""Hostile scan bundles (DESIGN.md §3, "A bundle is untrusted input") through `robocell reconstruct`.

Every bundle of ``tests.bundles.HOSTILE_BUNDLES`` sits between two good ones in one real
process: each gets its one-line error naming the view and what is wrong, the good ones
are still reconstructed, and the exit status says that something failed.
"""

import json
import shutil
import subprocess
import sys

from tests.bundles import HOSTILE_BUNDLES


def test_hostile_bundles_get_one_line_errors_and_the_good_ones_are_still_done(tmp_path, sphere_bundle_template):
    good = shutil.copytree(sphere_bundle_template, tmp_path / "good")
    hostile = []
    for name, (change, _) in HOSTILE_BUNDLES.items():
        hostile.append(shutil.copytree(sphere_bundle_template, tmp_path / name))
        change(hostile[-1])
    process = subprocess.run([sys.executable, "-m", "robocell", "reconstruct", good, *hostile, good],
                             capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert process.returncode == 1
    results = [json.loads(line) for line in process.stdout.splitlines()]
    assert [r["scan"] for r in results] == [str(p) for p in [good, *hostile, good]]  # nothing lost, in order
    assert "superquadric" in results[0] and "superquadric" in results[-1]
    for (name, (_, message)), result in zip(HOSTILE_BUNDLES.items(), results[1:-1]):
        assert message in result.get("error", ""), (name, result)
        assert "internal error" not in result["error"] and "\n" not in result["error"]
    assert "Traceback" not in process.stderr


def test_the_reconstruction_worker_checks_each_picture_against_its_calibration():
    """The worker's input is untrusted too: a picture of another size than K's is named, not carved."""
    import cv2
    import numpy as np

    from robocell.wire.messages import CameraModel, ReconstructReply, ReconstructRequest, ReconstructView
    from robocell.workers.reconstruct.worker import reconstruct_request

    small = cv2.imencode(".jpg", np.zeros((240, 320, 3), np.uint8))[1].tobytes()
    camera = CameraModel(K=[[600, 0, 319.5], [0, 600, 239.5], [0, 0, 1]])
    pose = [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 1], [0, 0, 0, 1]]
    request = ReconstructRequest(job_id="j", views=[ReconstructView(camera=camera, T_world_cam=pose, length=len(small))] * 2)
    reply_json, payload = reconstruct_request(request.model_dump_json(), small * 2)
    reply = ReconstructReply.model_validate_json(reply_json)
    assert reply.result is None and payload == b""
    assert reply.error.startswith("view 0: the picture is 320x240 pixels, but K was calibrated for about 640x480")
    assert reply.error_kind == "ImageError"
