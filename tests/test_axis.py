"""Tests of the Axis snapshot grabber (workers.axis) against the real simulated camera on loopback.

Protocol edge cases a real server cannot easily produce go through
``httpx.MockTransport`` at the end.
"""
from __future__ import annotations

import asyncio
import logging
import socket

import cv2
import httpx
import numpy as np
import pytest

from robocell.wire.backends import AxisCameraConfig as CameraConfig
from robocell.wire.config import SimConfig
from robocell.wire.errors import (CameraAuthError, CameraConnectionError, CameraError, CameraResponseError, CameraTimeout,
                         ConfigError)
from robocell.workers.sim.scans import default_K, look_at, object_target
from robocell.workers.camera.axis import AxisCamera
from robocell.workers.sim.scene import scene_from_config
from robocell.workers.sim.axis import SimCameraServer

PASSWORD = "s3cret-Pa55"
SIZE = (320, 240)  # small renders keep the tests quick
FAST = {"backoff_s": 0.01, "timeout_s": 5.0}
#: A real JPEG, 32x24: a camera may send any bytes, but they must be a JPEG with a frame header.
TINY_JPEG = cv2.imencode(".jpg", np.full((24, 32, 3), 128, np.uint8))[1].tobytes()


def grab(url: str, **kwargs) -> bytes:
    """One snapshot through a fresh AxisCamera, opened and closed around it."""
    async def go() -> bytes:
        async with AxisCamera(url, resolution=SIZE, **kwargs) as camera:
            return (await camera.snapshot()).data

    return asyncio.run(go())


def decodes(jpeg: bytes) -> tuple[int, ...]:
    image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert image is not None
    return image.shape


def sim_server(auth: str | None) -> SimCameraServer:
    scene = scene_from_config(SimConfig())
    target = object_target(scene[0])
    pose = look_at(target + [0.25, 0.1, 0.35], target)
    return SimCameraServer(scene, K=default_K(SIZE), image_size=SIZE, pose_provider=lambda: pose,
                           username="root", password=PASSWORD, auth=auth)


@pytest.fixture
def server():
    with sim_server("digest") as srv:
        yield srv


@pytest.fixture
def open_server():
    with sim_server(None) as srv:
        yield srv


def test_digest_auth(server):
    jpeg = grab(server.url, username="root", password=PASSWORD, **FAST)
    assert jpeg[:2] == b"\xff\xd8" and jpeg[-2:] == b"\xff\xd9"
    assert decodes(jpeg) == (240, 320, 3)


def test_basic_auth():
    with sim_server("basic") as srv:
        jpeg = grab(srv.url, username="root", password=PASSWORD, auth="basic", **FAST)
    assert decodes(jpeg) == (240, 320, 3)


def test_credentials_in_the_url_are_used_and_hidden(server):
    url = server.url.replace("http://", f"http://root:{PASSWORD}@")
    assert AxisCamera(url).source == server.url
    assert decodes(grab(url, **FAST)) == (240, 320, 3)


def test_wrong_password_is_an_auth_error_without_the_password(server, caplog):
    caplog.set_level(logging.DEBUG)
    with pytest.raises(CameraAuthError, match="refused the credentials") as info:
        grab(server.url, username="root", password="wrong-" + PASSWORD, retries=3, **FAST)
    assert info.value.status == 401 and server.url in str(info.value)
    assert PASSWORD not in str(info.value) and PASSWORD not in caplog.text
    assert "retrying" not in caplog.text  # refused credentials are not retried
    assert server.request_count == 0


def test_missing_credentials_say_so(server):
    with pytest.raises(CameraAuthError, match="requires credentials"):
        grab(server.url, **FAST)


def test_no_snapshot_endpoint_is_404(open_server, caplog):
    url = open_server.url + "/no/such/camera"
    with pytest.raises(CameraResponseError, match="no VAPIX snapshot endpoint at") as info:
        grab(url, **FAST)
    assert info.value.status == 404 and f"{url}/axis-cgi/jpg/image.cgi" in str(info.value)
    assert "retrying" not in caplog.text


def test_server_error_then_success_within_retries(server):
    server.fail_next(500, count=1)
    jpeg = grab(server.url, username="root", password=PASSWORD, retries=2, **FAST)
    assert decodes(jpeg) == (240, 320, 3)
    assert server.request_count == 2


def test_server_errors_beyond_retries(server):
    server.fail_next(500, count=3)
    with pytest.raises(CameraResponseError, match="HTTP 500") as info:
        grab(server.url, username="root", password=PASSWORD, retries=2, **FAST)
    assert info.value.status == 500 and "gave up after 3 attempts" in str(info.value)
    assert server.request_count == 3


def test_no_pose_yet_names_the_reason(open_server):
    with SimCameraServer([], K=default_K(SIZE), image_size=SIZE, pose_provider=lambda: None, auth=None) as srv:
        with pytest.raises(CameraResponseError, match="HTTP 503.*no robot pose yet"):
            grab(srv.url, retries=1, **FAST)


def test_garbage_body_is_not_a_jpeg(open_server):
    open_server.fail_next(garbage=True, count=5)
    with pytest.raises(CameraResponseError, match="not a JPEG"):
        grab(open_server.url, retries=4, **FAST)
    assert open_server.request_count == 2  # retried once only: a camera that keeps sending HTML won't stop


def test_hang_longer_than_the_timeout(open_server):
    open_server.fail_next(hang_s=30.0)  # stop() at teardown cuts the hang short
    with pytest.raises(CameraTimeout, match="did not answer within 0.2 s") as info:
        grab(open_server.url, timeout_s=0.2, retries=0)
    assert open_server.url in str(info.value)


def test_hang_then_success_within_retries(open_server):
    """The timed-out request is abandoned mid-flight; the retry gets a fresh connection."""
    open_server.fail_next(hang_s=30.0)
    assert decodes(grab(open_server.url, timeout_s=1.5, retries=1, backoff_s=0.01)) == (240, 320, 3)
    assert open_server.request_count == 2


def test_stopped_server_does_not_answer_on_a_kept_alive_connection():
    async def go(srv: SimCameraServer) -> None:
        async with AxisCamera(srv.url, resolution=SIZE, retries=0, **FAST) as camera:
            decodes((await camera.snapshot()).data)
            srv.stop()
            with pytest.raises(CameraConnectionError):
                await camera.snapshot()

    with sim_server(None) as srv:
        asyncio.run(go(srv))


def test_nothing_listening():
    with socket.socket() as s:  # a port that was free a moment ago
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"http://127.0.0.1:{port}"
    with pytest.raises(CameraConnectionError, match=f"cannot connect to camera at {url}") as info:
        grab(url, retries=1, **FAST)
    assert "gave up after 2 attempts" in str(info.value)


def test_from_config(server, monkeypatch):
    monkeypatch.setenv("ROBOCELL_CAMERA_PASSWORD", PASSWORD)
    config = CameraConfig(url=server.url, resolution=SIZE, username="root", password="stale-in-file")
    camera = AxisCamera.from_config(config)
    assert camera.resolution == SIZE and camera.source == server.url

    async def go() -> bytes:
        async with camera:
            return await camera.snapshot()

    picture = asyncio.run(go())
    assert decodes(picture.data) == (240, 320, 3)
    assert (picture.width, picture.height, picture.encoding) == (320, 240, "image/jpeg")


def test_from_config_names_what_is_missing(tmp_path, monkeypatch):
    monkeypatch.delenv("ROBOCELL_CAMERA_PASSWORD", raising=False)
    with pytest.raises(ConfigError, match="camera.username is 'root', but it has no password: set "
                                          "ROBOCELL_CAMERA_PASSWORD"):
        AxisCamera.from_config(CameraConfig(username="root"))
    missing = tmp_path / "ca.pem"
    with pytest.raises(ConfigError, match=f"camera.verify: cannot use '{missing}' as a CA bundle: No such file"):
        AxisCamera.from_config(CameraConfig(url="https://camera.test", verify=str(missing)))


def test_a_url_that_cannot_be_parsed_is_not_echoed_when_it_holds_credentials():
    with pytest.raises(ValueError, match=r"invalid camera URL \(not shown: it holds credentials\)") as info:
        AxisCamera("http://root:Hunter2/x@camera.test")
    assert "Hunter2" not in str(info.value)


# -- protocol edge cases through httpx.MockTransport ------------------------------------------


def mock_grab(handler, **kwargs) -> bytes:
    return grab("http://camera.test/", transport=httpx.MockTransport(handler), **FAST, **kwargs)


def test_html_with_200_is_not_a_jpeg():
    """A proxy's login page answers 200 text/html: not a snapshot, whatever the body."""
    def handler(request: httpx.Request) -> httpx.Response:
        return httpx.Response(200, headers={"content-type": "text/html"}, content=b"\xff\xd8<html></html>\xff\xd9")

    with pytest.raises(CameraResponseError, match="not a JPEG: content-type is 'text/html'"):
        mock_grab(handler, retries=0)


def test_request_parameters_and_unchanged_bytes():
    seen = []
    body = TINY_JPEG

    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request)
        return httpx.Response(200, headers={"content-type": "image/jpeg; charset=binary"}, content=body)

    assert mock_grab(handler, compression=30) == body
    (request,) = seen
    assert request.url.path == "/axis-cgi/jpg/image.cgi"
    assert dict(request.url.params) == {"resolution": "320x240", "compression": "30"}


def test_truncated_jpeg_is_retried_once():
    calls = []

    def handler(request: httpx.Request) -> httpx.Response:
        calls.append(request)
        body = TINY_JPEG[:-20] if len(calls) == 1 else TINY_JPEG
        return httpx.Response(200, headers={"content-type": "image/jpeg"}, content=body)

    assert mock_grab(handler, retries=2).endswith(b"\xff\xd9")
    assert len(calls) == 2
    calls.clear()
    with pytest.raises(CameraResponseError, match=r"not a JPEG: .*FF D9 \(truncated\?\)"):
        mock_grab(handler, retries=0)  # retries=0 means one request, whatever went wrong
    assert len(calls) == 1


def test_lifecycle_and_arguments():
    camera = AxisCamera("http://camera.test")

    async def misuse() -> None:
        with pytest.raises(RuntimeError, match="async with"):
            await camera.snapshot()
        async with camera:
            pass
        with pytest.raises(RuntimeError):
            await camera.snapshot()
        with pytest.raises(RuntimeError, match="only once"):
            await camera.__aenter__()

    asyncio.run(misuse())
    for bad in ({"resolution": (0, 480)}, {"auth": "ntlm"}, {"timeout_s": 0}, {"retries": -1}, {"compression": 101}):
        with pytest.raises(ValueError):
            AxisCamera("http://camera.test", **bad)
    with pytest.raises(ValueError, match="http"):
        AxisCamera("ftp://camera.test")
    assert issubclass(CameraTimeout, CameraError)


def test_a_body_without_a_frame_header_is_not_a_jpeg():
    """The snapshot reports the picture's real size, read from its header: a body without one is refused."""
    def handler(request: httpx.Request) -> httpx.Response:
        return httpx.Response(200, headers={"content-type": "image/jpeg"}, content=b"\xff\xd8 no frame \xff\xd9")

    with pytest.raises(CameraResponseError, match="not a JPEG: the body has no JPEG frame header"):
        mock_grab(handler, retries=0)
