"""Scan bundles (DESIGN.md §3): a directory with scan.json and its images.

Reading a bundle checks every field with pydantic and turns it into the
core's inputs; the images stay encoded bytes, so decoding is timed with the
reconstruction.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, model_validator

from core_cy.camera import Camera
from core_cy.errors import CoreError
from core_cy.reconstruct import View
from core_cy.segment import RED_HSV, Segmentation

from .errors import BundleError
from .messages import field_errors

__all__ = ["ScanJson", "ViewSpec", "SegmentationSpec", "Bundle", "load_bundle", "core_segmentation"]

Row3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Row4 = Annotated[list[float], Field(min_length=4, max_length=4)]
HSV = Annotated[list[Annotated[int, Field(ge=0, le=255)]], Field(min_length=3, max_length=3)]


class _Strict(BaseModel):
    # A misspelt key would otherwise be ignored and silently change the result.
    model_config = ConfigDict(extra="forbid")


class HsvSegmentation(_Strict):
    method: Literal["hsv"]
    lower: HSV
    upper: HSV


class ThresholdSegmentation(_Strict):
    method: Literal["threshold"]
    value: Annotated[int, Field(ge=0, le=255)]
    invert: bool = False


class ViewSpec(_Strict):
    image: str | None = None
    mask: str | None = None
    K: Annotated[list[Row3], Field(min_length=3, max_length=3)]
    dist: list[float] | None = None
    T_world_cam: Annotated[list[Row4], Field(min_length=4, max_length=4)]

    @model_validator(mode="after")
    def _needs_a_picture(self) -> "ViewSpec":
        if self.image is None and self.mask is None:
            raise ValueError("a view needs an 'image' or a 'mask'")
        return self


SegmentationSpec = Annotated[Union[HsvSegmentation, ThresholdSegmentation], Field(discriminator="method")]
_SEGMENTATION_SPEC = TypeAdapter(SegmentationSpec | None)


def core_segmentation(spec: dict | HsvSegmentation | ThresholdSegmentation | None) -> Segmentation:
    """The core's Segmentation for a scan.json ``segmentation`` (None: red, the default).

    Raises
    ------
    ValueError
        If a dict does not follow the scan.json format (the message names the field).
    CoreError
        If a bound is out of its range.
    """
    if isinstance(spec, dict):
        try:
            spec = _SEGMENTATION_SPEC.validate_python(spec)
        except ValidationError as exc:
            raise ValueError(f"segmentation: {field_errors(exc, whole='segmentation')}") from None
    if spec is None:
        return RED_HSV
    if isinstance(spec, HsvSegmentation):
        (h0, s0, v0), (h1, s1, v1) = spec.lower, spec.upper
        return Segmentation("hsv", lower=(h0, s0, v0), upper=(h1, s1, v1))
    return Segmentation("threshold", value=spec.value, invert=spec.invert)


class ScanJson(_Strict):
    """The content of scan.json."""

    views: list[ViewSpec]
    segmentation: SegmentationSpec | None = None
    support_plane: Row4 | None = None


class Bundle(BaseModel):
    """A loaded bundle: the core's inputs."""

    model_config = ConfigDict(arbitrary_types_allowed=True, frozen=True)

    path: Path
    views: list[View]
    segmentation: Segmentation
    support_plane: list[float] | None


def _read(path: Path, what: str, view: int) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise BundleError(f"view {view}: {what} file {path.name!r} not found") from None
    except OSError as exc:
        raise BundleError(f"view {view}: cannot read {what} file {path.name!r}: {exc.strerror}") from exc


def load_bundle(directory: str | Path) -> Bundle:
    """Read and validate a scan bundle.

    Raises
    ------
    BundleError
        If scan.json or a file it names is missing or unreadable, or a field
        is invalid (the message names the field, or the view).
    """
    directory = Path(directory)
    scan_file = directory / "scan.json"
    try:
        text = scan_file.read_text(encoding="utf-8")
    except FileNotFoundError:
        kind = "directory" if directory.is_dir() else "path"
        raise BundleError(f"no scan.json in {kind} {str(directory)!r}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BundleError(f"cannot read scan.json: {exc}") from exc
    try:
        spec = ScanJson.model_validate(json.loads(text))
    except json.JSONDecodeError as exc:
        raise BundleError(f"scan.json is not valid JSON: {exc}") from exc
    except ValidationError as exc:
        raise BundleError(f"scan.json: {field_errors(exc, whole='scan.json')}") from exc

    views = []
    for index, view in enumerate(spec.views):
        try:
            camera = Camera(K=np.asarray(view.K), T_world_cam=np.asarray(view.T_world_cam),
                            dist=None if view.dist is None else np.asarray(view.dist), view=index)
        except CoreError as exc:
            raise BundleError(str(exc)) from exc
        # The mask wins over the image, so the image is not even read.
        if view.mask is not None:
            views.append(View(camera, mask=_read(directory / view.mask, "mask", index)))
        else:
            assert view.image is not None  # a view names a mask or an image (ViewSpec checks)
            views.append(View(camera, image=_read(directory / view.image, "image", index)))
    try:
        segmentation = core_segmentation(spec.segmentation)
    except CoreError as exc:
        raise BundleError(str(exc)) from exc
    return Bundle(path=directory, views=views, segmentation=segmentation,
                  support_plane=spec.support_plane)
