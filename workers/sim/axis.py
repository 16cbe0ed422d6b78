"""A simulated Axis camera: the VAPIX snapshot endpoint, rendered from the robot's pose.

:class:`SimCameraServer` answers ``GET /axis-cgi/jpg/image.cgi?resolution=WxH`` with
a JPEG of the simulated scene (``workers.sim.render``) seen from ``pose_provider()``, and
``GET /axis-cgi/param.cgi?action=list&group=Properties.Image.Resolution`` with the
resolutions it offers, as an Axis camera does: a real HTTP server (stdlib), with
optional Digest (RFC 7616, MD5, qop=auth) or Basic authentication, so the camera
worker runs unchanged against it. ``pose_provider`` is a plain callable: where the
pose comes from (Zenoh) is the caller's business. :meth:`SimCameraServer.fail_next`
injects faults for tests of the cell.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import http.server
import logging
import re
import secrets
import socket
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal
from urllib.parse import parse_qs, urlsplit

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .camera import SceneCamera
from .objects import SimObject

__all__ = ["SimCameraServer"]

logger = logging.getLogger(__name__)

PoseProvider = Callable[[], "NDArray[np.float64] | None"]
_REALM = "AXIS_SIMULATED"
_NONCE_LIFETIME_S = 300.0
_MAX_NONCES = 1024  # oldest forgotten first: a client then gets stale=true and retries
_STOP_JOIN_S = 2.0  # how long stop() waits for request threads in total
# Axis's usual 4:3 and 16:9 resolutions; the server offers those of its own aspect ratio.
_AXIS_RESOLUTIONS = [(1920, 1080), (1280, 960), (1280, 720), (1024, 768), (800, 600), (800, 450),
                     (640, 480), (640, 360), (480, 360), (480, 270), (320, 240), (320, 180), (240, 180), (160, 120)]
_DIGEST_PARAM = re.compile(r'(\w+)\s*=\s*(?:"((?:[^"\\]|\\.)*)"|([^\s,]+))')


@dataclass
class _Fault:
    status: int | None
    garbage: bool
    hang_s: float
    count: int


class _Server(http.server.ThreadingHTTPServer):
    """Tracks its request threads and sockets so that stop() can end them in bounded time."""

    daemon_threads = True
    block_on_close = False  # stop() joins with a deadline instead

    def __init__(self, address: tuple[str, int], sim: SimCameraServer) -> None:
        self.sim = sim
        self.live: dict[threading.Thread, socket.socket] = {}
        self.live_lock = threading.Lock()
        super().__init__(address, _Handler)

    def process_request(self, request: Any, client_address: Any) -> None:
        t = threading.Thread(target=self.process_request_thread, args=(request, client_address), daemon=True)
        with self.live_lock:
            self.live = {th: s for th, s in self.live.items() if th.is_alive()}
            self.live[t] = request
        t.start()

    def handle_error(self, request: Any, client_address: Any) -> None:
        # A client that gave up (time-out) leaves a broken pipe: routine, not a traceback on stderr.
        logger.debug("request from %s failed", client_address, exc_info=True)


class _Handler(http.server.BaseHTTPRequestHandler):
    server: _Server
    protocol_version = "HTTP/1.1"  # keep-alive, as a real camera; needed for digest's two requests
    server_version = "SimAxis/1.0"

    def log_message(self, format: str, *args: Any) -> None:
        logger.debug("%s " + format, self.client_address[0], *args)

    def reply(self, status: int, body: bytes | str, headers: Sequence[tuple[str, str]] = ()) -> None:
        """Send ``body``: text as text/plain, bytes as image/jpeg (even fault-injected garbage)."""
        text = isinstance(body, str)
        data = body.encode() if isinstance(body, str) else body
        self.send_response(status)
        self.send_header("Content-Type", "text/plain; charset=utf-8" if text else "image/jpeg")
        self.send_header("Content-Length", str(len(data)))
        self.send_header("Cache-Control", "no-cache")
        for key, value in headers:
            self.send_header(key, value)
        self.end_headers()
        self.wfile.write(data)

    def do_GET(self) -> None:
        sim = self.server.sim
        challenge = sim._check_auth(self.headers.get("Authorization"), self.path)
        if challenge is not None:
            self.reply(401, "Unauthorized: credentials required or refused\n", [("WWW-Authenticate", challenge)])
            return
        url = urlsplit(self.path)
        query = {k: v[-1] for k, v in parse_qs(url.query, keep_blank_values=True).items()}
        if url.path == "/axis-cgi/jpg/image.cgi":
            self.reply(*sim._snapshot(query))
        elif url.path == "/axis-cgi/param.cgi":
            self.reply(*sim._params(query))
        else:
            self.reply(404, f"Not found: {url.path}\n")


class SimCameraServer:
    """A simulated Axis camera serving renders of ``scene_objects`` over HTTP.

    Parameters
    ----------
    scene_objects : sequence of SimObject
        What stands on the table (see :func:`workers.sim.scene.scene_from_config`).
    K : (3, 3) array_like
        Pinhole matrix at ``image_size``; scaled for other resolutions.
    image_size : (int, int)
        The camera's native (width, height).
    dist : array_like or None
        OpenCV distortion coefficients.
    pose_provider : callable returning a (4, 4) array or None
        The camera's current pose T_world_cam (camera-to-world, OpenCV axes);
        None while unknown, answered with 503. Called from request threads.
    host, port : where to listen; port 0 picks a free port.
    username, password : credentials required when ``username`` and ``auth`` are set.
    auth : {"digest", "basic", None}
    seed : the table's look and the sensor noise (noise also varies per request).
    jpeg_quality : JPEG quality when the request gives no ``compression``.
    """

    def __init__(
        self,
        scene_objects: Sequence[SimObject],
        *,
        K: ArrayLike,
        image_size: tuple[int, int] = (640, 480),
        dist: ArrayLike | None = None,
        pose_provider: PoseProvider,
        host: str = "127.0.0.1",
        port: int = 0,
        username: str | None = None,
        password: str | None = None,
        auth: Literal["digest", "basic"] | None = "digest",
        seed: int = 0,
        jpeg_quality: int = 90,
    ) -> None:
        if auth not in ("digest", "basic", None):
            raise ValueError(f"auth must be 'digest', 'basic' or None, got {auth!r}")
        if username is not None and auth is not None and password is None:
            raise ValueError("a username needs a password")
        self._camera = SceneCamera(scene_objects, K=K, image_size=image_size, dist=dist, seed=seed,
                                   jpeg_quality=jpeg_quality)
        self._size = self._camera.image_size
        self._pose_provider = pose_provider
        self._address = (host, int(port))
        self._username, self._password = username, password
        self._auth = auth if username is not None else None
        w, h = self._size
        sizes = {r for r in _AXIS_RESOLUTIONS if r[0] * h == r[1] * w} | {self._size}
        self.resolutions = sorted(sizes, key=lambda r: (-r[0], -r[1]))
        self._lock = threading.Lock()  # guards the counters, faults and nonces below
        self._requests = 0
        self._faults: list[_Fault] = []
        self._nonces: OrderedDict[str, tuple[float, set[int]]] = OrderedDict()
        self._opaque = secrets.token_hex(16)
        self._stopping = threading.Event()
        self._server: _Server | None = None
        self._thread: threading.Thread | None = None

    @property
    def scene_camera(self) -> SceneCamera:
        """What renders the pictures (its ``object_present`` empties the workspace)."""
        return self._camera

    # -- lifecycle -------------------------------------------------------------------------

    def start(self) -> None:
        """Bind and serve in a background thread."""
        if self._server is not None:
            raise RuntimeError("SimCameraServer already started")
        self._stopping.clear()
        self._server = _Server(self._address, self)
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05},
                                        name=f"sim-camera:{self.port}", daemon=True)
        self._thread.start()
        logger.info("simulated Axis camera at %s", self.url)

    def stop(self) -> None:
        """Stop serving, wake delayed answers, close connections; returns within a few seconds."""
        server, self._server = self._server, None
        if server is None:
            return
        self._stopping.set()
        server.shutdown()
        assert self._thread is not None
        self._thread.join(_STOP_JOIN_S)
        with server.live_lock:
            live = dict(server.live)
        for sock in live.values():  # ends keep-alive connections blocked reading the next request
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        deadline = time.monotonic() + _STOP_JOIN_S
        for thread in live:
            thread.join(max(0.0, deadline - time.monotonic()))
        server.server_close()

    def __enter__(self) -> SimCameraServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def port(self) -> int:
        if self._server is None:
            raise RuntimeError("SimCameraServer not started")
        return int(self._server.server_address[1])

    @property
    def url(self) -> str:
        host = self._address[0]
        return f"http://{f'[{host}]' if ':' in host else host}:{self.port}"

    @property
    def request_count(self) -> int:
        """Snapshot requests answered so far (authenticated ones only)."""
        with self._lock:
            return self._requests

    def fail_next(self, status: int | None = None, *, garbage: bool = False, hang_s: float = 0.0,
                  count: int = 1) -> None:
        """Make the next ``count`` snapshot requests misbehave.

        ``hang_s`` waits before answering (cut short by :meth:`stop`); then
        ``status`` answers that status, ``garbage`` answers 200 with a body that
        is not a JPEG, and neither answers normally. Calls queue up in order.
        """
        if status is None and not garbage and hang_s <= 0:
            raise ValueError("fail_next needs a status, garbage=True or hang_s > 0")
        if (status is not None and not 100 <= status <= 599) or count < 1:
            raise ValueError("status must be an HTTP status (100-599) and count >= 1")
        with self._lock:
            self._faults.append(_Fault(status, garbage, float(hang_s), int(count)))

    def clear_faults(self) -> None:
        """Forget the faults :meth:`fail_next` queued that have not happened yet (a hang under way
        goes on)."""
        with self._lock:
            self._faults.clear()

    # -- request handling (called from request threads) ------------------------------------

    def _snapshot(self, query: dict[str, str]) -> tuple[int, bytes | str]:
        with self._lock:
            self._requests += 1
            fault = self._faults[0] if self._faults else None
            if fault is not None:
                fault.count -= 1
                if fault.count == 0:
                    self._faults.pop(0)
        if fault is not None:
            if fault.hang_s > 0 and self._stopping.wait(fault.hang_s):
                return 503, "Service Unavailable: camera shutting down\n"
            if fault.status is not None:
                return fault.status, f"Simulated fault: HTTP {fault.status}\n"
            if fault.garbage:
                return 200, b"<html><body>not an image</body></html>"
        size = self._size
        if "resolution" in query:
            m = re.fullmatch(r"(\d+)x(\d+)", query["resolution"])
            if m is None or (int(m[1]), int(m[2])) not in self.resolutions:
                return 400, f"Error: resolution {query['resolution']!r} not supported\n"
            size = (int(m[1]), int(m[2]))
        quality = None
        if "compression" in query:
            if not query["compression"].isdigit() or int(query["compression"]) > 100:
                return 400, f"Error: compression {query['compression']!r} not in 0..100\n"
            quality = max(1, 100 - int(query["compression"]))
        try:
            pose = self._pose_provider()
        except Exception:  # a provider bug must not kill the request thread silently
            logger.exception("pose_provider failed")
            return 500, "Internal error: pose_provider failed\n"
        if pose is None:
            return 503, "Service Unavailable: no robot pose yet\n"
        try:
            return 200, self._camera.jpeg(pose, size=size, quality=quality)
        except ValueError as exc:
            logger.error("cannot render: %s", exc)
            return 500, f"Internal error: {exc}\n"

    def _params(self, query: dict[str, str]) -> tuple[int, str]:
        if query.get("action") != "list":
            return 400, "# Error: only action=list is supported\n"
        group = query.get("group", "")
        if group not in ("Properties.Image.Resolution", "Properties.Image", "Properties", "root.Properties"):
            return 200, f"# Error: Error -1 getting param in group '{group}'\n"
        listed = ",".join(f"{w}x{h}" for w, h in self.resolutions)
        return 200, f"root.Properties.Image.Resolution={listed}\n"

    # -- authentication ----------------------------------------------------------------------

    def _check_auth(self, header: str | None, uri: str) -> str | None:
        """None if the request may pass, else the WWW-Authenticate challenge to send."""
        if self._auth is None:
            return None
        assert self._username is not None and self._password is not None
        if self._auth == "basic":
            expected = base64.b64encode(f"{self._username}:{self._password}".encode())
            given = header[6:].strip().encode() if header and header[:6].lower() == "basic " else b""
            return None if hmac.compare_digest(given, expected) else f'Basic realm="{_REALM}"'
        stale = False
        if header and header[:7].lower() == "digest ":
            pairs = _DIGEST_PARAM.finditer(header[7:])
            fields = {m[1].lower(): m[2] if m[2] is not None else m[3] for m in pairs}
            verdict = self._verify_digest(fields, uri)
            if verdict == "ok":
                return None
            stale = verdict == "stale"
        nonce = secrets.token_hex(16)
        with self._lock:
            self._nonces[nonce] = (time.monotonic(), set())
            while len(self._nonces) > _MAX_NONCES:
                self._nonces.popitem(last=False)
        return (f'Digest realm="{_REALM}", nonce="{nonce}", algorithm=MD5, qop="auth", '
                f'opaque="{self._opaque}"' + (", stale=true" if stale else ""))

    def _verify_digest(self, f: dict[str, str], uri: str) -> Literal["ok", "stale", "bad"]:
        """RFC 7616 with MD5 and qop=auth; each nonce count is accepted once (no replays)."""
        need = ("username", "realm", "nonce", "uri", "response", "qop", "nc", "cnonce")
        if any(k not in f for k in need) or f.get("algorithm", "MD5").upper() != "MD5" or f["qop"] != "auth":
            return "bad"
        if f["realm"] != _REALM or f["uri"] != uri or not re.fullmatch(r"[0-9a-fA-F]{8}", f["nc"]):
            return "bad"

        def md5(text: str) -> str:
            return hashlib.md5(text.encode(), usedforsecurity=False).hexdigest()

        ha1 = md5(f"{self._username}:{_REALM}:{self._password}")
        ha2 = md5(f"GET:{uri}")
        expected = md5(f"{ha1}:{f['nonce']}:{f['nc']}:{f['cnonce']}:auth:{ha2}")
        # Both comparisons always run, in constant time, so timing reveals neither the user nor the hash.
        same_user = hmac.compare_digest(f["username"].encode(), self._username.encode())
        if not (hmac.compare_digest(expected.encode(), f["response"].lower().encode()) & same_user):
            return "bad"
        with self._lock:
            entry = self._nonces.get(f["nonce"])
            if entry is None or time.monotonic() - entry[0] > _NONCE_LIFETIME_S:
                self._nonces.pop(f["nonce"], None)
                return "stale"  # right password, old nonce: the client may retry at once
            nc = int(f["nc"], 16)
            if nc in entry[1]:
                return "bad"
            entry[1].add(nc)
        return "ok"
