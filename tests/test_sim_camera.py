"""Tests of the simulated Axis camera (workers.sim.axis), over real HTTP on loopback.

What the camera should see is worked out independently of the server: the
object's centre projected through the test's own K and pose.
"""
from __future__ import annotations

import hashlib
import re

import cv2
import httpx
import numpy as np
import pytest

from robocell.wire.backends import AxisCameraConfig as CameraConfig
from robocell.wire.config import SimConfig
from robocell.wire.errors import ConfigError
from robocell.workers.sim.objects import CupStack, LumpyFigure, SuperquadricObject
from robocell.workers.sim.render import project
from robocell.workers.sim.textures import PrintedObject
from robocell.workers.sim.scans import look_at, object_target
from robocell.workers.sim.scene import scene_from_config, truth_from_config
from robocell.workers.sim.axis import SimCameraServer
from robocell.workers.sim.camera import scaled_K

SNAPSHOT = "/axis-cgi/jpg/image.cgi"
K = np.asarray(CameraConfig().K)  # 640x480, f = 600
SIM = SimConfig()  # a red box at (0.6, 0) on the table


def red_mask(bgr: np.ndarray) -> np.ndarray:
    """Red in HSV, lower [170, 90, 40], upper [10, 255, 255], hue wrapping round 0."""
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    hue, sat, val = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    return ((hue >= 170) | (hue <= 10)) & (sat >= 90) & (val >= 40)


def centroid(mask: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    return np.array([cols.mean(), rows.mean()])


def decode(response: httpx.Response) -> np.ndarray:
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "image/jpeg"
    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_COLOR)
    assert image is not None
    return image


class Pose:
    """A settable pose_provider, as the Zenoh wiring would be."""

    def __init__(self, T: np.ndarray | None) -> None:
        self.T = T

    def __call__(self) -> np.ndarray | None:
        return self.T


def red_scene(sim: SimConfig) -> list:
    """The ``[sim]`` object as the classic red one (a printed object without its print): these tests
    find it by its colour."""
    return [obj.object if isinstance(obj, PrintedObject) else obj for obj in scene_from_config(sim)]


@pytest.fixture(scope="module")
def target() -> np.ndarray:
    return object_target(scene_from_config(SIM)[0])


@pytest.fixture
def pose(target) -> Pose:
    return Pose(look_at(target + [0.25, 0.1, 0.35], target))


@pytest.fixture
def server(pose):
    with SimCameraServer(red_scene(SIM), K=K, image_size=(640, 480), pose_provider=pose, auth=None) as srv:
        yield srv


@pytest.fixture
def client(server):
    with httpx.Client(base_url=server.url, timeout=10.0) as c:
        yield c


def test_snapshot_shows_the_object_at_the_image_centre(client):
    image = decode(client.get(SNAPSHOT, params={"resolution": "640x480"}))
    assert image.shape == (480, 640, 3)
    red = red_mask(image)
    assert red.sum() > 2000  # a 8 x 6 x 10 cm box at 45 cm fills thousands of pixels
    np.testing.assert_allclose(centroid(red), [319.5, 239.5], atol=12)
    # The table is not red: no red pixel far from the object.
    rows, cols = np.nonzero(red)
    assert np.hypot(cols - 319.5, rows - 239.5).max() < 150


def test_smaller_resolution_scales_the_camera(client):
    big = red_mask(decode(client.get(SNAPSHOT, params={"resolution": "640x480"})))
    small_image = decode(client.get(SNAPSHOT, params={"resolution": "320x240"}))
    assert small_image.shape == (240, 320, 3)
    small = red_mask(small_image)
    # The same view at half the size: centre halves (pixel edges scale), area quarters.
    np.testing.assert_allclose(centroid(small), (centroid(big) + 0.5) / 2 - 0.5, atol=2)
    assert small.sum() == pytest.approx(big.sum() / 4, rel=0.1)


def test_changing_the_pose_changes_the_image(client, pose, target):
    first = decode(client.get(SNAPSHOT))
    camera = pose.T[:3, 3]
    pose.T = look_at(camera, target + [0.0, 0.08, 0.0])  # aim 8 cm beside the object
    second = decode(client.get(SNAPSHOT))
    assert np.abs(first.astype(int) - second.astype(int)).mean() > 5
    expected, _ = project(target[None], pose.T, K)
    assert np.hypot(*(expected[0] - [319.5, 239.5])) > 60  # really off-centre
    np.testing.assert_allclose(centroid(red_mask(second)), expected[0], atol=12)


def test_no_pose_yet_is_503(client, pose):
    pose.T = None
    response = client.get(SNAPSHOT)
    assert response.status_code == 503
    assert "no robot pose yet" in response.text


def test_param_cgi_lists_the_resolutions(client, server):
    response = client.get("/axis-cgi/param.cgi", params={"action": "list", "group": "Properties.Image.Resolution"})
    assert response.status_code == 200
    key, _, value = response.text.strip().partition("=")
    assert key == "root.Properties.Image.Resolution"
    listed = value.split(",")
    assert "640x480" in listed and "320x240" in listed
    assert all(w * 3 == h * 4 for w, h in (map(int, r.split("x")) for r in listed))  # 4:3 like the sensor
    assert listed == [f"{w}x{h}" for w, h in server.resolutions]
    assert client.get("/axis-cgi/param.cgi", params={"action": "update"}).status_code == 400


@pytest.mark.parametrize("resolution", ["641x480", "1920x1080", "big", "640x480x3", ""])
def test_unsupported_resolution_is_400(client, resolution):
    response = client.get(SNAPSHOT, params={"resolution": resolution})
    assert response.status_code == 400
    assert "not supported" in response.text


def test_bad_compression_is_400_and_compression_shrinks_the_jpeg(client):
    assert client.get(SNAPSHOT, params={"compression": "101"}).status_code == 400
    fine = client.get(SNAPSHOT, params={"compression": "0"})
    coarse = client.get(SNAPSHOT, params={"compression": "90"})
    assert len(coarse.content) < len(fine.content)


def test_unknown_path_is_404(client):
    assert client.get("/axis-cgi/nothing.cgi").status_code == 404
    assert client.get("/").status_code == 404


def test_fault_injection(client, server):
    server.fail_next(500, count=2)
    server.fail_next(garbage=True)
    assert [client.get(SNAPSHOT).status_code for _ in range(2)] == [500, 500]
    garbage = client.get(SNAPSHOT)
    assert garbage.status_code == 200 and not garbage.content.startswith(b"\xff\xd8")
    decode(client.get(SNAPSHOT))  # faults used up: a real snapshot again
    assert server.request_count == 4
    with pytest.raises(ValueError):
        server.fail_next()
    with pytest.raises(ValueError):
        server.fail_next(500, count=0)


def test_pose_provider_errors_are_500(target):
    def broken():
        raise RuntimeError("zenoh gone")

    for provider in (broken, lambda: np.eye(3)):
        with SimCameraServer(red_scene(SIM), K=K, pose_provider=provider, auth=None) as srv:
            with httpx.Client(base_url=srv.url, timeout=10.0) as c:
                assert c.get(SNAPSHOT).status_code == 500


def digest_header(user: str, password: str, nonce: str, uri: str, nc: int = 1, realm: str = "AXIS_SIMULATED") -> str:
    """An Authorization header computed by RFC 7616 (MD5, qop=auth), independently of the server."""
    def md5(text: str) -> str:
        return hashlib.md5(text.encode()).hexdigest()

    cnonce, count = "0a4f113b", f"{nc:08x}"
    response = md5(f"{md5(f'{user}:{realm}:{password}')}:{nonce}:{count}:{cnonce}:auth:{md5(f'GET:{uri}')}")
    return (f'Digest username="{user}", realm="{realm}", nonce="{nonce}", uri="{uri}", algorithm=MD5, '
            f'qop=auth, nc={count}, cnonce="{cnonce}", response="{response}"')


@pytest.fixture(scope="module")
def digest_server(target):
    pose = Pose(look_at(target + [0.25, 0.1, 0.35], target))
    with SimCameraServer(red_scene(SIM), K=scaled_K(K, (640, 480), (160, 120)), image_size=(160, 120),
                         pose_provider=pose, username="root", password="pass word", auth="digest") as srv:
        yield srv


def test_digest_auth(digest_server):
    with httpx.Client(base_url=digest_server.url, timeout=10.0) as c:
        assert c.get(SNAPSHOT).status_code == 401  # no credentials
        challenge = c.get(SNAPSHOT).headers["www-authenticate"]
        assert challenge.startswith("Digest ") and 'qop="auth"' in challenge and "algorithm=MD5" in challenge
        good = c.get(SNAPSHOT, auth=httpx.DigestAuth("root", "pass word"))
        assert decode(good).shape == (120, 160, 3)
        assert c.get(SNAPSHOT, auth=httpx.DigestAuth("root", "wrong")).status_code == 401
        assert c.get(SNAPSHOT, auth=httpx.DigestAuth("admin", "pass word")).status_code == 401
        # Replaying an accepted Authorization header (same nonce and count) is refused.
        replayed = c.get(SNAPSHOT, headers={"Authorization": good.request.headers["authorization"]})
        assert replayed.status_code == 401
        # A response computed here by RFC 7616 passes once, and only for the URI it covers.
        nonce = re.search(r'nonce="([^"]+)"', c.get(SNAPSHOT).headers["www-authenticate"])[1]
        header = digest_header("root", "pass word", nonce, SNAPSHOT, nc=1)
        assert c.get(SNAPSHOT + "?resolution=160x120", headers={"Authorization": header}).status_code == 401
        assert c.get(SNAPSHOT, headers={"Authorization": header}).status_code == 200
        assert c.get(SNAPSHOT, headers={"Authorization": header}).status_code == 401  # replay
        header = digest_header("root", "pass word", nonce, SNAPSHOT, nc=2)
        assert c.get(SNAPSHOT, headers={"Authorization": header}).status_code == 200
        # A nonce the server never issued is refused, flagged stale only when the password is right.
        forged = c.get(SNAPSHOT, headers={"Authorization": digest_header("root", "pass word", "0" * 32, SNAPSHOT)})
        assert forged.status_code == 401 and "stale=true" in forged.headers["www-authenticate"]
        # Auth guards every path, as on a real camera.
        assert c.get("/axis-cgi/param.cgi?action=list").status_code == 401


def test_basic_auth(target):
    pose = Pose(look_at(target + [0.25, 0.1, 0.35], target))
    with SimCameraServer(red_scene(SIM), K=K, pose_provider=pose, username="root", password="pw",
                         auth="basic") as srv, httpx.Client(base_url=srv.url, timeout=10.0) as c:
        params = {"action": "list", "group": "Properties.Image.Resolution"}
        refused = c.get("/axis-cgi/param.cgi", params=params, auth=httpx.BasicAuth("root", "nope"))
        assert refused.status_code == 401 and refused.headers["www-authenticate"].startswith("Basic ")
        assert c.get("/axis-cgi/param.cgi", params=params, auth=("root", "pw")).status_code == 200


def test_server_arguments_are_checked():
    with pytest.raises(ValueError, match="auth"):
        SimCameraServer([], K=K, pose_provider=lambda: None, auth="ntlm")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="password"):
        SimCameraServer([], K=K, pose_provider=lambda: None, username="root")
    srv = SimCameraServer([], K=K, pose_provider=lambda: None)
    with pytest.raises(RuntimeError):
        srv.port
    srv.stop()  # stopping a server never started is harmless


@pytest.mark.parametrize(
    ("shape", "kind"),
    [("box", SuperquadricObject), ("cylinder", SuperquadricObject), ("ellipsoid", SuperquadricObject),
     ("rounded-box", SuperquadricObject), ("cup-stack", CupStack), ("lumpy", LumpyFigure)],
)
def test_scene_from_config(shape, kind):
    sim = SimConfig(shape=shape, size=[0.025, 0.035, 0.05], position=[0.5, 0.1])
    (obj,) = scene_from_config(sim)
    if isinstance(obj, PrintedObject):  # [sim] look printed: the same object, printed
        obj = obj.object
    assert isinstance(obj, kind)
    v = obj.mesh()[0]
    assert v[:, 2].min() == pytest.approx(0.0, abs=1e-9)  # stands on the table
    np.testing.assert_allclose((v.min(axis=0) + v.max(axis=0))[:2] / 2, [0.5, 0.1], atol=0.02)


def test_truth_from_config():
    truth = truth_from_config(SimConfig(shape="box", size=[0.04, 0.03, 0.05], position=[0.6, 0.0], yaw_deg=90))
    assert truth["kind"] == "superquadric"
    assert truth["size"] == [0.04, 0.03, 0.05]
    np.testing.assert_allclose(np.asarray(truth["T_world_object"])[:3, 3], [0.6, 0.0, 0.05], atol=1e-12)
    np.testing.assert_allclose(np.asarray(truth["T_world_object"])[:2, 0], [0.0, 1.0], atol=1e-12)
    with pytest.raises(ConfigError, match="cup-stack"):
        scene_from_config(SimConfig(shape="cup-stack", size=[0.05, 0.03, 0.06]))  # rim narrower than base
