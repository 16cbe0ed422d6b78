"""Camera calibration with a chessboard: intrinsics (K, distortion) and hand-eye (the camera on the flange).

Pure functions on images already in memory; ``robocell.cli.calibrate`` reads the
files and writes the results into the cell's configuration.

A board is given by its *inner* corners, ``(cols, rows)``, e.g. ``(9, 6)`` for a
board of 10 x 7 squares, and its square size in metres. The board frame has its
origin at the first inner corner, x along a row, y down the columns, z into the
board. For hand-eye calibration every image must give the same board frame, so
the corners are put in a canonical order: a right-handed frame seen from the
front, with the square between the first four corners dark. That needs a board
that differs from itself turned by 180 degrees: ``cols + rows`` odd.

Examples
--------
>>> parse_board("9x6")
(9, 6)
>>> board_points((3, 2), 0.5).tolist()
[[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.5, 0.5, 0.0], [1.0, 0.5, 0.0]]
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from .errors import CalibrationError
from .rigid import rigid_error

__all__ = [
    "parse_board", "board_points", "find_corners", "calibrate_intrinsics", "calibrate_hand_eye",
    "HAND_EYE_METHODS", "MIN_INTRINSICS_IMAGES", "MIN_HAND_EYE_IMAGES",
]

HAND_EYE_METHODS = {
    "TSAI": cv2.CALIB_HAND_EYE_TSAI, "PARK": cv2.CALIB_HAND_EYE_PARK, "HORAUD": cv2.CALIB_HAND_EYE_HORAUD,
    "ANDREFF": cv2.CALIB_HAND_EYE_ANDREFF, "DANIILIDIS": cv2.CALIB_HAND_EYE_DANIILIDIS,
}
#: Zhang's method needs three views of a plane for K; more give distortion and accuracy (10-20 is usual).
MIN_INTRINSICS_IMAGES = 3
#: Two motions with different rotation axes fix the hand-eye transform: three poses.
MIN_HAND_EYE_IMAGES = 3
_MAX_REACH_M = 10.0  # a flange further from the base was given in millimetres
_MIN_SECOND_AXIS_DEG = 3.0
_SUBPIX = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)

Names = Sequence[Any]


def parse_board(text: str) -> tuple[int, int]:
    """``"COLSxROWS"`` (inner corners) as ``(cols, rows)``; ValueError if malformed or smaller than 2x2."""
    parts = text.lower().replace(" ", "").split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise ValueError(f"board must be COLSxROWS inner corners, e.g. 9x6, got {text!r}")
    return _check_board((int(parts[0]), int(parts[1])))


def _check_board(board: Sequence[int]) -> tuple[int, int]:
    cols, rows = (int(v) for v in board)
    if cols < 2 or rows < 2:
        raise ValueError(f"a board needs at least 2x2 inner corners, got {cols}x{rows}")
    return cols, rows


def board_points(board: Sequence[int], square: float) -> NDArray[np.float32]:
    """(cols * rows, 3) inner corners in the board frame, metres, row by row."""
    cols, rows = _check_board(board)
    if not square > 0:
        raise ValueError(f"square size must be positive (metres), got {square}")
    j, i = np.mgrid[0:rows, 0:cols]
    return np.stack([i.ravel() * square, j.ravel() * square, np.zeros(i.size)], axis=1).astype(np.float32)


def _grey(image: ArrayLike, name: Any) -> NDArray[np.uint8]:
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3)):
        raise ValueError(f"image {name}: expected an (H, W) or (H, W, 3) uint8 array, "
                         f"got {img.dtype} of shape {img.shape}")
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 and img.shape[2] == 3 else img.reshape(img.shape[:2])
    return np.asarray(grey, dtype=np.uint8)


def find_corners(image: ArrayLike, board: Sequence[int]) -> NDArray[np.float32] | None:
    """The board's inner corners in the image, sub-pixel, in canonical order; None if not found.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray of uint8
        Grey or BGR.
    board : (cols, rows)
        Inner corners per row and per column.

    Returns
    -------
    (cols * rows, 2) ndarray of float32 or None
        Pixel coordinates in the order of :func:`board_points`.
    """
    cols, rows = _check_board(board)
    grey = _grey(image, "")
    # FAST_CHECK: an image without a board is rejected in milliseconds instead of seconds.
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    found, corners = cv2.findChessboardCorners(grey, (cols, rows), flags=flags)
    if not found:
        return None
    grid = corners.reshape(rows, cols, 2)
    spacing = min(float(np.min(np.linalg.norm(np.diff(grid, axis=0), axis=2))),
                  float(np.min(np.linalg.norm(np.diff(grid, axis=1), axis=2))))
    # The search window must stay within the four squares meeting at a corner, or a neighbour pulls it.
    half = int(np.clip(0.4 * spacing, 2, 11))
    corners = cv2.cornerSubPix(grey, np.ascontiguousarray(grid.reshape(-1, 1, 2)), (half, half), (-1, -1), _SUBPIX)
    grid = np.asarray(corners, dtype=np.float32).reshape(rows, cols, 2)
    # Projection keeps handedness, so a mirrored order (x cross y pointing at the camera) is
    # the detector's choice, not the board's: reverse the rows to undo it.
    dx, dy = grid[0, 1] - grid[0, 0], grid[1, 0] - grid[0, 0]
    if dx[0] * dy[1] - dx[1] * dy[0] < 0:
        grid = grid[::-1]
    if (cols + rows) % 2 == 1 and not _first_square_dark(grey, grid):
        grid = grid[::-1, ::-1]  # the same board turned by 180 degrees
    return np.ascontiguousarray(grid.reshape(-1, 2), dtype=np.float32)


def _first_square_dark(grey: NDArray[np.uint8], grid: NDArray[np.float32]) -> bool:
    """Is the square between the first four corners darker than its neighbour along the longer side?"""
    def level(a: int, b: int) -> float:
        centre = grid[a:a + 2, b:b + 2].reshape(-1, 2).mean(axis=0)
        return float(cv2.getRectSubPix(grey, (3, 3), (float(centre[0]), float(centre[1]))).mean())

    neighbour = level(0, 1) if grid.shape[1] >= 3 else level(1, 0)
    return level(0, 0) < neighbour


def _names(images: Sequence[Any], names: Names | None) -> list[Any]:
    if names is None:
        return list(range(len(images)))
    if len(names) != len(images):
        raise ValueError(f"{len(names)} names for {len(images)} images")
    return list(names)


def _detect(images: Sequence[ArrayLike], board: tuple[int, int], names: list[Any]):
    """(image size, [(index, corners)], skipped names); all images must have one size."""
    size, found, skipped = None, [], []
    for k, (name, image) in enumerate(zip(names, images)):
        grey = _grey(image, name)
        this = (grey.shape[1], grey.shape[0])
        if size is not None and this != size:
            raise CalibrationError(f"image {name} is {this[0]}x{this[1]}, the ones before it {size[0]}x{size[1]}: "
                                   "calibrate one resolution at a time")
        size = this
        corners = find_corners(grey, board)
        if corners is None:
            skipped.append(name)
        else:
            found.append((k, corners))
    return size, found, skipped


def _enough(found: int, total: int, needed: int, board: tuple[int, int], what: str) -> None:
    if found < needed:
        raise CalibrationError(
            f"{what} calibration needs at least {needed} images showing the {board[0]}x{board[1]} board, "
            f"found it in {found} of {total} (check --board: inner corners, not squares)")


def calibrate_intrinsics(images: Sequence[ArrayLike], board: Sequence[int], square: float, *,
                         k3: bool = False, names: Names | None = None) -> dict[str, Any]:
    """K and distortion of a camera from images of a chessboard.

    Parameters
    ----------
    images : sequence of (H, W) or (H, W, 3) ndarray of uint8
        All of one size; varied tilts and positions of the board give the best K.
    board : (cols, rows)
        Inner corners.
    square : float
        Side of a square, metres.
    k3 : bool
        Also fit the third radial coefficient. Off by default, as in ROS's
        camera_calibration: for ordinary lenses k3 trades off against k2 and comes
        out large and meaningless, fine inside the image and wild beyond it.
    names : sequence, optional
        How to name the images in ``skipped`` and in errors (default: their indices).

    Returns
    -------
    dict
        ``K`` (3, 3) ndarray, ``dist`` (5,) ndarray (k1, k2, p1, p2, k3), ``rms``
        reprojection error in pixels, ``image_size`` (width, height), ``skipped``
        the names of the images where the board was not found.

    Raises
    ------
    CalibrationError
        Fewer than ``MIN_INTRINSICS_IMAGES`` images show the board, or the images differ in size.
    """
    board = _check_board(board)
    names = _names(images, names)
    size, found, skipped = _detect(images, board, names)
    _enough(len(found), len(images), MIN_INTRINSICS_IMAGES, board, "intrinsic")
    obj = board_points(board, square)
    flags = 0 if k3 else cv2.CALIB_FIX_K3
    rms, K, dist, _, _ = cv2.calibrateCamera([obj] * len(found), [c for _, c in found], size, None, None,
                                             flags=flags)
    return {"K": K, "dist": dist.ravel(), "rms": float(rms), "image_size": size, "skipped": skipped}


def _check_poses(flange_poses: Sequence[ArrayLike], n_images: int) -> list[NDArray[np.float64]]:
    if len(flange_poses) != n_images:
        raise CalibrationError(f"{len(flange_poses)} flange poses for {n_images} images: "
                               "need one pose per image, in the same order")
    poses = []
    for i, pose in enumerate(flange_poses):
        T = np.asarray(pose, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise CalibrationError(f"flange pose {i} is not a finite 4x4 matrix (shape {T.shape})")
        problem = rigid_error(T)
        if problem is not None:
            raise CalibrationError(f"flange pose {i} {problem}")
        R = T[:3, :3]
        if np.linalg.norm(T[:3, 3]) > _MAX_REACH_M:
            raise CalibrationError(f"flange pose {i} lies {np.linalg.norm(T[:3, 3]):.0f} m from the base: "
                                   "poses must be in metres (KUKA's X, Y, Z are millimetres)")
        u, _, vt = np.linalg.svd(R)  # the nearest exact rotation, for OpenCV
        T = T.copy()
        T[:3, :3] = u @ vt
        poses.append(T)
    return poses


def _check_rotations(poses: list[NDArray[np.float64]]) -> None:
    """Hand-eye needs rotations about two different axes; about one axis the offset along it is unknown."""
    rotvecs = np.array([Rotation.from_matrix(poses[0][:3, :3].T @ T[:3, :3]).as_rotvec() for T in poses[1:]])
    second = np.linalg.svd(rotvecs, compute_uv=False)[1] if len(rotvecs) >= 2 else 0.0
    if np.degrees(second) < _MIN_SECOND_AXIS_DEG:
        raise CalibrationError("the flange poses rotate about one axis only (or hardly at all): "
                               "tilt the flange in at least two different directions between images")


def _inverse(T: NDArray[np.float64]) -> NDArray[np.float64]:
    inv = np.eye(4)
    inv[:3, :3] = T[:3, :3].T
    inv[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return inv


def calibrate_hand_eye(images: Sequence[ArrayLike], flange_poses: Sequence[ArrayLike], board: Sequence[int],
                       square: float, K: ArrayLike, dist: ArrayLike | None = None, method: str = "TSAI", *,
                       refine: bool = True, names: Names | None = None) -> dict[str, Any]:
    """The camera's pose on the flange from images of a fixed chessboard and the flange's poses.

    Parameters
    ----------
    images : sequence of ndarray of uint8
        Taken by the wrist camera with the board fixed in the robot's cell.
    flange_poses : sequence of (4, 4) array_like
        The flange's pose in the robot base frame (flange-to-base), metres, one per image.
    board, square :
        As for :func:`calibrate_intrinsics`; ``cols + rows`` must be odd.
    K : (3, 3) array_like
        Camera matrix at the images' resolution; ``dist`` its OpenCV distortion (default none).
    method : {"TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS"}
        ``cv2.calibrateHandEye``'s method, any case.
    refine : bool
        Polish the method's closed-form answer, and the board's pose, by least
        squares on the corners' reprojection error: the closed forms fit the
        motions between pose pairs, not the pixels (measured on rendered views:
        0.4-4.6 mm before, under 0.1 mm after).

    Returns
    -------
    dict
        ``T_flange_cam`` (4, 4) ndarray, camera-to-flange; ``residual_mm`` and
        ``residual_deg``, the RMS spread of the board's centre and orientation in the
        base frame as each image implies them (zero for a perfect calibration);
        ``rms_px``, the corners' RMS reprojection error through the robot's poses;
        ``method``; ``skipped``, the images where the board was not found.

    Raises
    ------
    CalibrationError
        Too few images show the board, the pose count differs from the image
        count, a pose is not a rigid motion or not in metres, the poses do not
        rotate about two axes, the board is symmetric, or the method failed.
    ValueError
        For an unknown method or a malformed K.
    """
    name = str(method).upper()
    if name not in HAND_EYE_METHODS:
        raise ValueError(f"unknown hand-eye method {method!r}; choose one of {', '.join(HAND_EYE_METHODS).lower()}")
    board = _check_board(board)
    if sum(board) % 2 == 0:
        raise CalibrationError(f"a {board[0]}x{board[1]} board looks the same turned by 180 degrees, so its "
                               "pose is ambiguous: use a board with cols + rows odd, e.g. 9x6")
    names = _names(images, names)
    poses = _check_poses(flange_poses, len(images))
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise ValueError(f"K must be 3x3, got shape {K.shape}")
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=np.float64).ravel()
    _, found, skipped = _detect(images, board, names)
    _enough(len(found), len(images), MIN_HAND_EYE_IMAGES, board, "hand-eye")
    used, corners = [poses[k] for k, _ in found], [c.astype(np.float64) for _, c in found]
    _check_rotations(used)
    obj = board_points(board, square).astype(np.float64)
    T_cam_board = []
    for c in corners:
        _, rvec, tvec = cv2.solvePnP(obj, c, K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        T_cam_board.append(_matrix(cv2.Rodrigues(rvec)[0], tvec))
    R, t = cv2.calibrateHandEye([T[:3, :3] for T in used], [T[:3, 3] for T in used],
                                [T[:3, :3] for T in T_cam_board], [T[:3, 3] for T in T_cam_board],
                                method=HAND_EYE_METHODS[name])
    # OpenCV reports a failure on stderr only, answering identity and zero (Tsai, since 4.10: too few
    # consecutive pairs rotate by a useful angle) or NaN (Andreff on some data).
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))) or (np.array_equal(R, np.eye(3)) and not t.any()):
        raise CalibrationError(f"cv2.calibrateHandEye ({name}) failed: Tsai uses consecutive images only, "
                               "and ignores pairs turned by little or by nearly 180 degrees; "
                               "reorder the images or choose another --method (park, horaud)")
    X = _matrix(R, t)
    B = _mean_pose([P @ X @ C for P, C in zip(used, T_cam_board)])
    if refine:
        X, B = _refine(X, B, used, corners, obj, K, dist)
    rms = float(np.sqrt(np.mean(_reprojection(X, B, used, corners, obj, K, dist) ** 2)))
    mm, deg = _spread([P @ X @ C for P, C in zip(used, T_cam_board)], obj.mean(axis=0))
    return {"T_flange_cam": X, "residual_mm": mm, "residual_deg": deg, "rms_px": rms, "method": name,
            "skipped": skipped}


def _matrix(R: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, np.ravel(t)
    return T


def _mean_pose(poses: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    rotations = Rotation.from_matrix(np.array([T[:3, :3] for T in poses]))
    return _matrix(rotations.mean().as_matrix(), np.mean([T[:3, 3] for T in poses], axis=0))


def _reprojection(X, B, flanges, corners, obj, K, dist) -> NDArray[np.float64]:
    """Pixel errors of every corner, the camera at flange @ X, the board at B (both in the base frame)."""
    errors = []
    for F, c in zip(flanges, corners):
        T = _inverse(F @ X) @ B
        uv = cv2.projectPoints(obj, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K, dist)[0].reshape(-1, 2)
        errors.append(uv - c)
    return np.concatenate(errors).ravel()


def _refine(X, B, flanges, corners, obj, K, dist) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Least-squares X and B; each moves by a local correction (rotation vector, translation), which,
    unlike a global rotation vector, has no singularity near the board's usual half-turn."""
    def unpack(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return (X @ _matrix(Rotation.from_rotvec(x[:3]).as_matrix(), x[3:6]),
                B @ _matrix(Rotation.from_rotvec(x[6:9]).as_matrix(), x[9:]))

    fit = least_squares(lambda x: _reprojection(*unpack(x), flanges, corners, obj, K, dist), np.zeros(12),
                        method="lm", x_scale="jac")
    return unpack(fit.x)


def _spread(T_base_board: list[NDArray[np.float64]], centre: NDArray[np.float64]) -> tuple[float, float]:
    """RMS distance (mm) of the board centre, and RMS angle (degrees) of its orientation, from their means."""
    points = np.array([T[:3, :3] @ centre + T[:3, 3] for T in T_base_board])
    mm = 1000.0 * float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))
    rotations = Rotation.from_matrix(np.array([T[:3, :3] for T in T_base_board]))
    angles = (rotations.mean().inv() * rotations).magnitude()
    return mm, float(np.degrees(np.sqrt(np.mean(angles ** 2))))
