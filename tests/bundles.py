"""Scan bundles written from exact scenes, for tests of the bundle reader and the CLI."""

from __future__ import annotations

import json
import os
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from tests.helpers import intrinsics, look_at, sphere_silhouette
from robocell.core_cy.camera import Camera

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


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def blank_png(width: int, height: int) -> bytes:
    """A valid, all-black 1-bit PNG: 20000x20000 takes 48 kB, and 400 MB once decoded."""
    rows = zlib.compressobj(9)
    row = bytes(1 + (width + 7) // 8)  # filter byte, then the row's bits
    data = b"".join([rows.compress(row) for _ in range(height)] + [rows.flush()])
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0))
            + _png_chunk(b"IDAT", data) + _png_chunk(b"IEND", b""))


def _jpeg_claiming(data: bytes, width: int, height: int) -> bytes:
    """``data`` (a JPEG) with its frame header changed to claim ``width`` x ``height`` pixels."""
    at = 2
    while data[at + 1] not in range(0xC0, 0xC4):  # the baseline or progressive frame header
        at += 2 + struct.unpack(">H", data[at + 2:at + 4])[0]
    return data[:at + 5] + struct.pack(">HH", height, width) + data[at + 9:]


def _outside_image(directory: Path) -> Path:
    """A good picture beside the bundle, which the bundle must not be able to read."""
    outside = directory.parent / "outside.jpg"
    outside.write_bytes((directory / "view0.jpg").read_bytes())
    return outside


def _name(view: int, key: str, name: str):
    return lambda d: edit_scan(d, lambda s: s["views"][view].update({key: name}))


def _symlink(view: int, target) -> Callable[[Path], None]:
    def change(directory: Path) -> None:
        (directory / f"view{view}.jpg").unlink()
        (directory / f"view{view}.jpg").symlink_to(target(directory) if callable(target) else target)
    return change


def _fifo(directory: Path) -> None:
    (directory / "view1.jpg").unlink()
    os.mkfifo(directory / "view1.jpg")


def _many_views(count: int) -> Callable[[Path], None]:
    return lambda d: edit_scan(d, lambda s: s.update(views=[s["views"][i % 3] for i in range(count)]))


def _mask(view: int, shape: tuple[int, int]) -> Callable[[Path], None]:
    def change(directory: Path) -> None:
        cv2.imwrite(str(directory / f"mask{view}.png"), np.full(shape, 255, np.uint8))
        edit_scan(directory, lambda s: s["views"][view].update(mask=f"mask{view}.png"))
    return change


def _write(name: str, data: Callable[[Path], bytes]) -> Callable[[Path], None]:
    return lambda d: (d / name).write_bytes(data(d))


def _sparse_scan_json(directory: Path) -> None:
    with open(directory / "scan.json", "r+b") as file:
        file.truncate(2**31)  # 2 GB that take no disk: zeros after the JSON


def _sparse_image(directory: Path) -> None:
    with open(directory / "view0.jpg", "r+b") as file:
        file.truncate(300_000_000)  # a JPEG's header, then zeros that take no disk


def _large_masks(directory: Path) -> None:
    """Six views of 48 megapixels each: each within the limit, together over it."""
    (directory / "large.png").write_bytes(blank_png(8000, 6000))
    K = intrinsics(7500.0, 8000, 6000).tolist()
    edit_scan(directory, lambda s: s.update(views=[{**s["views"][i % 3], "mask": "large.png", "K": K}
                                                   for i in range(6)]))


def _huge_integer(directory: Path) -> None:
    edit_scan(directory, lambda s: s["views"][0]["K"][0].__setitem__(0, "focal"))
    text = (directory / "scan.json").read_text()
    (directory / "scan.json").write_text(text.replace('"focal"', "9" * 5000))


#: Hostile bundles (DESIGN.md §3, "A bundle is untrusted input"): how each is made from a copy of
#: :func:`write_sphere_bundle`'s bundle (JPEGs, 640x480), and what its one-line error must say.
HOSTILE_BUNDLES: dict[str, tuple[Callable[[Path], None], str]] = {
    "file-outside": (lambda d: (_outside_image(d), _name(0, "image", "../outside.jpg")(d)),
                     "view 0: image file '../outside.jpg' is outside the bundle"),
    "absolute-path": (_name(2, "image", "/dev/zero"), "view 2: image file '/dev/zero' is outside the bundle"),
    "symlink-out": (_symlink(1, _outside_image), "view 1: image file 'view1.jpg' is a symlink out of the bundle"),
    "symlink-to-dev-zero": (_symlink(0, "/dev/zero"), "view 0: image file 'view0.jpg' is a symlink out of the bundle"),
    "scan-json-to-dev-zero": (lambda d: ((d / "scan.json").unlink(), (d / "scan.json").symlink_to("/dev/zero")),
                              "scan.json is a symlink out of the bundle"),
    "fifo": (_fifo, "view 1: image file 'view1.jpg' is a FIFO, not a regular file"),
    "directory": (lambda d: ((d / "view2.jpg").unlink(), (d / "view2.jpg").mkdir()),
                  "view 2: image file 'view2.jpg' is a directory, not a regular file"),
    "nul-in-name": (_name(1, "image", "view1.jpg\0.png"), "view 1: image file 'view1.jpg\\x00.png' is not a file name"),
    "huge-scan-json": (_sparse_scan_json, "scan.json is 2147.5 MB; at most 1 MB is read"),
    "16000-views": (_many_views(16000), "MB; at most 1 MB is read"),
    "65-views": (_many_views(65), "scan.json: views: List should have at most 64 items"),
    "300-mb-image": (_sparse_image, "view 0: image file 'view0.jpg' is 300.0 MB; the images and masks of a bundle "
                                    "take at most 256 MB together"),
    "6-images-of-48-mp": (_large_masks, "view 5: mask file 'large.png' is 8000x6000 pixels, which takes the bundle "
                                        "over 256 megapixels of images and masks together"),
    "deep-json": (lambda d: (d / "scan.json").write_text('{"views": ' + "[" * 100_000 + "]" * 100_000 + "}"),
                  "scan.json is not valid JSON: nested too deeply"),
    "huge-integer": (_huge_integer, "scan.json is not valid JSON: Exceeds the limit (4300 digits)"),
    "20000x20000-png": (lambda d: ((d / "view1.jpg").write_bytes(blank_png(20_000, 20_000))),
                        "view 1: image file 'view1.jpg' is 20000x20000 pixels (400.0 megapixels); "
                        "at most 50 megapixels are decoded"),
    "65000x65000-jpeg": (_write("view2.jpg", lambda d: _jpeg_claiming((d / "view2.jpg").read_bytes(), 65000, 65000)),
                         "view 2: image file 'view2.jpg' is 65000x65000 pixels"),
    "40000x1000-png": (_mask(0, (1000, 40_000)), "view 0: mask file 'mask0.png' is 40000x1000 pixels; at most 32767 "
                                                 "a side are decoded"),
    "100x100-mask": (_mask(1, (100, 100)), "view 1: mask file 'mask1.png' is 100x100 pixels, but K was calibrated "
                                           "for about 640x480"),
    "half-size-image": (_write("view0.jpg", lambda d: cv2.imencode(".jpg", cv2.resize(
        cv2.imread(str(d / "view0.jpg")), (320, 240)))[1].tobytes()),
        "view 0: image file 'view0.jpg' is 320x240 pixels, but K was calibrated for about 640x480"),
    "distortion-1e300": (lambda d: edit_scan(d, lambda s: s["views"][2].update(dist=[1e300, 0, 0, 0, 0])),
                         "view 2: dist [1e+300, 0, 0, 0, 0] moves pixels of the image to infinity"),
    "distortion-1e6": (lambda d: edit_scan(d, lambda s: s["views"][0].update(dist=[0, 0, 1e6, 0])),
                       "view 0: dist [0, 0, 1e+06, 0] moves pixels of the image by up to"),
}
