"""Scan bundles (DESIGN.md §3): a directory with scan.json and its images.

Reading a bundle checks every field with pydantic and turns it into the
core's inputs; the images stay encoded bytes, so decoding is timed with the
reconstruction.

A bundle is untrusted input. Every file is read from inside the bundle's
directory (symlinks are followed only to files inside it), only if it is a
regular file, and only within the limits below; an image's size is read from
its header and checked, against the limits and against its view's K, before
anything is decoded.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path, PurePosixPath

import numpy as np
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from robocell.core_cy.camera import Camera
from robocell.core_cy.errors import CoreError
from robocell.core_cy.images import MAX_IMAGE_PIXELS, check_calibrated_size, checked_size
from robocell.core_cy.reconstruct import View
from robocell.core_cy.segment import Segmentation

from .errors import BundleError
from .messages import field_errors
from .segmentation import SegmentationSpec, StrictSpec, core_segmentation

__all__ = ["ScanJson", "ViewSpec", "CandidateSpec", "MAX_CANDIDATES", "Bundle", "load_bundle",
           "MAX_SCAN_JSON_BYTES", "MAX_VIEWS", "MAX_BUNDLE_BYTES", "MAX_BUNDLE_PIXELS", "MAX_IMAGE_PIXELS"]

#: scan.json is read only up to this size: 64 views at full precision take about 100 kB.
MAX_SCAN_JSON_BYTES = 1_000_000
#: Views of a bundle: the cell's own scans take at most 16; DTU's research sets 49 or 64.
MAX_VIEWS = 64
#: Candidate poses of the next view: a robot's reachable ring of views takes a few dozen.
MAX_CANDIDATES = 64
#: The images and masks read, together: they are held, encoded, until the reconstruction decodes them.
MAX_BUNDLE_BYTES = 256_000_000
#: Pixels of all the images and masks together: the reconstruction keeps about 5 bytes a pixel of
#: every view (its silhouette, and that silhouette smoothed for sub-pixel edges), 1.3 GB at most.
MAX_BUNDLE_PIXELS = 256_000_000

Row3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Row4 = Annotated[list[float], Field(min_length=4, max_length=4)]


class ViewSpec(StrictSpec):
    image: str | None = None
    mask: str | None = None
    K: Annotated[list[Row3], Field(min_length=3, max_length=3)]
    dist: list[float] | None = None
    T_world_cam: Annotated[list[Row4], Field(min_length=4, max_length=4)]
    #: The empty workspace from the same pose (DESIGN.md §3), for the segmentation.
    background: str | None = None

    @model_validator(mode="after")
    def _needs_a_picture(self) -> "ViewSpec":
        if self.image is None and self.mask is None:
            raise ValueError("a view needs an 'image' or a 'mask'")
        return self


class CandidateSpec(StrictSpec):
    """A pose the next view could be taken from (``robocell reconstruct --next-view``)."""

    K: Annotated[list[Row3], Field(min_length=3, max_length=3)]
    dist: list[float] | None = None
    T_world_cam: Annotated[list[Row4], Field(min_length=4, max_length=4)]


class ScanJson(StrictSpec):
    """The content of scan.json."""

    views: Annotated[list[ViewSpec], Field(max_length=MAX_VIEWS)]
    segmentation: SegmentationSpec | None = None
    support_plane: Row4 | None = None
    candidates: Annotated[list[CandidateSpec], Field(max_length=MAX_CANDIDATES)] | None = None


class Bundle(BaseModel):
    """A loaded bundle: the core's inputs."""

    model_config = ConfigDict(arbitrary_types_allowed=True, frozen=True)

    path: Path
    views: list[View]
    segmentation: Segmentation
    support_plane: list[float] | None
    candidates: list[Camera] | None = None


_FILE_KINDS = {stat.S_IFDIR: "a directory", stat.S_IFIFO: "a FIFO", stat.S_IFCHR: "a character device",
               stat.S_IFBLK: "a block device", stat.S_IFSOCK: "a socket"}


def _fail(view: int | None, message: str) -> BundleError:
    return BundleError(message if view is None else f"view {view}: {message}")


def _read_inside(root: str, name: str, *, what: str, view: int | None, limit: int, limit_text: str) -> bytes:
    """The bytes of the regular file ``name`` inside the bundle ``root`` (a real path), at most ``limit``.

    ``what`` names the file in errors ("image file 'view0.jpg'"); ``limit_text`` says what the
    limit is. Nothing but a regular file is opened, so a FIFO cannot hang the reader and a
    device cannot feed it forever.
    """
    if not name or "\0" in name:
        raise _fail(view, f"{what} is not a file name")
    if PurePosixPath(name).is_absolute() or ".." in PurePosixPath(name).parts:
        raise _fail(view, f"{what} is outside the bundle: name a file inside the bundle's directory, "
                          f"relative to it and without '..'")
    try:
        real = os.path.realpath(os.path.join(root, name), strict=True)
        if os.path.commonpath([root, real]) != root:
            raise _fail(view, f"{what} is a symlink out of the bundle (to {real!r})")
        status = os.stat(real)
        if not stat.S_ISREG(status.st_mode):
            raise _fail(view, f"{what} is {_FILE_KINDS.get(stat.S_IFMT(status.st_mode), 'special')}, "
                              f"not a regular file")
        if status.st_size > limit:
            raise _fail(view, f"{what} is {status.st_size / 1e6:.1f} MB; {limit_text}")
        # The file was checked by name; O_NOFOLLOW, O_NONBLOCK and the fstat keep a file swapped in
        # since then from being anything else.
        descriptor = os.open(real, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
        with open(descriptor, "rb") as file:
            if not stat.S_ISREG(os.fstat(descriptor).st_mode):
                raise _fail(view, f"{what} is not a regular file")
            data = file.read(limit + 1)
    except FileNotFoundError:
        raise _fail(view, f"{what} not found") from None
    except OSError as exc:
        raise _fail(view, f"cannot read {what}: {exc.strerror or exc}") from exc
    if len(data) > limit:  # it grew since it was checked
        raise _fail(view, f"{what} is over {limit / 1e6:.1f} MB; {limit_text}")
    return data


class _Budget:
    """What is left of a bundle's limits on the bytes and pixels of its images and masks."""

    def __init__(self) -> None:
        self.bytes = MAX_BUNDLE_BYTES
        self.pixels = MAX_BUNDLE_PIXELS

    def read_picture(self, root: str, name: str, what: str, camera: Camera, view: int) -> bytes:
        """The bytes of a view's image or mask, its size checked against the limits and K."""
        label = f"{what} file {name!r}"
        data = _read_inside(root, name, what=label, view=view, limit=self.bytes,
                            limit_text=f"the images and masks of a bundle take at most "
                                       f"{MAX_BUNDLE_BYTES / 1e6:.0f} MB together")
        self.bytes -= len(data)
        try:
            width, height = checked_size(data, what=label, view=view)
            check_calibrated_size(camera, width, height, what=label)
        except CoreError as exc:
            raise BundleError(str(exc)) from exc
        if width * height > self.pixels:
            raise _fail(view, f"{label} is {width}x{height} pixels, which takes the bundle over "
                              f"{MAX_BUNDLE_PIXELS / 1e6:.0f} megapixels of images and masks together")
        self.pixels -= width * height
        return data


def _parse_scan_json(data: bytes) -> ScanJson:
    try:
        return ScanJson.model_validate(json.loads(data))
    except ValidationError as exc:
        raise BundleError(f"scan.json: {field_errors(exc, whole='scan.json')}") from exc
    except RecursionError:
        raise BundleError("scan.json is not valid JSON: nested too deeply") from None
    except UnicodeDecodeError as exc:
        raise BundleError(f"scan.json is not UTF-8 text: {exc.reason} at byte {exc.start}") from exc
    except ValueError as exc:  # JSONDecodeError, and integers of thousands of digits
        raise BundleError(f"scan.json is not valid JSON: {exc}") from exc


def load_bundle(directory: str | Path) -> Bundle:
    """Read and validate a scan bundle.

    Raises
    ------
    BundleError
        If scan.json or a file it names is missing, unreadable, outside the
        bundle or not a regular file, a field is invalid, a limit is passed, or
        an image does not have the size its K was calibrated for (the message
        names the field, or the view).
    """
    directory = Path(directory)
    try:
        root = os.path.realpath(directory, strict=True)
    except OSError:
        root = ""
    if not (os.path.isdir(root) and os.path.lexists(os.path.join(root, "scan.json"))):
        kind = "directory" if os.path.isdir(root) else "path"
        raise BundleError(f"no scan.json in {kind} {str(directory)!r}")
    spec = _parse_scan_json(_read_inside(root, "scan.json", what="scan.json", view=None, limit=MAX_SCAN_JSON_BYTES,
                                         limit_text=f"at most {MAX_SCAN_JSON_BYTES / 1e6:.0f} MB is read"))
    views = []
    budget = _Budget()
    for index, view in enumerate(spec.views):
        try:
            camera = Camera(K=np.asarray(view.K), T_world_cam=np.asarray(view.T_world_cam),
                            dist=None if view.dist is None else np.asarray(view.dist), view=index)
        except CoreError as exc:
            raise BundleError(str(exc)) from exc
        # The mask wins over the image, so the image is not even read.
        if view.mask is not None:
            views.append(View(camera, mask=budget.read_picture(root, view.mask, "mask", camera, index)))
        else:
            assert view.image is not None  # a view names a mask or an image (ViewSpec checks)
            image = budget.read_picture(root, view.image, "image", camera, index)
            background = None
            if view.background is not None:
                background = budget.read_picture(root, view.background, "background", camera, index)
                image_size, background_size = checked_size(image), checked_size(background)
                if background_size != image_size:
                    raise _fail(index, f"background file {view.background!r} is {background_size[0]}x"
                                       f"{background_size[1]} pixels, but its image {view.image!r} is "
                                       f"{image_size[0]}x{image_size[1]}")
            views.append(View(camera, image=image, background=background))
    try:
        segmentation = core_segmentation(spec.segmentation)
    except CoreError as exc:
        raise BundleError(str(exc)) from exc
    return Bundle(path=directory, views=views, segmentation=segmentation,
                  support_plane=spec.support_plane, candidates=_candidates(spec.candidates))


def _candidates(specs: list[CandidateSpec] | None) -> list[Camera] | None:
    """The candidates' cameras; a malformed one is an error naming it."""
    if specs is None:
        return None
    cameras = []
    for index, spec in enumerate(specs):
        try:
            cameras.append(Camera(K=np.asarray(spec.K), T_world_cam=np.asarray(spec.T_world_cam),
                                  dist=None if spec.dist is None else np.asarray(spec.dist)))
        except CoreError as exc:
            raise BundleError(f"candidate {index}: {exc}") from exc
    return cameras
