"""``robocell calibrate intrinsics|handeye|capture``: the camera's K and its mounting on the flange.

The calibration commands read image files, call :mod:`core_cy.calibrate`,
print JSON and, with ``--write-config``, put the result into a cell
configuration file (``robocell.cli.config.write_config``, which keeps the file's
comments): ``[camera]`` ``K`` and ``dist``, or the top-level ``T_flange_cam``.
``capture`` moves the running cell's robot through poses and saves an image
at each, for ``handeye``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robocell.core_cy.errors import CalibrationError

from .command import Commands
from .config import write_config

if TYPE_CHECKING:
    import numpy as np

    from robocell.wire.config import CellConfig

__all__ = ["register", "capture"]

log = logging.getLogger(__name__)


# --- calibrate ---------------------------------------------------------------------------------

def _read_images(paths: list[str]) -> list[np.ndarray]:
    import cv2

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
    from robocell.core_cy.calibrate import calibrate_intrinsics, parse_board
    from robocell.wire.config import load_config

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
    """K, dist and (if known) the image size they are for: from --K-from, else from the --config file."""
    import numpy as np

    from robocell.wire.config import load_config

    if args.k_from:
        data = _read_json(args.k_from, "intrinsics")
        if not isinstance(data, dict) or "K" not in data:
            raise CalibrationError(f"{args.k_from}: expected the JSON of `robocell calibrate intrinsics`")
        size = tuple(data["image_size"]) if "image_size" in data else None
        return np.asarray(data["K"], dtype=np.float64), data.get("dist"), size
    if args.config is None:
        raise CalibrationError("hand-eye calibration needs the camera's K: give --K-from INTRINSICS.json "
                               "or --config CELL.toml")
    camera = load_config(args.config).camera
    return np.asarray(camera.K, dtype=np.float64), camera.dist, tuple(camera.resolution)


def _handeye_command(args: argparse.Namespace) -> int:
    from robocell.core_cy.calibrate import calibrate_hand_eye, parse_board

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

    Not a job of the daemon, on purpose: a calibration is not a scan (its poses aim at a board,
    there is nothing to reconstruct and no result for the job store, and its pictures must
    come back to whoever calibrates), so it asks the robot and camera workers itself. The
    daemon owns the robot while it runs, so this refuses to move while a daemon of the cell is
    up. Writes ``view00.jpg``, ... and ``poses.json``: the poses the robot reports it reached,
    not the commanded ones, rewritten after every view so that an interrupted run leaves
    images and poses that match.

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
        For a pose that is not a rigid 4x4 transform, or while the cell's daemon runs.
    TransportError
        If a worker is not running, refuses a move (its reason in the message) or does not answer in time.
    """
    import numpy as np
    from pydantic import ValidationError

    from robocell.wire import keys
    from robocell.wire.messages import CaptureRequest, MoveReply, MoveRequest, field_errors, parse
    from robocell.wire.transport import Transport

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
        if await transport.alive(keys.alive(cell, "daemon"), timeout=2.0):
            raise CalibrationError(f"the daemon of cell {cell} is running, and it owns the robot while it does: "
                                   f"stop it (robocell cell), then capture the calibration images")
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
    from robocell.wire.config import load_config

    config = load_config(args.config)
    images = asyncio.run(capture(config, poses, args.out, settle_s=args.settle))
    print(json.dumps({"images": [str(p) for p in images], "poses": str(Path(args.out) / "poses.json")}))
    return 0


def register(commands: Commands) -> None:
    calibrate = commands.group("calibrate", help="calibrate the camera (intrinsics) and its mounting (hand-eye)")

    def board_and_images(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--board", required=True, metavar="COLSxROWS",
                            help="inner corners of the chessboard, e.g. 9x6")
        parser.add_argument("--square", required=True, type=float, metavar="METRES", help="side of one square")
        parser.add_argument("--write-config", metavar="FILE.toml",
                            help="also put the result into this configuration file")
        parser.add_argument("images", nargs="+", metavar="IMAGE")

    intrinsics = calibrate.add("intrinsics", _intrinsics_command,
                               help="K and distortion from images of a chessboard; prints JSON")
    board_and_images(intrinsics)
    intrinsics.add_argument("--k3", action="store_true",
                            help="also fit the third radial coefficient (wide-angle lenses)")

    handeye = calibrate.add("handeye", _handeye_command, help="the camera's pose on the flange (T_flange_cam); "
                                                              "prints JSON; K and dist from --K-from or --config")
    board_and_images(handeye)
    handeye.add_argument("--poses", required=True, metavar="POSES.json",
                         help="JSON list of 4x4 flange poses (flange-to-base, metres), one per image, in order")
    handeye.add_argument("--K-from", dest="k_from", metavar="INTRINSICS.json",
                         help="the output of `calibrate intrinsics` (default: K and dist of the --config file)")
    handeye.add_argument("--method", default="tsai", type=str.lower,
                         help="cv2.calibrateHandEye's method: tsai, park, horaud, andreff or daniilidis "
                              "(default %(default)s)")
    handeye.add_argument("--no-refine", action="store_true",
                         help="the method's closed-form answer, without the least-squares polish")

    grab = calibrate.add("capture", _capture_command,
                         help="move the robot through poses and save an image at each (cell running)")
    grab.add_argument("--poses", required=True, metavar="POSES.json",
                      help="JSON list of 4x4 flange poses (flange-to-base, metres) that see the board")
    grab.add_argument("--out", required=True, metavar="DIR", help="where the images and poses.json go")
    grab.add_argument("--settle", type=float, default=0.5, metavar="SECONDS",
                      help="wait after each move before the image (default %(default)s)")
