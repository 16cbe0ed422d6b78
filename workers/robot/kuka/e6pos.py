"""KUKA's E6POS and E6AXIS: conversion to and from the 4x4 base-frame poses robocell uses, and KRL text.

Pure functions, no I/O. KUKA gives a pose as X, Y, Z in millimetres and A, B, C
in degrees, rotations about Z, Y and X: ``R = Rz(A) @ Ry(B) @ Rx(C)``. robocell
uses 4x4 rigid transforms in metres (``T[:3, :3] = R``, ``T[:3, 3] = [X, Y, Z] / 1000``).

At B = +-90 degrees (gimbal lock) only A - C (B = +90) or A + C (B = -90) is
defined; :func:`abc_from_rotation` then returns C = 0 and puts the whole turn into A.

KukaVarProxy and OPC servers return structures as KRL aggregate text, e.g.
``{E6POS: X 1.0, Y 2.0, Z 3.0, A 0.0, B 90.0, C 0.0, S 2, T 35, E1 0.0, ...}``;
:func:`parse_e6pos` and :func:`parse_e6axis` read it, tolerant of spacing, case,
a missing type name, exponents and KRL bit literals (``S 'B010'``).

Examples
--------
>>> pose = pose_from_e6pos(E6Pos(500.0, 0.0, 600.0, 0.0, 0.0, 180.0))  # the flange looks down
>>> pose[:3, 3].tolist(), np.round(np.diag(pose[:3, :3]), 12).tolist()
([0.5, 0.0, 0.6], [1.0, -1.0, -1.0])
>>> format_e6pos(e6pos_from_pose(pose))
'{E6POS: X 500, Y 0, Z 600, A 0, B 0, C 180}'
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from robocell.core_cy.rigid import rigid_error

__all__ = [
    "E6Pos", "E6Axis", "rotation_from_abc", "abc_from_rotation", "e6pos_from_pose", "pose_from_e6pos",
    "format_e6pos", "parse_krl_struct", "parse_e6pos", "parse_e6axis",
]

# Below this, cos(B) is taken as zero: the pose is in gimbal lock.
_GIMBAL_EPS = 1e-12
# How far from a rotation matrix a caller's matrix may be (rounding of several products).


@dataclass(frozen=True)
class E6Pos:
    """A KUKA Cartesian pose: millimetres, degrees; status S, turn T and external axes E1.. if known."""

    x: float
    y: float
    z: float
    a: float
    b: float
    c: float
    s: int | None = None
    t: int | None = None
    external: tuple[float, ...] = ()


@dataclass(frozen=True)
class E6Axis:
    """KUKA axis angles A1..A6 (degrees) and external axes E1.. if given."""

    axes: tuple[float, ...]
    external: tuple[float, ...] = ()


def _wrap(degrees: float) -> float:
    """An angle in (-180, 180], without negative zero."""
    wrapped = math.remainder(degrees, 360.0)
    if wrapped <= -180.0:
        wrapped += 360.0
    return wrapped + 0.0


def rotation_from_abc(a: float, b: float, c: float) -> np.ndarray:
    """The rotation matrix ``Rz(a) @ Ry(b) @ Rx(c)`` of KUKA angles in degrees, (3, 3) float64.

    Examples
    --------
    >>> np.round(rotation_from_abc(90, 0, 0) @ [1, 0, 0], 12).tolist()  # A turns x towards y
    [0.0, 1.0, 0.0]
    """
    ca, sa = math.cos(math.radians(a)), math.sin(math.radians(a))
    cb, sb = math.cos(math.radians(b)), math.sin(math.radians(b))
    cc, sc = math.cos(math.radians(c)), math.sin(math.radians(c))
    return np.array([
        [ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc],
        [sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc],
        [-sb, cb * sc, cb * cc],
    ])


def abc_from_rotation(rotation) -> tuple[float, float, float]:
    """KUKA angles (A, B, C) in degrees of a rotation matrix; A, C in (-180, 180], B in [-90, 90].

    In gimbal lock (B = +-90) C is 0.
    """
    r = np.asarray(rotation, dtype=np.float64)
    cos_b = math.hypot(r[0, 0], r[1, 0])
    b = math.atan2(-r[2, 0], cos_b)
    if cos_b > _GIMBAL_EPS:
        a = math.atan2(r[1, 0], r[0, 0])
        c = math.atan2(r[2, 1], r[2, 2])
    else:
        # R = Rz(A) Ry(+-90) Rx(C) depends on A -+ C only; with C = 0, r01 = -sin A and r11 = cos A.
        a, c = math.atan2(-r[0, 1], r[1, 1]), 0.0
    return _wrap(math.degrees(a)), _wrap(math.degrees(b)), _wrap(math.degrees(c))


def _check_pose(pose) -> np.ndarray:
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4):
        raise ValueError(f"a pose must be a 4x4 matrix, got shape {pose.shape}")
    if not np.all(np.isfinite(pose)):
        raise ValueError("the pose has a non-finite entry")
    problem = rigid_error(pose)
    if problem is not None:
        raise ValueError(f"the pose {problem}")
    return pose


def e6pos_from_pose(pose, *, s: int | None = None, t: int | None = None) -> E6Pos:
    """The E6POS (mm, degrees) of a 4x4 pose in metres.

    Raises
    ------
    ValueError
        If ``pose`` is not a finite 4x4 rigid transform.
    """
    pose = _check_pose(pose)
    a, b, c = abc_from_rotation(pose[:3, :3])
    x, y, z = (1000.0 * pose[:3, 3]).tolist()
    return E6Pos(x, y, z, a, b, c, s, t)


def pose_from_e6pos(position: E6Pos) -> np.ndarray:
    """The 4x4 pose (metres) of an E6POS (mm, degrees); S, T and external axes play no part."""
    pose = np.eye(4)
    pose[:3, :3] = rotation_from_abc(position.a, position.b, position.c)
    pose[:3, 3] = np.array([position.x, position.y, position.z]) / 1000.0
    return pose


def _number(value: float) -> str:
    # KRL REALs are 32-bit: micrometres and micro-degrees are more than they hold.
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def format_e6pos(position: E6Pos, type_name: str = "E6POS") -> str:
    """KRL aggregate text for an E6POS, with S and T only when they are set.

    Examples
    --------
    >>> format_e6pos(E6Pos(1.5, -2, 3, 0, 90, -0.0, s=2, t=35))
    '{E6POS: X 1.5, Y -2, Z 3, A 0, B 90, C 0, S 2, T 35}'
    """
    parts = [f"{name} {_number(getattr(position, name.lower()))}" for name in "XYZABC"]
    if position.s is not None:
        parts.append(f"S {position.s}")
    if position.t is not None:
        parts.append(f"T {position.t}")
    parts += [f"E{index} {_number(value)}" for index, value in enumerate(position.external, start=1)]
    return "{" + (f"{type_name}: " if type_name else "") + ", ".join(parts) + "}"


_STRUCT = re.compile(r"^\s*\{\s*(?:(?P<type>[A-Za-z_$][\w$]*)\s*:)?(?P<body>[^{}]*)\}\s*$")
_ITEM = re.compile(r"^\s*(?P<name>[A-Za-z_$][\w$]*)\s+(?P<value>\S+)\s*$")
_BITS = re.compile(r"^'B([01]+)'$", re.IGNORECASE)


def _value(text: str) -> float | int:
    bits = _BITS.match(text)
    if bits:
        return int(bits.group(1), 2)
    if re.fullmatch(r"[+-]?\d+", text):
        return int(text)
    return float(text)  # ValueError for anything else, "nan" and "inf" included below


def parse_krl_struct(text: str) -> tuple[str | None, dict[str, float | int]]:
    """The type name (or None) and the components of KRL aggregate text, names in upper case.

    Raises
    ------
    ValueError
        If the text is not a flat aggregate of numbers, or a number is not finite.

    Examples
    --------
    >>> parse_krl_struct("{e6pos: x 1.0,Y 2E1, S 'B010'}")
    ('E6POS', {'X': 1.0, 'Y': 20.0, 'S': 2})
    """
    match = _STRUCT.match(text or "")
    if not match:
        raise ValueError(f"not a KRL structure: {text!r}")
    values: dict[str, float | int] = {}
    body = match.group("body")
    for item in body.split(",") if body.strip() else []:
        found = _ITEM.match(item)
        if not found:
            raise ValueError(f"cannot read {item.strip()!r} in {text!r}")
        name = found.group("name").upper()
        try:
            value = _value(found.group("value"))
        except ValueError:
            raise ValueError(f"{name} is not a number in {text!r}") from None
        if not math.isfinite(value):
            raise ValueError(f"{name} is not finite in {text!r}")
        values[name] = value
    type_name = match.group("type")
    return (type_name.upper() if type_name else None), values


def _externals(values: dict[str, float | int]) -> tuple[float, ...]:
    external = []
    for index in range(1, 7):
        if f"E{index}" not in values:
            break
        external.append(float(values[f"E{index}"]))
    return tuple(external)


def parse_e6pos(text: str) -> E6Pos:
    """An E6POS (or POS, FRAME) from KRL text; X, Y, Z, A, B, C are required.

    Raises
    ------
    ValueError
        If the text is not an aggregate, or X, Y, Z, A, B or C is missing or not a number.
    """
    type_name, values = parse_krl_struct(text)
    missing = [name for name in "XYZABC" if name not in values]
    if missing:
        raise ValueError(f"{', '.join(missing)} missing in {type_name or 'pose'} {text!r}")
    s, t = values.get("S"), values.get("T")
    return E6Pos(*(float(values[name]) for name in "XYZABC"),
                 s=None if s is None else int(s), t=None if t is None else int(t), external=_externals(values))


def parse_e6axis(text: str) -> E6Axis:
    """An E6AXIS (or AXIS) from KRL text; A1..A6 are required.

    Raises
    ------
    ValueError
        If the text is not an aggregate, or an axis is missing or not a number.
    """
    type_name, values = parse_krl_struct(text)
    names = [f"A{index}" for index in range(1, 7)]
    missing = [name for name in names if name not in values]
    if missing:
        raise ValueError(f"{', '.join(missing)} missing in {type_name or 'axis angles'} {text!r}")
    return E6Axis(tuple(float(values[name]) for name in names), _externals(values))
