"""Grab JPEG snapshots from an Axis network camera (VAPIX ``image.cgi``) over HTTP.

Pure asyncio and httpx, no Zenoh: the camera worker wraps this class. One
snapshot is ``GET {url}/axis-cgi/jpg/image.cgi?resolution=WxH``, with HTTP
Digest (the Axis default) or Basic authentication. Every attempt has a
deadline; server errors, time-outs and lost connections are retried with
exponential backoff; refused credentials and a missing endpoint are not,
because asking again cannot help. httpx's exceptions are translated in one
place, :func:`_map_httpx_errors`. The password never appears in a message or
a log line: messages name :attr:`AxisCamera.source`, the URL without
credentials.

Examples
--------
>>> AxisCamera("http://root:secret@192.168.0.90/").source
'http://192.168.0.90'
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import logging
import re
import ssl
from collections.abc import Iterator
from typing import TYPE_CHECKING, Literal

import httpx

from robocell.core_cy.images import jpeg_size
from robocell.wire.errors import (CameraAuthError, CameraConnectionError, CameraError, CameraResponseError, CameraTimeout,
                         ConfigError)

from .backend import Camera, Snapshot

if TYPE_CHECKING:
    from robocell.wire.backends import AxisCameraConfig

__all__ = ["AxisCamera", "SNAPSHOT_PATH", "PARAM_PATH", "parse_resolutions"]

logger = logging.getLogger(__name__)

#: The VAPIX snapshot endpoint, relative to the camera's base URL.
SNAPSHOT_PATH = "/axis-cgi/jpg/image.cgi"
#: The VAPIX parameter list (the resolutions a camera offers), relative to the camera's base URL.
PARAM_PATH = "/axis-cgi/param.cgi"
_RESOLUTIONS = "Properties.Image.Resolution"
_SOI, _EOI = b"\xff\xd8", b"\xff\xd9"
_SNIPPET = 200  # characters of an error page quoted in a message


class _State(enum.Enum):
    UNOPENED = 1
    OPENED = 2
    CLOSED = 3


@contextlib.contextmanager
def _map_httpx_errors(source: str, timeout_s: float) -> Iterator[None]:
    """Turn httpx's (and the deadline's) exceptions into :class:`CameraError` subclasses.

    The one place where library exceptions are translated. httpx's own
    messages hold no credentials, since the URL handed to httpx has none.
    """
    try:
        yield
    except (httpx.TimeoutException, TimeoutError) as exc:
        raise CameraTimeout(f"camera at {source} did not answer within {timeout_s:g} s", source=source) from exc
    except httpx.ConnectError as exc:
        raise CameraConnectionError(f"cannot connect to camera at {source}: {exc}", source=source) from exc
    except httpx.HTTPError as exc:  # read/write errors, protocol errors, a malformed digest challenge
        raise CameraConnectionError(
            f"connection to camera at {source} failed: {type(exc).__name__}: {exc}", source=source
        ) from exc


def parse_resolutions(text: str) -> list[tuple[int, int]]:
    """The resolutions in an Axis ``param.cgi`` answer, in its order.

    Raises
    ------
    ValueError
        If the answer lists no resolutions (the message quotes its start).

    Examples
    --------
    >>> parse_resolutions("root.Properties.Image.Resolution=1920x1080,1280x720\\n")
    [(1920, 1080), (1280, 720)]
    """
    for line in text.splitlines():
        key, sep, value = line.partition("=")
        if sep and key.strip().endswith(_RESOLUTIONS):
            return [(int(w), int(h)) for w, h in re.findall(r"(\d+)x(\d+)", value)]
    raise ValueError(" ".join(text.split())[:_SNIPPET] or "empty answer")


def _snippet(response: httpx.Response) -> str:
    """The start of a text error page, on one line ("" for anything else)."""
    if not response.headers.get("content-type", "").startswith("text/"):
        return ""
    return " ".join(response.text.split())[:_SNIPPET]


class AxisCamera(Camera):
    """An Axis camera's snapshot endpoint; owns one ``httpx.AsyncClient``.

    Use it as ``async with AxisCamera(...) as camera: picture = await camera.snapshot()``.

    Parameters
    ----------
    url : str
        The camera's base URL, e.g. ``http://192.168.0.90``. Credentials in it
        (``http://user:pw@host``) are used when ``username`` is not given, and
        removed from :attr:`source`.
    resolution : (int, int)
        Width and height asked for, as ``resolution=WxH``.
    username, password : str or None
        Credentials; no authentication when ``username`` is None.
    auth : {"digest", "basic"}
        HTTP authentication scheme.
    timeout_s : float
        Deadline of one attempt, digest challenge round trip included.
    retries : int
        Further attempts after a server error (5xx), a time-out or a lost
        connection; a body that is not a JPEG is retried at most once.
    backoff_s : float
        Wait before the first retry; doubled before each further one.
    verify : bool or ssl.SSLContext
        TLS certificate verification for ``https`` URLs.
    compression : int or None
        Axis ``compression`` parameter, 0 (best quality) to 100.
    transport : httpx.AsyncBaseTransport or None
        A custom transport (tests use ``httpx.MockTransport``).

    Raises
    ------
    ValueError
        For a URL that is not http(s) or has no host, or an out-of-range parameter.
    """

    def __init__(
        self,
        url: str,
        *,
        resolution: tuple[int, int] = (640, 480),
        username: str | None = None,
        password: str | None = None,
        auth: Literal["digest", "basic"] = "digest",
        timeout_s: float = 3.0,
        retries: int = 2,
        backoff_s: float = 0.2,
        verify: bool | ssl.SSLContext = True,
        compression: int | None = None,
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> None:
        try:
            parsed = httpx.URL(url)
        except httpx.InvalidURL as exc:
            # httpx quotes the part it could not parse: with credentials in the URL, a password.
            raise ValueError("invalid camera URL" + (f": {exc}" if "@" not in url else
                                                     " (not shown: it holds credentials)")) from None
        safe = str(parsed.copy_with(username=None, password=None)).rstrip("/")
        if parsed.scheme not in ("http", "https") or not parsed.host:
            raise ValueError(f"camera URL must be http:// or https:// with a host, got {safe!r}")
        if username is None and parsed.username:
            username, password = parsed.username, parsed.password
        self._source = safe
        width, height = (int(v) for v in resolution)
        if width <= 0 or height <= 0:
            raise ValueError(f"resolution must be two positive integers, got {resolution!r}")
        if auth not in ("digest", "basic"):
            raise ValueError(f"auth must be 'digest' or 'basic', got {auth!r}")
        if timeout_s <= 0 or retries < 0 or backoff_s < 0:
            raise ValueError("need timeout_s > 0, retries >= 0 and backoff_s >= 0")
        if compression is not None and not 0 <= compression <= 100:
            raise ValueError(f"compression must lie in 0..100, got {compression}")
        self.resolution = (width, height)
        self._params: dict[str, str] = {"resolution": f"{width}x{height}"}
        if compression is not None:
            self._params["compression"] = str(int(compression))
        self._username = username
        self._auth: httpx.Auth | None = None
        if username is not None:
            scheme = httpx.DigestAuth if auth == "digest" else httpx.BasicAuth
            self._auth = scheme(username, password or "")
        self._timeout_s, self._retries, self._backoff_s = float(timeout_s), int(retries), float(backoff_s)
        self._verify, self._transport = verify, transport
        self._client: httpx.AsyncClient | None = None
        self._state = _State.UNOPENED

    @classmethod
    def from_config(cls, camera: AxisCameraConfig, *, transport: httpx.AsyncBaseTransport | None = None) -> AxisCamera:
        """The camera described by the cell's ``[camera]`` section (password from the environment first).

        ``verify`` may name a CA bundle: the certificate check then trusts that CA.

        Raises
        ------
        ConfigError
            If the CA bundle cannot be read, or a user has no password.
        """
        verify = camera.verify
        if isinstance(verify, str):
            try:
                verify = ssl.create_default_context(cafile=verify)
            except (OSError, ssl.SSLError) as exc:
                raise ConfigError(f"camera.verify: cannot use {camera.verify!r} as a CA bundle: "
                                  f"{exc.strerror or exc}") from None
        username, password = camera.credentials()
        return cls(
            camera.url, resolution=tuple(camera.resolution), username=username,
            password=password, auth=camera.auth, timeout_s=camera.timeout_s,
            retries=camera.retries, verify=verify, compression=camera.compression, transport=transport,
        )

    @property
    def source(self) -> str:
        """The camera's URL without credentials: safe to log and to show."""
        return self._source

    @property
    def endpoint(self) -> str:
        """The snapshot URL without credentials or query."""
        return self._source + SNAPSHOT_PATH

    def __repr__(self) -> str:
        return f"AxisCamera({self._source!r}, resolution={self.resolution!r})"

    async def open(self) -> None:
        if self._state is not _State.UNOPENED:
            raise RuntimeError("an AxisCamera can be opened only once")
        # Per-operation httpx time-outs, plus the attempt's overall deadline in snapshot():
        # a camera that trickles bytes would otherwise never trip a read time-out.
        self._client = httpx.AsyncClient(
            auth=self._auth, timeout=httpx.Timeout(self._timeout_s), verify=self._verify,
            transport=self._transport, follow_redirects=False, trust_env=False,
        )
        self._state = _State.OPENED

    async def close(self) -> None:
        """Close the HTTP client; idempotent."""
        self._state = _State.CLOSED
        if self._client is not None:
            client, self._client = self._client, None
            await client.aclose()

    async def snapshot(self) -> Snapshot:
        """Grab one JPEG, retrying transient failures.

        Returns
        -------
        Snapshot
            The JPEG exactly as the camera sent it, and its size as its header gives it.

        Raises
        ------
        CameraAuthError
            The credentials were refused (HTTP 401/403); not retried.
        CameraResponseError
            No snapshot endpoint (404, not retried), another bad status, a
            server error (5xx) on every attempt, or a body that is not a JPEG.
        CameraTimeout, CameraConnectionError
            On every attempt.
        RuntimeError
            Outside ``async with``.
        """
        if self._state is not _State.OPENED:
            raise RuntimeError("use AxisCamera inside 'async with' before calling snapshot()")
        not_jpeg_retried = False
        attempts = self._retries + 1
        for attempt in range(1, attempts + 1):
            try:
                return await self._attempt()
            except CameraError as exc:
                transient = exc.status is None or exc.status >= 500
                if exc.status == 200 and not not_jpeg_retried:  # a torn frame may not repeat
                    transient, not_jpeg_retried = True, True
                if not transient or attempt == attempts:
                    if attempt > 1:
                        exc.args = (f"{exc}; gave up after {attempt} attempts",)
                    raise
                delay = self._backoff_s * 2 ** (attempt - 1)
                logger.warning("%s; retrying in %.2f s (attempt %d of %d)", exc, delay, attempt + 1, attempts)
                await asyncio.sleep(delay)
        raise AssertionError("unreachable")  # the loop returns or raises

    async def resolutions(self) -> list[tuple[int, int]]:
        """The resolutions the camera offers (VAPIX ``param.cgi``), in its order; one attempt.

        Raises
        ------
        CameraAuthError, CameraResponseError, CameraTimeout, CameraConnectionError
            As :meth:`snapshot`; a :class:`CameraResponseError` also for an answer that lists none.
        RuntimeError
            Outside ``async with``.
        """
        if self._state is not _State.OPENED:
            raise RuntimeError("use AxisCamera inside 'async with' before calling resolutions()")
        assert self._client is not None
        endpoint = self._source + PARAM_PATH
        with _map_httpx_errors(self._source, self._timeout_s):
            async with asyncio.timeout(self._timeout_s):
                response = await self._client.get(endpoint, params={"action": "list", "group": _RESOLUTIONS})
        self._check_status(response, endpoint, "parameter list")
        try:
            return parse_resolutions(response.text)
        except ValueError as exc:
            raise CameraResponseError(f"camera at {self._source} lists no resolutions: {exc}",
                                      source=self._source, status=response.status_code) from None

    async def _attempt(self) -> Snapshot:
        assert self._client is not None
        with _map_httpx_errors(self._source, self._timeout_s):
            async with asyncio.timeout(self._timeout_s):
                response = await self._client.get(self.endpoint, params=self._params)
        return self._check(response)

    def _check_status(self, response: httpx.Response, endpoint: str, what: str) -> None:
        """Nothing for HTTP 200; a :class:`CameraError` for any other status."""
        status, src = response.status_code, self._source
        if status in (401, 403):
            if self._username is None:
                msg = f"camera at {src} requires credentials (HTTP {status}) and none are configured"
            else:
                msg = f"camera at {src} refused the credentials of user {self._username!r} (HTTP {status})"
            raise CameraAuthError(msg, source=src, status=status)
        if status == 404:
            msg = f"no VAPIX {what} endpoint at {endpoint} (HTTP 404)"
            raise CameraResponseError(msg, source=src, status=404)
        if status != 200:
            detail = _snippet(response)
            msg = f"camera at {src} answered HTTP {status} {response.reason_phrase}" + (f": {detail}" if detail else "")
            raise CameraResponseError(msg, source=src, status=status)

    def _check(self, response: httpx.Response) -> Snapshot:
        """The JPEG of a good answer; a :class:`CameraError` for anything else."""
        src = self._source
        self._check_status(response, self.endpoint, "snapshot")
        body = response.content
        ctype = response.headers.get("content-type", "").split(";")[0].strip().lower()
        problem, size = None, None
        if ctype != "image/jpeg":
            problem = f"content-type is {ctype or 'missing'!r}"
        elif not body.startswith(_SOI):
            problem = "the body does not start with the JPEG marker FF D8"
        elif not body.endswith(_EOI):
            problem = "the body does not end with the JPEG marker FF D9 (truncated?)"
        elif (size := jpeg_size(body)) is None:
            problem = "the body has no JPEG frame header"
        if problem is not None or size is None:
            raise CameraResponseError(f"camera at {src} answered, but not a JPEG: {problem}", source=src, status=200)
        logger.debug("snapshot from %s: %d bytes", src, len(body))
        return Snapshot(body, *size)
