"""Calibration (core_cy.calibrate, robocell calibrate) on rendered chessboards with a known camera and mounting.

The renderer draws a printed board (white sheet, dark squares) as polygons
whose edges are densely sampled and projected with distortion, four times
over-sampled and anti-aliased, then averaged down and given sensor noise: the
detector sees curved edges and soft transitions, as from a real lens.
"""
from __future__ import annotations

import asyncio
import json
import stat
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocell.cli.calibrate import capture
from robocell.cli.config import write_config
from robocell.cli.main import build_parser
from robocell.core_cy.calibrate import (HAND_EYE_METHODS, board_points, calibrate_hand_eye, calibrate_intrinsics, find_corners,
                            parse_board)
from robocell.wire.config import SimConfig, load_config
from robocell.core_cy.errors import CalibrationError
from robocell.wire.errors import ConfigError
from robocell.workers.sim.scans import default_K, look_at
from robocell.workers.sim.axis import SimCameraServer

SIZE = (640, 480)
K_TRUE = np.array([[820.0, 0.0, 322.5], [0.0, 818.0, 236.0], [0.0, 0.0, 1.0]])
DIST_TRUE = np.array([-0.21, 0.09, 0.0008, -0.0005, 0.0])
BOARD, SQUARE = (9, 6), 0.02
OVERSAMPLE = 4
#: The board lies on the table, face up: its z axis (into the board) points down.
T_BASE_BOARD = np.array([[1.0, 0, 0, 0.5], [0, -1.0, 0, 0.05], [0, 0, -1.0, 0.0], [0, 0, 0, 1.0]])
#: The camera on the flange: about DEFAULT_HAND_EYE, but no angle or offset a round number.
T_FLANGE_CAM = np.eye(4)
T_FLANGE_CAM[:3, :3] = Rotation.from_euler("xyz", [3.0, -2.0, 91.0], degrees=True).as_matrix()
T_FLANGE_CAM[:3, 3] = [0.032, -0.018, 0.105]
PASSWORD = "pr0be-Pa55"


def _outline(x0: float, y0: float, x1: float, y1: float, n: int = 16) -> np.ndarray:
    """A rectangle in the board plane as 4n points, so that its projected edges can curve."""
    t = np.linspace(0.0, 1.0, n, endpoint=False)[:, None]
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
    return np.concatenate([a + (b - a) * t for a, b in zip(corners[:-1], corners[1:])])


def _sheet(board=BOARD, square=SQUARE) -> tuple[float, float, float, float]:
    """The white paper: one square of margin around the squares (the detector needs the quiet zone)."""
    cols, rows = board
    return -2 * square, -2 * square, (cols + 1) * square, (rows + 1) * square


def render_board(T_cam_board: np.ndarray, rng: np.random.Generator, *, board=BOARD, square=SQUARE) -> np.ndarray:
    """(H, W) uint8 image of the board at ``T_cam_board`` (board-to-camera) through K_TRUE, DIST_TRUE."""
    w, h = SIZE
    K = K_TRUE.copy()
    K[:2, :2] *= OVERSAMPLE
    K[:2, 2] = OVERSAMPLE * (K[:2, 2] + 0.5) - 0.5  # pixel edges scale, centres do not
    rvec, tvec = cv2.Rodrigues(T_cam_board[:3, :3])[0], T_cam_board[:3, 3]

    def project(xy: np.ndarray) -> np.ndarray:
        uv = cv2.projectPoints(np.column_stack([xy, np.zeros(len(xy))]), rvec, tvec, K, DIST_TRUE)[0]
        return np.round(uv.reshape(-1, 2) * 8).astype(np.int32)  # 3 fractional bits for fillPoly

    image = np.full((h * OVERSAMPLE, w * OVERSAMPLE), 90, np.uint8)
    cv2.fillPoly(image, [project(_outline(*_sheet(board, square)))], 230, cv2.LINE_AA, shift=3)
    cols, rows = board
    dark = [project(_outline((a - 1) * square, (b - 1) * square, a * square, b * square))
            for a in range(cols + 1) for b in range(rows + 1) if (a + b) % 2 == 0]
    cv2.fillPoly(image, dark, 30, cv2.LINE_AA, shift=3)
    small = cv2.resize(image, SIZE, interpolation=cv2.INTER_AREA).astype(np.float64)
    return np.clip(np.round(small + rng.normal(0.0, 2.0, small.shape)), 0, 255).astype(np.uint8)


def _in_view(T_cam_board: np.ndarray, margin: float = 8.0) -> bool:
    x0, y0, x1, y1 = _sheet()
    corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])
    uv = cv2.projectPoints(corners, cv2.Rodrigues(T_cam_board[:3, :3])[0], T_cam_board[:3, 3], K_TRUE,
                           DIST_TRUE)[0].reshape(-1, 2)
    return bool(np.all(uv >= margin) and np.all(uv <= np.array(SIZE) - margin))


def _roll(angle: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", angle).as_matrix()
    return T


def camera_poses(n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """``n`` camera-to-base poses 0.33-0.45 m from the board, tilted 10-40 degrees, whole sheet in view."""
    centre = (T_BASE_BOARD @ [(BOARD[0] - 1) * SQUARE / 2, (BOARD[1] - 1) * SQUARE / 2, 0, 1])[:3]
    poses = []
    while len(poses) < n:
        distance, tilt, azimuth = rng.uniform(0.33, 0.45), np.radians(rng.uniform(10, 40)), rng.uniform(0, 2 * np.pi)
        direction = [np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)]
        up = (np.cos(azimuth + 1.0), np.sin(azimuth + 1.0), 0.0)
        T = look_at(centre + distance * np.array(direction), centre + [*rng.normal(0, 0.01, 2), 0], up)
        T = T @ _roll(rng.uniform(-0.3, 0.3))
        if _in_view(np.linalg.inv(T) @ T_BASE_BOARD):
            poses.append(T)
    return poses


def angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(Rotation.from_matrix(R).magnitude()))


@pytest.fixture(scope="module")
def scene():
    """12 views of the board, their camera poses and the flange poses that put the camera there."""
    rng = np.random.default_rng(20240611)
    cameras = camera_poses(12, rng)
    images = [render_board(np.linalg.inv(T) @ T_BASE_BOARD, rng) for T in cameras]
    flanges = [T @ np.linalg.inv(T_FLANGE_CAM) for T in cameras]
    return images, cameras, flanges


@pytest.fixture(scope="module")
def files(scene, tmp_path_factory):
    """The scene as a calibration would leave it on disk: PNGs, one without a board, and poses.json."""
    out = tmp_path_factory.mktemp("calib")
    images, _, flanges = scene
    paths = []
    for i, image in enumerate(images):
        paths.append(str(out / f"view{i:02d}.png"))
        cv2.imwrite(paths[-1], image)
    blank = str(out / "blank.png")
    cv2.imwrite(blank, np.full(SIZE[::-1], 128, np.uint8))
    (out / "poses.json").write_text(json.dumps([T.tolist() for T in flanges] + [flanges[0].tolist()]))
    return {"dir": out, "images": paths + [blank], "poses": str(out / "poses.json"), "blank": blank}


# --- detection -----------------------------------------------------------------------------------

def test_parse_board():
    assert parse_board("9x6") == (9, 6) and parse_board(" 7X4 ") == (7, 4)
    for bad in ("9by6", "9x", "1x6", "9x6x2"):
        with pytest.raises(ValueError):
            parse_board(bad)


@pytest.mark.parametrize("roll_deg", [0, 90, 180, 270])
def test_corner_order_is_the_board_frame_however_the_camera_turns(roll_deg):
    """Corner k lands on board_points()[k] in every image: the order follows the board, not the camera."""
    rng = np.random.default_rng(roll_deg)
    camera = look_at([0.58, 0.0, 0.5], [0.58, 0.0, 0.0], up=(0.0, 1.0, 0.0)) @ _roll(np.radians(roll_deg))
    T_cam_board = np.linalg.inv(camera) @ T_BASE_BOARD
    assert _in_view(T_cam_board)
    truth = cv2.projectPoints(board_points(BOARD, SQUARE).astype(np.float64), cv2.Rodrigues(T_cam_board[:3, :3])[0],
                              T_cam_board[:3, 3], K_TRUE, DIST_TRUE)[0].reshape(-1, 2)
    corners = find_corners(render_board(T_cam_board, rng), BOARD)
    assert corners is not None and corners.shape == (54, 2)
    error = np.linalg.norm(corners - truth, axis=1)  # pixels; a wrong order would be off by squares
    assert error.max() < 0.4 and np.sqrt(np.mean(error ** 2)) < 0.15


def test_no_board_is_none():
    assert find_corners(np.full((480, 640, 3), 128, np.uint8), BOARD) is None
    with pytest.raises(ValueError, match="uint8"):
        find_corners(np.zeros((480, 640)), BOARD)


# --- intrinsics ------------------------------------------------------------------------------------

def test_intrinsics_recovered_and_blank_image_skipped(scene):
    images = scene[0] + [np.full((480, 640), 128, np.uint8)]
    names = [f"v{i}" for i in range(len(images))]
    result = calibrate_intrinsics(images, BOARD, SQUARE, names=names)
    K = result["K"]
    focal_error = np.abs(np.diag(K)[:2] / np.diag(K_TRUE)[:2] - 1)
    assert focal_error.max() < 0.01, focal_error
    assert np.abs(K[:2, 2] - K_TRUE[:2, 2]).max() < 3.0  # principal point, pixels
    assert abs(result["dist"][0] - DIST_TRUE[0]) < 0.03 and result["dist"][4] == 0.0  # k3 fixed by default
    assert result["rms"] < 0.2 and result["image_size"] == SIZE
    assert result["skipped"] == ["v12"]


def test_too_few_images_say_how_many(scene):
    blank = np.full((480, 640), 128, np.uint8)
    with pytest.raises(CalibrationError, match=r"at least 3 images showing the 9x6 board, found it in 2 of 4"):
        calibrate_intrinsics(scene[0][:2] + [blank, blank], BOARD, SQUARE)
    with pytest.raises(CalibrationError, match="found it in 0 of 3"):  # wrong board: squares, not inner corners
        calibrate_intrinsics(scene[0][:3], (10, 7), SQUARE)


def test_images_of_different_sizes(scene):
    with pytest.raises(CalibrationError, match="image 1 is 320x240"):
        calibrate_intrinsics([scene[0][0], cv2.resize(scene[0][1], (320, 240))], BOARD, SQUARE)


# --- hand-eye --------------------------------------------------------------------------------------

@pytest.mark.parametrize("refine", [True, False])
@pytest.mark.parametrize("method", list(HAND_EYE_METHODS))
def test_hand_eye_recovered(scene, method, refine):
    images, _, flanges = scene
    result = calibrate_hand_eye(images, flanges, BOARD, SQUARE, K_TRUE, DIST_TRUE, method=method.lower(),
                                refine=refine)
    error = np.linalg.inv(T_FLANGE_CAM) @ result["T_flange_cam"]
    mm, deg = 1000 * np.linalg.norm(error[:3, 3]), angle_deg(error[:3, :3])
    assert mm < 2.0 and deg < 0.2
    if refine:  # measured: 0.03 mm and 0.005 degrees; the closed forms alone 0.1-0.8 mm
        assert mm < 0.3 and deg < 0.03 and result["rms_px"] < 0.15
    assert result["residual_mm"] < 1.0 and result["residual_deg"] < 0.2
    assert result["method"] == method and result["skipped"] == []


def test_tsai_failure_is_an_error():
    """OpenCV's Tsai pairs consecutive images only and skips pairs turned by nearly 180 degrees; when too few are
    left it answers the identity (and says so on stderr only). Park on the same images is fine."""
    rng = np.random.default_rng(6)
    cameras = camera_poses(6, rng)
    flanges = [T @ np.linalg.inv(T_FLANGE_CAM) for T in cameras]
    images = [render_board(np.linalg.inv(T) @ T_BASE_BOARD, rng) for T in cameras]
    with pytest.raises(CalibrationError, match=r"cv2.calibrateHandEye \(TSAI\) failed: .* choose another --method"):
        calibrate_hand_eye(images, flanges, BOARD, SQUARE, K_TRUE, DIST_TRUE)
    result = calibrate_hand_eye(images, flanges, BOARD, SQUARE, K_TRUE, DIST_TRUE, method="park")
    error = np.linalg.inv(T_FLANGE_CAM) @ result["T_flange_cam"]
    assert 1000 * np.linalg.norm(error[:3, 3]) < 0.5 and angle_deg(error[:3, :3]) < 0.05


def test_hand_eye_skips_an_image_and_its_pose(scene):
    images, _, flanges = scene
    blank = np.full((480, 640), 128, np.uint8)
    result = calibrate_hand_eye([blank] + images, [np.eye(4)] + flanges, BOARD, SQUARE, K_TRUE, DIST_TRUE)
    assert result["skipped"] == [0]
    error = np.linalg.inv(T_FLANGE_CAM) @ result["T_flange_cam"]
    assert 1000 * np.linalg.norm(error[:3, 3]) < 2.0


def test_hand_eye_errors(scene):
    images, _, flanges = scene
    args = (BOARD, SQUARE, K_TRUE, DIST_TRUE)
    with pytest.raises(CalibrationError, match="11 flange poses for 12 images"):
        calibrate_hand_eye(images, flanges[:-1], *args)
    scaled = [T.copy() for T in flanges]
    scaled[4][:3, :3] *= 1.01
    with pytest.raises(CalibrationError, match="flange pose 4 is not a rigid transform: its rotation is not orthonormal"):
        calibrate_hand_eye(images, scaled, *args)
    millimetres = [T * [[1], [1], [1], [1]] for T in flanges]
    for T in millimetres:
        T[:3, 3] *= 1000
    with pytest.raises(CalibrationError, match="flange pose 0 lies .* poses must be in metres"):
        calibrate_hand_eye(images, millimetres, *args)
    with pytest.raises(CalibrationError, match="hand-eye calibration needs at least 3 images.* found it in 2 of 2"):
        calibrate_hand_eye(images[:2], flanges[:2], *args)
    with pytest.raises(CalibrationError, match="cols \\+ rows odd"):
        calibrate_hand_eye(images, flanges, (8, 6), SQUARE, K_TRUE)
    with pytest.raises(ValueError, match="unknown hand-eye method 'best'"):
        calibrate_hand_eye(images, flanges, *args, method="best")


def test_hand_eye_needs_two_rotation_axes():
    """Turning the flange about its own z axis only leaves the camera's offset along that axis unknown."""
    rng = np.random.default_rng(7)
    centre = (T_BASE_BOARD @ [(BOARD[0] - 1) * SQUARE / 2, (BOARD[1] - 1) * SQUARE / 2, 0, 1])[:3]
    above = look_at(centre + [0, 0, 0.65], centre, up=(1.0, 0.0, 0.0)) @ np.linalg.inv(T_FLANGE_CAM)
    flanges = [above @ _roll(a) for a in np.radians([-30, -10, 15, 30])]
    boards = [np.linalg.inv(T @ T_FLANGE_CAM) @ T_BASE_BOARD for T in flanges]
    assert all(_in_view(T) for T in boards)
    images = [render_board(T, rng) for T in boards]
    with pytest.raises(CalibrationError, match="rotate about one axis only"):
        calibrate_hand_eye(images, flanges, BOARD, SQUARE, K_TRUE, DIST_TRUE)


# --- the configuration file --------------------------------------------------------------------------

CONFIG = """\
# robocell cell configuration
cell_id = "bench"   # the lab bench

[camera]
url = "http://192.168.0.90"  # Axis M1065
K = [[600, 0, 319.5],
     [0, 600, 239.5],   # a guess
     [0, 0, 1]]

[robot.workspace]
max_tilt_deg = 60.0
"""


def test_write_config_round_trip(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text(CONFIG)
    path.chmod(0o600)
    K = [[812.345678901234, 0.0, 321.25], [0.0, 811.5, 238.75], [0.0, 0.0, 1.0]]
    dist = [-0.2, 0.08, 1e-4, -2.5e-05, 0.0]
    write_config(path, "camera", {"K": K, "dist": dist})
    write_config(path, "", {"T_flange_cam": T_FLANGE_CAM.tolist()})
    config = load_config(path)
    assert np.allclose(config.camera.K, K, rtol=1e-11) and np.allclose(config.camera.dist, dist, rtol=1e-11)
    assert np.allclose(config.T_flange_cam, T_FLANGE_CAM, atol=1e-11)
    assert config.cell_id == "bench" and config.camera.url == "http://192.168.0.90"
    assert config.robot.workspace.max_tilt_deg == 60.0
    text = path.read_text()
    for kept in ("# robocell cell configuration", 'url = "http://192.168.0.90"  # Axis M1065', "[robot.workspace]"):
        assert kept in text
    assert "# a guess" not in text and text.count("K =") == 1
    assert text.index("T_flange_cam") < text.index("[camera]")
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    write_config(path, "camera", {"dist": [0.0] * 5})  # again: replaced, not repeated
    assert path.read_text().count("dist =") == 1 and load_config(path).camera.dist == [0.0] * 5


def test_write_config_creates_a_file_and_puts_top_level_keys_above_tables(tmp_path):
    path = tmp_path / "new.toml"
    write_config(path, "camera", {"K": K_TRUE.tolist()})
    write_config(path, "", {"T_flange_cam": T_FLANGE_CAM.tolist()})
    assert path.read_text().startswith("T_flange_cam = ")
    assert np.allclose(load_config(path).camera.K, K_TRUE)


def test_write_config_refuses_to_break_a_file(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text(CONFIG)
    with pytest.raises(ConfigError, match="camera.dist"):
        write_config(path, "camera", {"dist": [[1.0]]})
    path.write_text("[camera\n")
    with pytest.raises(ConfigError, match="cannot update"):
        write_config(path, "camera", {"K": K_TRUE.tolist()})
    assert path.read_text() == "[camera\n"


# --- the commands -------------------------------------------------------------------------------------

def run(capsys, *argv: str) -> tuple[int, str, str]:
    """A command as ``robocell`` parses it; its errors are raised, not printed."""
    args = build_parser().parse_args(argv)
    status = args.run(args)
    out, err = capsys.readouterr()
    return status, out, err


def test_calibrate_commands(files, tmp_path, capsys):
    config = tmp_path / "cell.toml"
    config.write_text(CONFIG)
    board = ("--board", "9x6", "--square", str(SQUARE), "--write-config", str(config))
    status, out, err = run(capsys, "calibrate", "intrinsics", *board, *files["images"])
    assert status == 0 and f"board not found in {files['blank']}; skipped" in err
    intrinsics = json.loads(out)
    assert set(intrinsics) == {"K", "dist", "rms", "image_size"} and intrinsics["image_size"] == list(SIZE)
    assert abs(intrinsics["K"][0][0] / K_TRUE[0, 0] - 1) < 0.01
    assert np.allclose(load_config(config).camera.K, intrinsics["K"], rtol=1e-11)
    (tmp_path / "intrinsics.json").write_text(out)

    status, out, err = run(capsys, "calibrate", "handeye", *board, "--poses", files["poses"], "--method", "PARK",
                           "--K-from", str(tmp_path / "intrinsics.json"), *files["images"])
    assert status == 0 and "board found in 12 of 13 images" in err
    hand_eye = json.loads(out)
    assert set(hand_eye) == {"T_flange_cam", "residual_mm", "residual_deg"}
    error = np.linalg.inv(T_FLANGE_CAM) @ np.array(hand_eye["T_flange_cam"])
    assert 1000 * np.linalg.norm(error[:3, 3]) < 2.0 and angle_deg(error[:3, :3]) < 0.2
    assert np.allclose(load_config(config).T_flange_cam, hand_eye["T_flange_cam"])

    # K from the configuration just written, named by robocell's --config, before the command or after it
    handeye = ["calibrate", "handeye", "--board", "9x6", "--square", str(SQUARE), "--poses", files["poses"],
               *files["images"]]
    for argv in (["--config", str(config), *handeye], [*handeye, "--config", str(config)]):
        status, out, _ = run(capsys, *argv)
        error = np.linalg.inv(T_FLANGE_CAM) @ np.array(json.loads(out)["T_flange_cam"])
        assert status == 0 and 1000 * np.linalg.norm(error[:3, 3]) < 2.0 and angle_deg(error[:3, :3]) < 0.2

    with pytest.raises(CalibrationError, match="needs the camera's K"):
        run(capsys, "calibrate", "handeye", "--board", "9x6", "--square", "0.02", "--poses", files["poses"],
            *files["images"])
    with pytest.raises(CalibrationError, match="cannot read image nowhere.png"):
        run(capsys, "calibrate", "intrinsics", "--board", "9x6", "--square", "0.02", "nowhere.png")


def test_calibrate_intrinsics_in_a_subprocess(files):
    """The command as a program, in a fresh interpreter."""
    process = subprocess.run([sys.executable, "-m", "robocell", "calibrate", "intrinsics", "--board", "9x6",
                              "--square", str(SQUARE), *files["images"][:5]],
                             capture_output=True, text=True, timeout=60, cwd=Path(__file__).parents[1])
    assert process.returncode == 0, process.stderr
    assert abs(json.loads(process.stdout)["K"][1][1] / K_TRUE[1, 1] - 1) < 0.02  # five views only


# --- camera probe ----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def camera():
    size = (320, 240)
    pose = look_at([0.85, 0.25, 0.35], [0.6, 0.0, 0.02])
    from robocell.workers.sim.scene import scene_from_config

    with SimCameraServer(scene_from_config(SimConfig()), K=default_K(size), image_size=size,
                         pose_provider=lambda: pose, username="root", password=PASSWORD, auth="digest") as server:
        yield server


def test_camera_probe(camera, capsys, monkeypatch):
    monkeypatch.setenv("PROBE_PW", PASSWORD)
    # The simulated camera renders its scene for each snapshot: on a busy machine (the suite runs its
    # files side by side) that can take longer than a real camera's answer, which --timeout allows for.
    status, out, _ = run(capsys, "camera", "probe", camera.url, "--user", "root", "--password-env", "PROBE_PW",
                         "--timeout", "60")
    assert status == 0, out
    assert f"camera       {camera.url}" in out
    assert "resolutions  1280x960, 1024x768, 800x600, 640x480, 480x360, 320x240, 240x180, 160x120" in out
    assert "snapshot     ok: 640x480 JPEG" in out

    status, out, _ = run(capsys, "camera", "probe", camera.url, "--user", "root", "--password-env", "PROBE_PW",
                         "--resolution", "320x240", "--json", "--timeout", "60")
    result = json.loads(out)
    assert status == 0 and result["snapshot"]["ok"] and (result["snapshot"]["width"], result["snapshot"]["height"]) \
        == (320, 240) and result["snapshot"]["time_ms"] > 0 and [320, 240] in result["resolutions"]


def test_camera_probe_failures(camera, capsys, monkeypatch):
    monkeypatch.setenv("PROBE_PW", "wrong")
    status, out, _ = run(capsys, "camera", "probe", camera.url, "--user", "root", "--password-env", "PROBE_PW")
    assert status == 1
    assert f"resolutions  unknown (camera at {camera.url} refused the credentials of user 'root' (HTTP 401))" in out
    assert "snapshot     FAILED at 640x480: " in out and "refused the credentials" in out
    assert "wrong" not in out
    monkeypatch.delenv("PROBE_PW")
    with pytest.raises(ConfigError, match="PROBE_PW is not set"):
        run(capsys, "camera", "probe", camera.url, "--user", "root", "--password-env", "PROBE_PW")
    status, out, _ = run(capsys, "camera", "probe", camera.url + "/nothing", "--json", "--timeout", "2")
    assert status == 1 and json.loads(out)["resolutions_error"].endswith("requires credentials (HTTP 401) and none "
                                                                          "are configured")


# --- capture through the cell's workers ------------------------------------------------------------------

def test_capture_then_hand_eye(tmp_path):
    """`calibrate capture` over real Zenoh on loopback, with stand-in robot and camera workers that render the
    board from where the robot went; its files then give the hand-eye transform."""
    from robocell.wire import keys
    from robocell.wire.config import CellConfig
    from robocell.wire.messages import CaptureInfo, MoveReply, MoveRequest, parse
    from robocell.wire.transport import Response, Transport

    from tests.cell_fixtures import free_port

    config = CellConfig.model_validate({"cell_id": "calib", "zenoh": {"router": f"tcp/127.0.0.1:{free_port()}"}})
    rng = np.random.default_rng(5)
    flanges = [T @ np.linalg.inv(T_FLANGE_CAM) for T in camera_poses(6, rng)]
    at: list[np.ndarray] = []

    async def on_move(request):
        at.append(np.asarray(parse(MoveRequest, request.payload).T_base_flange))
        return Response(MoveReply(T_base_flange=at[-1].tolist(), duration_s=0.0).model_dump_json())

    async def on_capture(request):
        image = render_board(np.linalg.inv(at[-1] @ T_FLANGE_CAM) @ T_BASE_BOARD, rng)
        jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes()
        info = CaptureInfo(width=SIZE[0], height=SIZE[1], source="test", time=0.0, duration_s=0.0)
        return Response(jpeg, encoding="image/jpeg", attachment=info.model_dump_json())

    async def go(with_a_daemon: bool = False):
        async with await Transport.open(config.zenoh.router, mode="router") as router:
            router.serve(keys.robot_move("calib"), on_move)
            router.serve(keys.camera_capture("calib"), on_capture)
            if with_a_daemon:  # its token, as a running daemon declares it
                router.declare_token(keys.alive("calib", "daemon"))
            return await capture(config, [T.tolist() for T in flanges], tmp_path / "cap", settle_s=0)

    with pytest.raises(CalibrationError, match="the daemon of cell calib is running, and it owns the robot"):
        asyncio.run(go(with_a_daemon=True))
    assert at == []  # not moved
    images = asyncio.run(go())
    assert [p.name for p in images] == [f"view{i:02d}.jpg" for i in range(6)]
    poses = json.loads((tmp_path / "cap" / "poses.json").read_text())
    assert np.allclose(poses, flanges)
    result = calibrate_hand_eye([cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in images], poses, BOARD, SQUARE,
                                K_TRUE, DIST_TRUE)
    error = np.linalg.inv(T_FLANGE_CAM) @ result["T_flange_cam"]
    assert 1000 * np.linalg.norm(error[:3, 3]) < 2.0 and angle_deg(error[:3, :3]) < 0.2
    with pytest.raises(CalibrationError, match="pose 1: .*rigid"):
        asyncio.run(capture(config, [np.eye(4), 2 * np.eye(4)], tmp_path / "bad"))
