"""``robocell calibrate intrinsics|handeye`` and ``robocell camera probe``: setting up a real cell.

The calibration commands read image files, call :mod:`cell.calibrate`, print
JSON and, with ``--write-config``, put the result into a cell configuration
file: ``[camera]`` ``K`` and ``dist``, or the top-level ``T_flange_cam``. The
file is edited line by line (the standard library reads TOML but does not
write it), so comments and everything else stay as they were; the edited text
must load as a valid configuration before it replaces the file.

``camera probe`` asks an Axis camera which resolutions it offers and times one
snapshot, with the grabber the camera worker uses.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import re
import shutil
import sys
import tempfile
import time
import tomllib
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np
from pydantic import ValidationError

from wire import keys
from core_cy.calibrate import HAND_EYE_METHODS, calibrate_hand_eye, calibrate_intrinsics, parse_board
from wire.config import CellConfig, load_config
from core_cy.errors import CalibrationError
from wire.errors import CameraError, ConfigError
from wire.messages import CaptureRequest, MoveReply, MoveRequest, field_errors, parse

__all__ = ["add_commands", "update_toml", "write_config", "capture", "parse_resolutions", "probe", "PARAM_PATH"]

log = logging.getLogger(__name__)

#: The VAPIX parameter list of the resolutions a camera offers, relative to its base URL.
PARAM_PATH = "/axis-cgi/param.cgi"
_HEADER = re.compile(r"\s*\[\[?\s*([^\]]*?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"""\s*("(?:[^"\\]|\\.)*"|'[^']*'|[A-Za-z0-9_.-]+)\s*=""")


# --- editing a TOML file in place --------------------------------------------------------------

def _toml(value: Any) -> str:
    """Numbers and nested lists as TOML; 12 significant digits are far below any calibration's error."""
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    number = float(value)
    if not np.isfinite(number):
        raise ValueError(f"cannot write {number} to a configuration")
    return repr(float(f"{number:.12g}"))  # repr keeps the '.0' or exponent that makes it a TOML float


def _value_end(lines: list[str], row: int, col: int) -> tuple[int, str]:
    """The last line of a value starting at ``lines[row][col]``, and the comment that ends it."""
    depth, quote = 0, ""
    while row < len(lines):
        text, pos, comment = lines[row], col, ""
        while pos < len(text):
            if quote:  # inside a string: look for its end only
                if text[pos] == "\\" and quote[0] == '"':
                    pos += 2
                    continue
                if text.startswith(quote, pos):
                    pos, quote = pos + len(quote), ""
                    continue
                pos += 1
                continue
            ch = text[pos]
            if ch == "#":
                comment = text[pos:]
                break
            if ch in "\"'":
                quote = ch * 3 if text.startswith(ch * 3, pos) else ch
                pos += len(quote)
                continue
            depth += (ch in "[{") - (ch in "]}")
            pos += 1
        if depth <= 0 and len(quote) != 3:  # multi-line arrays and strings go on
            return row, comment
        row, col = row + 1, 0
    raise ValueError("a value runs to the end of the file")


def _statements(lines: list[str]) -> list[tuple[str, str | None, int, int, str]]:
    """``(table, key, first line, last line, trailing comment)`` of each key; key None for a header."""
    found, table, row = [], "", 0
    while row < len(lines):
        header = _HEADER.match(lines[row]) if lines[row].lstrip().startswith("[") else None
        key = None if header else _KEY.match(lines[row])
        if header:
            table = header[1].replace(" ", "")
            found.append((table, None, row, row, ""))
        elif key:
            last, comment = _value_end(lines, row, key.end())
            found.append((table, key[1].strip("\"'"), row, last, comment))
            row = last
        row += 1
    return found


def update_toml(text: str, table: str, values: dict[str, Any]) -> str:
    """``text`` with ``values`` set in ``table`` ("" for the top level); other lines unchanged.

    Examples
    --------
    >>> print(update_toml("# cell\\nx = 1\\n\\n[camera]\\nK = [[1, 0, 0],\\n  [0, 1, 0], [0, 0, 1]]  # old\\n",
    ...                   "camera", {"K": [[2, 0, 1], [0, 2, 1], [0, 0, 1]], "dist": [0.1, 0, 0, 0, 0]}), end="")
    # cell
    x = 1
    <BLANKLINE>
    [camera]
    K = [[2.0, 0.0, 1.0], [0.0, 2.0, 1.0], [0.0, 0.0, 1.0]]  # old
    dist = [0.1, 0.0, 0.0, 0.0, 0.0]
    """
    lines = text.splitlines()
    for key, value in values.items():
        statements = _statements(lines)
        line = f"{key} = {_toml(value)}"
        mine = [s for s in statements if s[0] == table]
        existing = [s for s in mine if s[1] == key]
        if existing:
            _, _, first, last, comment = existing[0]
            indent = lines[first][:len(lines[first]) - len(lines[first].lstrip())]
            lines[first:last + 1] = [indent + line + (f"  {comment}" if comment else "")]
        elif mine:
            lines.insert(max(s[3] for s in mine) + 1, line)  # after the table's last key (or its header)
        elif table:
            lines += ([""] if lines and lines[-1].strip() else []) + [f"[{table}]", line]
        else:  # the first top-level key: above the first table and the comments that introduce it
            headers = [s[2] for s in statements if s[1] is None]
            at = headers[0] if headers else len(lines)
            while at > 0 and lines[at - 1].lstrip().startswith("#"):
                at -= 1
            lines[at:at] = [line, ""] if headers else [line]
    return "\n".join(lines) + "\n"


def write_config(path: str | Path, table: str, values: dict[str, Any]) -> None:
    """Set ``values`` in ``table`` of the configuration file ``path`` (created if missing).

    Raises
    ------
    ConfigError
        If the file is not valid TOML, or would not be a valid configuration afterwards
        (the file is then left as it was).
    """
    path = Path(path)
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    try:
        tomllib.loads(text)
        new = update_toml(text, table, values)
        CellConfig.model_validate(tomllib.loads(new))
    except (tomllib.TOMLDecodeError, ValueError) as exc:
        detail = field_errors(exc) if isinstance(exc, ValidationError) else str(exc)
        where = f"[{table}] " if table else ""
        raise ConfigError(f"cannot update {path} ({detail}); set {where}{', '.join(values)} by hand") from exc
    # A new file beside the old, then one rename: a crash leaves either file whole, never half of one.
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as file:
            file.write(new)
        if path.exists():
            shutil.copymode(path, tmp)  # a file holding a camera password stays private
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


# --- calibrate ---------------------------------------------------------------------------------

def _read_images(paths: list[str]) -> list[np.ndarray]:
    images = []
    for path in paths:
        image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise CalibrationError(f"cannot read image {path} (missing, or not an image format OpenCV reads)")
        images.append(image)
    return images


def _read_json(path: str, what: str) -> Any:
    try:
        with open(path, encoding="utf-8") as file:
            return json.load(file)
    except (OSError, json.JSONDecodeError) as exc:
        raise CalibrationError(f"cannot read {what} {path}: {exc}") from exc


def _report_skipped(skipped: list[str], total: int) -> None:
    for name in skipped:
        print(f"robocell calibrate: board not found in {name}; skipped", file=sys.stderr)
    print(f"robocell calibrate: board found in {total - len(skipped)} of {total} images", file=sys.stderr)


def _intrinsics_command(args: argparse.Namespace) -> int:
    result = calibrate_intrinsics(_read_images(args.images), parse_board(args.board), args.square,
                                  k3=args.k3, names=args.images)
    _report_skipped(result["skipped"], len(args.images))
    out = {"K": result["K"].tolist(), "dist": result["dist"].tolist(), "rms": result["rms"],
           "image_size": list(result["image_size"])}
    print(json.dumps(out))
    if args.write_config:
        write_config(args.write_config, "camera", {"K": out["K"], "dist": out["dist"]})
        configured = load_config(args.write_config).camera.resolution
        if tuple(configured) != tuple(result["image_size"]):
            w, h = result["image_size"]
            print(f"robocell calibrate: warning: K is for {w}x{h} images but [camera] resolution in "
                  f"{args.write_config} is {configured[0]}x{configured[1]}", file=sys.stderr)
    return 0


def _camera_model(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray | None, tuple[int, int] | None]:
    """K, dist and (if known) the image size they are for: from --K-from, --config, or the global --config."""
    if args.k_from:
        data = _read_json(args.k_from, "intrinsics")
        if not isinstance(data, dict) or "K" not in data:
            raise CalibrationError(f"{args.k_from}: expected the JSON of `robocell calibrate intrinsics`")
        size = tuple(data["image_size"]) if "image_size" in data else None
        return np.asarray(data["K"], dtype=np.float64), data.get("dist"), size
    source = args.k_config or getattr(args, "config", None)
    if source is None:
        raise CalibrationError("hand-eye calibration needs the camera's K: give --K-from INTRINSICS.json "
                               "or --config CELL.toml")
    camera = load_config(source).camera
    return np.asarray(camera.K, dtype=np.float64), camera.dist, tuple(camera.resolution)


def _handeye_command(args: argparse.Namespace) -> int:
    K, dist, size = _camera_model(args)
    poses = _read_json(args.poses, "poses")
    if not isinstance(poses, list):
        raise CalibrationError(f"{args.poses}: expected a JSON list of 4x4 flange poses")
    images = _read_images(args.images)
    if size is not None and images and (images[0].shape[1], images[0].shape[0]) != tuple(size):
        raise CalibrationError(f"K is for {size[0]}x{size[1]} images, the images are "
                               f"{images[0].shape[1]}x{images[0].shape[0]}")
    result = calibrate_hand_eye(images, poses, parse_board(args.board), args.square, K, dist,
                                method=args.method, refine=not args.no_refine, names=args.images)
    _report_skipped(result["skipped"], len(args.images))
    print(f"robocell calibrate: {result['method'].lower()}{'' if args.no_refine else ' refined'}: corners "
          f"reproject through the robot's poses to {result['rms_px']:.2f} px RMS", file=sys.stderr)
    out = {"T_flange_cam": result["T_flange_cam"].tolist(), "residual_mm": result["residual_mm"],
           "residual_deg": result["residual_deg"]}
    print(json.dumps(out))
    if args.write_config:
        write_config(args.write_config, "", {"T_flange_cam": out["T_flange_cam"]})
    return 0


async def capture(client_config: CellConfig, poses: list, out_dir: str | Path, *,
                  settle_s: float = 0.5) -> list[Path]:
    """Move the robot through ``poses`` and save a camera image at each, for ``calibrate handeye``.

    Asks the robot and camera workers directly (no job, no daemon), so run it while
    the cell is not scanning. Writes ``view00.jpg``, ... and ``poses.json``: the
    poses the robot reports it reached, not the commanded ones, rewritten after
    every view so that an interrupted run leaves images and poses that match.

    Parameters
    ----------
    client_config : CellConfig
        The cell to talk to (router, cell id, time-outs).
    poses : list of (4, 4) array_like
        Flange poses (flange-to-base, metres) around a board fixed in the cell.
    out_dir : path
        Created if missing.
    settle_s : float
        Wait after each move, so that the arm has stopped swaying when the image is taken.

    Returns
    -------
    list of Path
        The images, in order.

    Raises
    ------
    CalibrationError
        For a pose that is not a rigid 4x4 transform.
    TransportError
        If a worker is not running, refuses a move (its reason in the message) or does not answer in time.
    """
    from wire.transport import Transport  # Zenoh only for the one command that needs it

    moves = []
    for i, pose in enumerate(poses):
        try:
            moves.append(MoveRequest(T_base_flange=np.asarray(pose, dtype=np.float64).tolist()))
        except ValidationError as exc:
            raise CalibrationError(f"pose {i}: {field_errors(exc)}") from None
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cell, timeouts = client_config.cell_id, client_config.timeouts
    images: list[Path] = []
    reached: list[list[list[float]]] = []
    async with await Transport.open(client_config.zenoh.router, settings=client_config.zenoh.client_settings(),
                                    connect_timeout_s=10.0) as transport:
        for i, move in enumerate(moves):
            reply = await transport.query(keys.robot_move(cell), move.model_dump_json(), timeout=timeouts.move_s)
            moved = parse(MoveReply, reply.payload)
            await asyncio.sleep(settle_s)
            shot = await transport.query(keys.camera_capture(cell), CaptureRequest(view=i).model_dump_json(),
                                         timeout=timeouts.capture_s)
            images.append(out / f"view{i:02d}.jpg")
            images[-1].write_bytes(shot.payload)
            reached.append(moved.T_base_flange)
            (out / "poses.json").write_text(json.dumps(reached), encoding="utf-8")
            log.info("view %d of %d: %s", i + 1, len(moves), images[-1])
    return images


def _capture_command(args: argparse.Namespace) -> int:
    poses = _read_json(args.poses, "poses")
    if not isinstance(poses, list):
        raise CalibrationError(f"{args.poses}: expected a JSON list of 4x4 flange poses")
    config = load_config(getattr(args, "config", None))
    images = asyncio.run(capture(config, poses, args.out, settle_s=args.settle))
    print(json.dumps({"images": [str(p) for p in images], "poses": str(Path(args.out) / "poses.json")}))
    return 0


# --- camera probe ------------------------------------------------------------------------------

def parse_resolutions(text: str) -> list[tuple[int, int]]:
    """The resolutions in an Axis ``param.cgi`` answer, in its order.

    Examples
    --------
    >>> parse_resolutions("root.Properties.Image.Resolution=1920x1080,1280x720\\n")
    [(1920, 1080), (1280, 720)]
    """
    for line in text.splitlines():
        key, sep, value = line.partition("=")
        if sep and key.strip().endswith("Properties.Image.Resolution"):
            return [(int(w), int(h)) for w, h in re.findall(r"(\d+)x(\d+)", value)]
    raise ValueError(" ".join(text.split())[:200] or "empty answer")


async def probe(url: str, *, username: str | None = None, password: str | None = None, auth: str = "digest",
                resolution: tuple[int, int] | None = None, timeout_s: float = 5.0,
                verify: bool = True) -> dict[str, Any]:
    """What the camera at ``url`` offers, and whether (and how fast) it gives a snapshot.

    Returns ``{"url", "resolutions" (list of [w, h], or None), "resolutions_error",
    "snapshot": {"ok", "resolution", "bytes", "width", "height", "time_ms", "error"}}``.
    The snapshot uses ``resolution``, else 640x480 if offered, else the first offered.
    """
    from workers.camera.axis import AxisCamera  # as cell/cli.py does: cell imports workers only when it runs one

    camera_args = {"username": username, "password": password, "auth": auth, "timeout_s": timeout_s, "verify": verify}
    source = AxisCamera(url, **camera_args).source
    parsed = httpx.URL(url)
    if username is None and parsed.username:
        username, password = parsed.username, parsed.password
    scheme = httpx.DigestAuth if auth == "digest" else httpx.BasicAuth
    result: dict[str, Any] = {"url": source, "resolutions": None, "resolutions_error": None}
    async with httpx.AsyncClient(auth=scheme(username, password or "") if username else None, verify=verify,
                                 timeout=httpx.Timeout(timeout_s), trust_env=False) as client:
        try:
            reply = await client.get(source + PARAM_PATH,
                                     params={"action": "list", "group": "Properties.Image.Resolution"})
            if reply.status_code != 200:
                result["resolutions_error"] = f"HTTP {reply.status_code} {reply.reason_phrase}"
            else:
                result["resolutions"] = [list(r) for r in parse_resolutions(reply.text)]
        except httpx.HTTPError as exc:
            result["resolutions_error"] = f"{type(exc).__name__}: {exc}"
        except ValueError as exc:
            result["resolutions_error"] = f"unexpected answer: {exc}"
    offered = [tuple(r) for r in result["resolutions"] or []]
    size = resolution or ((640, 480) if (640, 480) in offered or not offered else offered[0])
    shot: dict[str, Any] = {"ok": False, "resolution": list(size), "bytes": None, "width": None, "height": None,
                            "time_ms": None, "error": None}
    try:
        async with AxisCamera(url, resolution=size, retries=0, **camera_args) as camera:
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


def _probe_command(args: argparse.Namespace) -> int:
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


# --- the parsers -------------------------------------------------------------------------------

def add_commands(commands: argparse._SubParsersAction) -> None:
    """Add ``calibrate`` and ``camera`` to the ``robocell`` sub-commands; each leaf sets ``run``."""
    calibrate = commands.add_parser("calibrate", help="calibrate the camera (intrinsics) and its mounting (hand-eye)")
    what = calibrate.add_subparsers(dest="calibrate_what", required=True, metavar="WHAT")

    def common(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--board", required=True, metavar="COLSxROWS",
                            help="inner corners of the chessboard, e.g. 9x6")
        parser.add_argument("--square", required=True, type=float, metavar="METRES", help="side of one square")
        parser.add_argument("--write-config", metavar="FILE.toml",
                            help="also put the result into this configuration file")
        parser.add_argument("images", nargs="+", metavar="IMAGE")

    intrinsics = what.add_parser("intrinsics", help="K and distortion from images of a chessboard; prints JSON")
    common(intrinsics)
    intrinsics.add_argument("--k3", action="store_true",
                            help="also fit the third radial coefficient (wide-angle lenses)")
    intrinsics.set_defaults(run=_intrinsics_command)

    handeye = what.add_parser("handeye", help="the camera's pose on the flange (T_flange_cam); prints JSON")
    common(handeye)
    handeye.add_argument("--poses", required=True, metavar="POSES.json",
                         help="JSON list of 4x4 flange poses (flange-to-base, metres), one per image, in order")
    source = handeye.add_mutually_exclusive_group()
    source.add_argument("--K-from", dest="k_from", metavar="INTRINSICS.json",
                        help="the output of `calibrate intrinsics`")
    # Not dest="config": a sub-command's default would overwrite robocell's own --config.
    source.add_argument("--config", dest="k_config", metavar="CELL.toml",
                        help="take K and dist from this configuration (default: robocell's --config)")
    handeye.add_argument("--method", default="tsai", type=str.lower, choices=[m.lower() for m in HAND_EYE_METHODS],
                         help="cv2.calibrateHandEye method (default %(default)s)")
    handeye.add_argument("--no-refine", action="store_true",
                         help="the method's closed-form answer, without the least-squares polish")
    handeye.set_defaults(run=_handeye_command)

    grab = what.add_parser("capture", help="move the robot through poses and save an image at each (cell running)")
    grab.add_argument("--poses", required=True, metavar="POSES.json",
                      help="JSON list of 4x4 flange poses (flange-to-base, metres) that see the board")
    grab.add_argument("--out", required=True, metavar="DIR", help="where the images and poses.json go")
    grab.add_argument("--settle", type=float, default=0.5, metavar="SECONDS",
                      help="wait after each move before the image (default %(default)s)")
    grab.set_defaults(run=_capture_command)

    camera = commands.add_parser("camera", help="check a network camera")
    camera_what = camera.add_subparsers(dest="camera_what", required=True, metavar="WHAT")
    probe_parser = camera_what.add_parser("probe", help="list an Axis camera's resolutions and time one snapshot")
    probe_parser.add_argument("url", metavar="URL")
    probe_parser.add_argument("--user", help="user name (the password comes from the environment)")
    probe_parser.add_argument("--password-env", default="ROBOCELL_CAMERA_PASSWORD", metavar="VAR",
                              help="environment variable holding the password (default %(default)s)")
    probe_parser.add_argument("--auth", choices=["digest", "basic"], default="digest")
    probe_parser.add_argument("--resolution", metavar="WxH", help="snapshot size (default 640x480 if offered)")
    probe_parser.add_argument("--timeout", type=float, default=5.0, help="seconds per request (default %(default)s)")
    probe_parser.add_argument("--insecure", action="store_true", help="do not check the HTTPS certificate")
    probe_parser.add_argument("--json", action="store_true", help="print one JSON object")
    probe_parser.set_defaults(run=_probe_command)
