"""Scan bundles written from exact scenes, for tests of the bundle reader and the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from tests.helpers import intrinsics, look_at, sphere_silhouette
from core_cy.camera import Camera

SPHERE_CENTRE = np.array([0.6, 0.0, 0.04])
SPHERE_RADIUS = 0.04


def tabletop_poses(target, distance=0.5, elevations=(50, 40, 35), azimuths=(0, 120, 240)):
    poses = []
    for elevation, azimuth in zip(np.radians(elevations), np.radians(azimuths)):
        offset = distance * np.array([np.cos(elevation) * np.cos(azimuth),
                                      np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        poses.append(look_at(np.asarray(target) + offset, target))
    return poses


def write_sphere_bundle(directory: Path, *, masks: bool = False, scale: float = 1.0,
                        support_plane=(0, 0, 1, 0)) -> Path:
    """A red sphere resting on the table z = 0, seen from three tabletop views, in JPEG.

    ``scale`` multiplies every length (1000: millimetres); ``masks`` adds exact masks.
    """
    directory.mkdir(parents=True, exist_ok=True)
    K = intrinsics()
    views = []
    for index, pose in enumerate(tabletop_poses(SPHERE_CENTRE)):
        silhouette = sphere_silhouette(Camera(K=K, T_world_cam=pose), SPHERE_CENTRE, SPHERE_RADIUS)
        image = np.full((*silhouette.shape, 3), (110, 120, 125), np.uint8)
        image[silhouette > 0] = (30, 30, 200)
        cv2.imwrite(str(directory / f"view{index}.jpg"), image, [cv2.IMWRITE_JPEG_QUALITY, 90])
        scaled = pose.copy()
        scaled[:3, 3] *= scale
        view = {"image": f"view{index}.jpg", "K": K.tolist(), "T_world_cam": scaled.tolist()}
        if masks:
            cv2.imwrite(str(directory / f"mask{index}.png"), silhouette)
            view["mask"] = f"mask{index}.png"
        views.append(view)
    scan = {"views": views}
    if support_plane is not None:
        scan["support_plane"] = [float(support_plane[0]), float(support_plane[1]),
                                 float(support_plane[2]), float(support_plane[3]) * scale]
    (directory / "scan.json").write_text(json.dumps(scan, indent=1))
    truth = {"size": [SPHERE_RADIUS * scale] * 3, "shape": [1.0, 1.0],
             "T_world_object": _translation(SPHERE_CENTRE * scale).tolist()}
    (directory / "truth.json").write_text(json.dumps(truth))
    return directory


def _translation(offset) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = offset
    return T


def edit_scan(directory: Path, change) -> None:
    """Apply ``change(scan_dict)`` to a bundle's scan.json."""
    path = directory / "scan.json"
    scan = json.loads(path.read_text())
    change(scan)
    path.write_text(json.dumps(scan))
