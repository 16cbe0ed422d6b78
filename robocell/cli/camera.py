"""``robocell camera probe URL``: which resolutions an Axis camera offers, and one timed snapshot.

Both go through the grabber the camera worker uses (``workers.camera.axis``),
so that a camera's errors read here as they will in the cell.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import time
from typing import Any

from .command import Commands

__all__ = ["register", "probe"]


def register(commands: Commands) -> None:
    camera = commands.group("camera", help="check a network camera")
    probe_parser = camera.add("probe", _probe, help="list an Axis camera's resolutions and time one snapshot")
    probe_parser.add_argument("url", metavar="URL")
    probe_parser.add_argument("--user", help="user name (the password comes from the environment)")
    probe_parser.add_argument("--password-env", default="ROBOCELL_CAMERA_PASSWORD", metavar="VAR",
                              help="environment variable holding the password (default %(default)s)")
    probe_parser.add_argument("--auth", choices=["digest", "basic"], default="digest")
    probe_parser.add_argument("--resolution", metavar="WxH", help="snapshot size (default 640x480 if offered)")
    probe_parser.add_argument("--timeout", type=float, default=5.0, help="seconds per request (default %(default)s)")
    probe_parser.add_argument("--insecure", action="store_true", help="do not check the HTTPS certificate")
    probe_parser.add_argument("--json", action="store_true", help="print one JSON object")


async def probe(url: str, *, username: str | None = None, password: str | None = None, auth: str = "digest",
                resolution: tuple[int, int] | None = None, timeout_s: float = 5.0,
                verify: bool = True) -> dict[str, Any]:
    """What the camera at ``url`` offers, and whether (and how fast) it gives a snapshot.

    Returns ``{"url", "resolutions" (list of [w, h], or None), "resolutions_error",
    "snapshot": {"ok", "resolution", "bytes", "width", "height", "time_ms", "error"}}``.
    The snapshot uses ``resolution``, else 640x480 if offered, else the first offered.
    """
    import cv2
    import numpy as np

    from robocell.wire.errors import CameraError
    from robocell.workers.camera.axis import AxisCamera

    camera_args = {"username": username, "password": password, "auth": auth, "timeout_s": timeout_s,
                   "verify": verify, "retries": 0}
    result: dict[str, Any] = {"url": None, "resolutions": None, "resolutions_error": None}
    async with AxisCamera(url, **camera_args) as camera:
        result["url"] = camera.source
        try:
            result["resolutions"] = [list(r) for r in await camera.resolutions()]
        except CameraError as exc:
            result["resolutions_error"] = str(exc)
    offered = [tuple(r) for r in result["resolutions"] or []]
    size = resolution or ((640, 480) if (640, 480) in offered or not offered else offered[0])
    shot: dict[str, Any] = {"ok": False, "resolution": list(size), "bytes": None, "width": None, "height": None,
                            "time_ms": None, "error": None}
    try:
        async with AxisCamera(url, resolution=size, **camera_args) as camera:
            began = time.perf_counter()
            jpeg = (await camera.snapshot()).data
            shot["time_ms"] = 1000 * (time.perf_counter() - began)
        image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_UNCHANGED)
        shot["bytes"] = len(jpeg)
        if image is None:
            shot["error"] = "the JPEG does not decode"
        else:
            shot.update(ok=True, width=image.shape[1], height=image.shape[0])
    except CameraError as exc:
        shot["error"] = str(exc)
    result["snapshot"] = shot
    return result


def _probe(args: argparse.Namespace) -> int:
    from robocell.wire.errors import ConfigError

    password = os.environ.get(args.password_env) if args.user else None
    if args.user and password is None:
        raise ConfigError(f"--user {args.user} given, but the environment variable {args.password_env} is not set")
    resolution = None
    if args.resolution:
        w, _, h = args.resolution.partition("x")
        if not (w.isdigit() and h.isdigit()):
            raise ValueError(f"--resolution must be WIDTHxHEIGHT, got {args.resolution!r}")
        resolution = (int(w), int(h))
    result = asyncio.run(probe(args.url, username=args.user, password=password, auth=args.auth,
                               resolution=resolution, timeout_s=args.timeout, verify=not args.insecure))
    shot = result["snapshot"]
    if args.json:
        print(json.dumps(result))
    else:
        listed = result["resolutions"]
        print(f"camera       {result['url']}")
        print("resolutions  " + (", ".join(f"{w}x{h}" for w, h in listed) if listed is not None
                                 else f"unknown ({result['resolutions_error']})"))
        if shot["ok"]:
            print(f"snapshot     ok: {shot['width']}x{shot['height']} JPEG, {shot['bytes'] / 1000:.1f} kB "
                  f"in {shot['time_ms']:.0f} ms")
        else:
            print(f"snapshot     FAILED at {shot['resolution'][0]}x{shot['resolution'][1]}: {shot['error']}")
    return 0 if shot["ok"] else 1
