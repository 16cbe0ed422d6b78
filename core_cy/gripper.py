"""Parallel-jaw grippers and grasps (DESIGN.md §3): the gripper's dimensions and the grasp frame.

The grasp frame: **z** the approach (palm to fingertips), **y** the closing
direction, **x = y × z**; the origin midway between the pads, at their centre.
Fingertips lie at ``z = pad_length/2``, the palm at
``z = pad_length/2 - finger_length``. Each finger is ``finger_width`` wide along
x and ``finger_thickness`` thick along y; its pad covers the last
``pad_length`` before the tip. The palm, and the gripper body behind it,
covers ``|x| <= palm_width/2`` and ``|y| <= max_opening/2 + finger_thickness``
at and behind ``z = pad_length/2 - finger_length``.
"""

from __future__ import annotations

import json
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from .errors import GripperError

__all__ = ["Gripper", "Grasp", "DEFAULT_GRIPPER", "grasps_to_json"]


def _number(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise GripperError(f"gripper {name} must be a finite number, got {value!r}")
    if value <= 0:
        raise GripperError(f"gripper {name} must be positive, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Gripper:
    """A parallel-jaw gripper (DESIGN.md §3), in the scan's units.

    Parameters
    ----------
    max_opening : float
        Largest gap between the finger pads.
    finger_length : float
        From the palm to the fingertip, along the approach.
    finger_width : float
        Across the finger, along the grasp x axis.
    finger_thickness : float
        Of each finger, along the closing (y) axis.
    pad_length : float
        The contact pad covers this much of the finger before its tip.
    palm_width : float
        Of the palm along x; along y it spans both fingers at full opening.
    friction : float
        Coefficient of friction of the pads on objects (0.5 when not given).

    Raises
    ------
    GripperError
        Naming the field that is not a positive finite number, or a pad
        longer than its finger, a finger wider than the palm, or a friction
        coefficient above 2.

    Examples
    --------
    >>> Gripper().max_opening
    0.085
    >>> Gripper.from_dict({**Gripper().to_dict(), "pad_length": 0.05})
    Traceback (most recent call last):
    ...
    robocell.core_cy.errors.GripperError: gripper pad_length (0.05) is longer than finger_length (0.045)
    """

    max_opening: float = 0.085
    finger_length: float = 0.045
    finger_width: float = 0.02
    finger_thickness: float = 0.008
    pad_length: float = 0.02
    palm_width: float = 0.06
    friction: float = 0.5

    def __post_init__(self) -> None:
        for field in fields(self):
            object.__setattr__(self, field.name, _number(field.name, getattr(self, field.name)))
        if self.pad_length > self.finger_length:
            raise GripperError(f"gripper pad_length ({self.pad_length:g}) is longer than "
                               f"finger_length ({self.finger_length:g})")
        if self.finger_width > self.palm_width:
            raise GripperError(f"gripper finger_width ({self.finger_width:g}) is wider than "
                               f"palm_width ({self.palm_width:g})")
        if self.friction > 2:
            raise GripperError(f"gripper friction must be at most 2, got {self.friction:g}")

    @classmethod
    def from_dict(cls, d) -> Gripper:
        """From the JSON object of DESIGN.md §3; every field but ``friction`` is required."""
        if not isinstance(d, Mapping):
            raise GripperError(f"a gripper must be a JSON object of its dimensions, got {type(d).__name__}")
        names = [field.name for field in fields(cls)]
        for key in d:
            if key not in names:
                raise GripperError(f"gripper has an unknown field {key!r} (expected {', '.join(names)})")
        for name in names[:-1]:
            if name not in d:
                raise GripperError(f"gripper is missing {name}")
        return cls(**d)

    @classmethod
    def from_json(cls, text: str | bytes) -> Gripper:
        """From the text of a ``GRIPPER.json`` file."""
        try:
            d = json.loads(text)
        except (ValueError, UnicodeDecodeError) as exc:
            raise GripperError(f"the gripper file is not JSON: {exc}") from exc
        return cls.from_dict(d)

    def to_dict(self) -> dict[str, float]:
        return {field.name: getattr(self, field.name) for field in fields(self)}

    @property
    def tip(self) -> float:
        """z of the fingertips in the grasp frame."""
        return self.pad_length / 2

    @property
    def palm(self) -> float:
        """z of the palm in the grasp frame."""
        return self.pad_length / 2 - self.finger_length

    def corners(self) -> np.ndarray:
        """(20, 3) grasp-frame corners of both fingers at full opening and of the palm."""
        g, t, w, p = self.max_opening / 2, self.finger_thickness, self.finger_width / 2, self.palm_width / 2
        fingers = [(x, s * y, z) for x in (-w, w) for s in (-1, 1) for y in (g, g + t)
                   for z in (self.palm, self.tip)]
        palm = [(x, y, self.palm) for x in (-p, p) for y in (-(g + t), g + t)]
        return np.array(fingers + palm)


DEFAULT_GRIPPER = Gripper()


@dataclass(frozen=True, eq=False)
class Grasp:
    """One planned grasp.

    Attributes
    ----------
    T_world_grasp : (4, 4) ndarray
        Grasp-to-world (DESIGN.md §3 frame).
    width : float
        The model's width between the pads at this pose.
    score : float
        Estimated chance, in [0, 1], that the grasp holds given the model's error.
    approach : str
        ``"top"`` (within 30 degrees of straight down the support plane's normal),
        ``"side"`` (within 30 degrees of parallel to the plane) or ``"tilted"``.
    """

    T_world_grasp: np.ndarray
    width: float
    score: float
    approach: str

    def to_dict(self) -> dict:
        """The JSON of one grasp in DESIGN.md §3."""
        return {"T_world_grasp": [[float(v) for v in row] for row in self.T_world_grasp],
                "width": float(self.width), "score": round(float(self.score), 4)}


def grasps_to_json(grasps) -> list[dict]:
    """The ``"grasps"`` list of DESIGN.md §3, best first."""
    return [grasp.to_dict() for grasp in grasps]
