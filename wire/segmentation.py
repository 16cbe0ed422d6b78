"""A scan's segmentation as scan.json, a scan request and the cell's ``[scan]`` name it, and the core's
:class:`~robocell.core_cy.segment.Segmentation` it stands for.

Apart from ``wire.bundle`` so that checking a configuration or a request needs only the segmentation's
bounds, not the reconstruction behind a bundle: every part of a cell loads its configuration as it starts.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from robocell.core_cy.segment import AUTO, Segmentation

from .messages import field_errors

__all__ = ["StrictSpec", "AutoSegmentation", "HsvSegmentation", "ThresholdSegmentation", "SegmentationSpec", "core_segmentation"]

HSV = Annotated[list[Annotated[int, Field(ge=0, le=255)]], Field(min_length=3, max_length=3)]


class StrictSpec(BaseModel):
    """An object of scan.json: a misspelt key would otherwise be ignored and silently change the result."""

    model_config = ConfigDict(extra="forbid")


class AutoSegmentation(StrictSpec):
    method: Literal["auto"]


class HsvSegmentation(StrictSpec):
    method: Literal["hsv"]
    lower: HSV
    upper: HSV


class ThresholdSegmentation(StrictSpec):
    method: Literal["threshold"]
    value: Annotated[int, Field(ge=0, le=255)]
    invert: bool = False


SegmentationSpec = Annotated[Union[AutoSegmentation, HsvSegmentation, ThresholdSegmentation],
                             Field(discriminator="method")]
_SEGMENTATION_SPEC = TypeAdapter(SegmentationSpec | None)


def core_segmentation(spec: dict | AutoSegmentation | HsvSegmentation | ThresholdSegmentation | None
                      ) -> Segmentation:
    """The core's Segmentation for a scan.json ``segmentation`` (None: ``auto``, the default).

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
    if spec is None or isinstance(spec, AutoSegmentation):
        return AUTO
    if isinstance(spec, HsvSegmentation):
        (h0, s0, v0), (h1, s1, v1) = spec.lower, spec.upper
        return Segmentation("hsv", lower=(h0, s0, v0), upper=(h1, s1, v1))
    return Segmentation("threshold", value=spec.value, invert=spec.invert)
