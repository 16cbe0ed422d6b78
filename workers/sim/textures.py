"""Printed looks for simulated objects, and the textured tables they stand on.

A :class:`PrintedObject` is any :class:`~workers.sim.objects.SimObject` wearing
a :class:`Look`: a base colour and paints (bands, stripes, text-like rows,
discs, a checker, or the table's own pattern) laid on the surface in the
object's own frame, so that a point of the object has the same colour in every
view. Texture coordinates are a projection of the object-frame point: around
the object's z axis for round things (``"cylinder"``: u is arc length, v
height), onto the faces for boxes (``"box"``: the two coordinates across the
face the normal points out of).

Table patterns for the new table kinds (``oak``, ``rubber-mat``, ``laminate``,
``cutting-mat``) live here too, as :func:`table_pattern`;
:class:`workers.sim.render.TableScene` calls it. Every pattern is a pure
function of the table point (metres), so the table looks the same from every
view; fine detail fades with the pixel's footprint so that it does not alias.

Colours are BGR in [0, 1] (albedo), float32.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .objects import SimObject

__all__ = ["Band", "Checker", "Disc", "Look", "Paint", "PrintedObject", "Stripes", "TablePattern", "Text",
           "PRODUCT_LOOKS", "TABLE_KINDS", "hsv_bgr", "product_look", "table_look", "table_pattern"]

F32 = NDArray[np.float32]
#: Table kinds drawn by :func:`table_pattern` (``wood`` and ``fabric`` are the renderer's own).
TABLE_KINDS = ("oak", "rubber-mat", "laminate", "cutting-mat")


def hsv_bgr(h: float, s: float, v: float) -> tuple[float, float, float]:
    """BGR in [0, 1] of hue ``h`` in degrees (0-360), saturation and value in [0, 1].

    >>> hsv_bgr(0.0, 1.0, 1.0)
    (0.0, 0.0, 1.0)
    """
    h = (h % 360.0) / 60.0
    c = v * s
    x = c * (1 - abs(h % 2 - 1))
    r, g, b = [(c, x, 0), (x, c, 0), (0, c, x), (0, x, c), (x, 0, c), (c, 0, x)][int(h) % 6]
    m = v - c
    return (b + m, g + m, r + m)


# --- noise -------------------------------------------------------------------------------------

def _hash(ix: NDArray[np.int64], iy: NDArray[np.int64], seed: int) -> NDArray[np.float32]:
    """A uniform value in [0, 1) per integer lattice point (a wrapping integer hash)."""
    h = (ix.astype(np.uint32) * np.uint32(374761393)) ^ (iy.astype(np.uint32) * np.uint32(668265263))
    h = h ^ np.uint32((seed * 2246822519 + 12345) % 2**32)
    h = (h ^ (h >> np.uint32(13))) * np.uint32(1274126177)
    h = h ^ (h >> np.uint32(16))
    return (h >> np.uint32(8)).astype(np.float32) * np.float32(1.0 / 2**24)


def value_noise(x: F32, y: F32, seed: int) -> F32:
    """Smooth noise in [0, 1], one lattice cell per unit of ``x`` and ``y``."""
    fx, fy = np.floor(x), np.floor(y)
    ix, iy = fx.astype(np.int64), fy.astype(np.int64)
    tx, ty = x - fx, y - fy
    tx, ty = tx * tx * (3 - 2 * tx), ty * ty * (3 - 2 * ty)
    a, b = _hash(ix, iy, seed), _hash(ix + 1, iy, seed)
    c, d = _hash(ix, iy + 1, seed), _hash(ix + 1, iy + 1, seed)
    return (a + (b - a) * tx) * (1 - ty) + (c + (d - c) * tx) * ty


def fbm(x: F32, y: F32, seed: int, octaves: int = 3) -> F32:
    """Fractal noise in about [-0.5, 0.5]: ``octaves`` of :func:`value_noise`, each twice as fine."""
    total = np.zeros_like(x)
    amplitude, norm = np.float32(1.0), 0.0
    for k in range(octaves):
        total += amplitude * (value_noise(x * 2**k, y * 2**k, seed + 31 * k) - 0.5)
        norm += float(amplitude)
        amplitude *= np.float32(0.5)
    return total / np.float32(norm)


def _line_coverage(coord: F32, period: float, width: float, footprint: F32) -> F32:
    """Share of a pixel (``footprint`` wide) covered by lines ``width`` wide every ``period``.

    An exact 1D box filter: thin lines grow faint instead of aliasing.
    """
    d = np.abs((coord / np.float32(period) + 0.5) % 1.0 - 0.5) * np.float32(period)
    half = np.float32(width / 2)
    fp = np.maximum(footprint, np.float32(1e-5))
    overlap = np.minimum(d + fp / 2, half) - np.maximum(d - fp / 2, -half)
    return np.clip(overlap / fp, 0, 1).astype(np.float32)


# --- tables ------------------------------------------------------------------------------------

# The oak's latewood across one growth ring (its phase in [0, 1)): none, rising, dark, fading into the
# next ring's earlywood. Its integral over the ring, tabulated finely, averages it over any span.
_RING_GRID = np.linspace(0.0, 1.0, 4097)
_LATEWOOD = np.interp(_RING_GRID, [0.0, 0.55, 0.75, 0.88, 1.0], [0.0, 0.0, 1.0, 1.0, 0.0])
_LATEWOOD_INTEGRAL = np.concatenate([[0.0], np.cumsum((_LATEWOOD[1:] + _LATEWOOD[:-1]) / 2 * np.diff(_RING_GRID))])


def _latewood_over(phase: F32, span: F32) -> F32:
    """The latewood's share averaged over ``span`` rings centred on ``phase`` (in rings): an exact box
    filter, so a pixel that spans several rings reads their mean instead of whichever it happens to hit."""
    def integral(x: NDArray[np.float64]) -> NDArray[np.float64]:
        whole = np.floor(x)
        return whole * _LATEWOOD_INTEGRAL[-1] + np.interp(x - whole, _RING_GRID, _LATEWOOD_INTEGRAL)

    x = phase.astype(np.float64)
    half = np.maximum(span.astype(np.float64), 1e-3) / 2  # a thousandth of a ring: a point sample
    return ((integral(x + half) - integral(x - half)) / (2 * half)).astype(np.float32)


def table_pattern(kind: str, base_bgr: ArrayLike, xy: F32, footprint: F32, grain_angle: float,
                  phase: float) -> F32:
    """BGR albedo (N, 3) in the 0-255 scale of ``base_bgr`` at table points ``xy`` (N, 2), metres.

    ``footprint`` (N,) is a pixel's size on the table (metres); ``grain_angle`` turns
    the pattern; ``phase`` (any float) picks its instance.
    """
    seed = int(abs(phase) * 1000) % 100_003
    base = np.asarray(base_bgr, dtype=np.float32).reshape(1, 3)
    c, s = np.float32(np.cos(grain_angle)), np.float32(np.sin(grain_angle))
    along, across = xy[:, 0] * c + xy[:, 1] * s, xy[:, 1] * c - xy[:, 0] * s
    fade = 1.0 / (1.0 + (footprint / np.float32(0.0015)) ** 2)
    ones = np.ones((len(xy), 1), dtype=np.float32)
    if kind == "oak":
        # Boards 14 cm wide along the grain, each its own tone, sawn from a log: the growth rings are
        # cylinders round the log's pith, so a board shows them as lines that widen into arches where
        # the cut passes near the pith (cut depth wandering along the board). Latewood bands are darker
        # and redder; pores are short dark streaks along the grain; a dark seam between boards.
        width = np.float32(0.14)
        board = np.floor(across / width)
        in_board = across - board * width
        ib = board.astype(np.int64)
        zero = ib * 0
        pith = width * (1.6 * _hash(ib, zero + 1, seed) - 0.3)  # across the board, may lie outside it
        depth = (0.008 + 0.03 * _hash(ib, zero + 2, seed) + 0.012 * fbm(along / np.float32(0.5), board * 7.3, seed, 2)
                 + 0.004 * np.sin(along / np.float32(0.13) + 6.0 * _hash(ib, zero + 4, seed)))
        radius = np.sqrt((in_board - pith) ** 2 + depth**2)
        spacing = np.float32(0.0035) + np.float32(0.002) * _hash(ib, zero + 5, seed)
        phase = radius / spacing + 0.6 * fbm(radius / np.float32(0.012), board * 3.1, seed + 9, 2)
        # A pixel spans footprint * |grad radius| / spacing rings; the latewood is averaged over that span,
        # as a camera's pixel averages the light that falls on it, so that fine rings in a view low over
        # the table grow even instead of aliasing into moire bands. The radius grows across the board
        # (its growth along the board, with the cut's depth, is slow).
        rings_spanned = footprint * np.abs(in_board - pith) / np.maximum(radius, np.float32(1e-6)) / spacing
        late = _latewood_over(phase, rings_spanned)
        pores = np.clip((value_noise(along / np.float32(0.004), across / np.float32(0.0005), seed + 5) - 0.75) * 4,
                        0, 1)
        tone = 0.9 + 0.16 * _hash(ib, zero + 7, seed) + 0.05 * fbm(along / np.float32(0.3), across / np.float32(0.1),
                                                                    seed + 11, 2)
        seam = _line_coverage(across, float(width), 0.0012, footprint)
        shade = tone * (1.0 - 0.2 * late - 0.18 * fade * pores) * (1.0 - 0.55 * seam)
        warm = np.array([[0.85, 0.94, 1.0]], dtype=np.float32)  # latewood a little redder
        colour = base * (ones - (1 - warm) * late[:, None])
        return colour * shade[:, None]
    if kind == "rubber-mat":
        # A dark mat with a fine speckle of 1.5 mm grains and a soft mottle.
        speck = _hash(np.floor(xy[:, 0] / 0.0015).astype(np.int64), np.floor(xy[:, 1] / 0.0015).astype(np.int64),
                      seed) - 0.5
        mottle = fbm(xy[:, 0] / np.float32(0.2), xy[:, 1] / np.float32(0.2), seed, 2)
        shade = 1.0 + 0.35 * fade * speck + 0.25 * mottle
        return base * shade[:, None]
    if kind == "laminate":
        mottle = fbm(along / np.float32(0.15), across / np.float32(0.4), seed, 3)
        speck = value_noise(xy[:, 0] / np.float32(0.002), xy[:, 1] / np.float32(0.002), seed + 1) - 0.5
        shade = 1.0 + 0.05 * mottle + 0.02 * fade * speck
        return base * shade[:, None]
    if kind == "cutting-mat":
        # A green mat: pale lines every centimetre, bolder every five, a faint mottle.
        fine = np.maximum(_line_coverage(along, 0.01, 0.0004, footprint),
                          _line_coverage(across, 0.01, 0.0004, footprint))
        bold = np.maximum(_line_coverage(along, 0.05, 0.0009, footprint),
                          _line_coverage(across, 0.05, 0.0009, footprint))
        ink = np.maximum(0.8 * fine, bold)[:, None]
        line_colour = np.array([[0.75, 0.92, 0.85]], dtype=np.float32) * 255
        mottle = 1.0 + 0.06 * fbm(xy[:, 0] / np.float32(0.3), xy[:, 1] / np.float32(0.3), seed, 2)
        return (base * (1 - ink) + line_colour * ink) * mottle[:, None]
    raise ValueError(f"unknown table kind {kind!r}; known: {', '.join(TABLE_KINDS)}")


# --- printed objects ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Surface:
    """Texture coordinates of surface samples, the object frame's view of them.

    ``u``, ``v``: metres across the surface; ``height``: the object-frame z over the
    object's half-height, in [-1, 1]; ``side``: True off the caps (cylinder mapping) or
    on the four side faces (box mapping).
    """

    u: F32
    v: F32
    height: F32
    side: NDArray[np.bool_]


class Paint:
    """One layer of a :class:`Look`: where it paints and in what colour."""

    colour: tuple[float, float, float]

    def coverage(self, s: Surface) -> F32:  # pragma: no cover - the protocol
        raise NotImplementedError

    def apply(self, albedo: F32, s: Surface) -> None:
        a = self.coverage(s)[:, None]
        albedo *= 1 - a
        albedo += a * np.asarray(self.colour, dtype=np.float32)


@dataclass(frozen=True)
class Band(Paint):
    """A band round the side between heights ``lo`` and ``hi`` (fractions of the half-height, -1..1)."""

    lo: float
    hi: float
    colour: tuple[float, float, float]
    caps: bool = False  # paint the caps as well (a band from -1 to 1 with caps: the whole object)

    def coverage(self, s: Surface) -> F32:
        inside = (s.height >= self.lo) & (s.height <= self.hi)
        return (inside & (s.side | self.caps)).astype(np.float32)


@dataclass(frozen=True)
class Stripes(Paint):
    """Straight stripes ``period`` apart (metres), ``duty`` of it painted, at ``angle`` (radians)."""

    period: float
    duty: float
    colour: tuple[float, float, float]
    angle: float = 0.0
    lo: float = -1.0
    hi: float = 1.0

    def coverage(self, s: Surface) -> F32:
        t = s.u * np.float32(np.cos(self.angle)) + s.v * np.float32(np.sin(self.angle))
        on = ((t / np.float32(self.period)) % 1.0) < self.duty
        return (on & s.side & (s.height >= self.lo) & (s.height <= self.hi)).astype(np.float32)


@dataclass(frozen=True)
class Text(Paint):
    """Rows of text-like glyphs (3x5 cells of a hash) ``size`` high, between heights ``lo`` and ``hi``."""

    lo: float
    hi: float
    colour: tuple[float, float, float]
    size: float = 0.006
    seed: int = 0

    def coverage(self, s: Surface) -> F32:
        line = np.float32(1.6 * self.size)
        cell_w = np.float32(0.65 * self.size)
        col, row = np.floor(s.u / cell_w), np.floor(s.v / line)
        fu, fv = s.u / cell_w - col, (s.v / line - row) * np.float32(1.6)  # fv in glyph heights
        ic, ir = col.astype(np.int64), row.astype(np.int64)
        bits = (_hash(ic, ir, self.seed) * 2**20).astype(np.int64)
        word = _hash(ic // 5, ir, self.seed + 1) < 0.8  # ragged words: some cells are spaces
        gx = np.clip(((fu - 0.12) / 0.76 * 3).astype(np.int64), 0, 2)
        gy = np.clip(((fv - 0.3) / 1.0 * 5).astype(np.int64), 0, 4)
        in_glyph = (fu > 0.12) & (fu < 0.88) & (fv > 0.3) & (fv < 1.3)
        ink = ((bits >> (gx * 5 + gy)) & 1).astype(bool) & in_glyph & word & (bits % 7 != 0)
        return (ink & s.side & (s.height >= self.lo) & (s.height <= self.hi)).astype(np.float32)


@dataclass(frozen=True)
class Disc(Paint):
    """A round medallion of ``radius`` (metres) at arc position ``u`` and height ``height``."""

    u: float
    height: float
    radius: float
    colour: tuple[float, float, float]
    half_height: float = 1.0  # metres per unit of height, set by the look

    def coverage(self, s: Surface) -> F32:
        dv = (s.height - np.float32(self.height)) * np.float32(self.half_height)
        return (((s.u - self.u) ** 2 + dv**2 < self.radius**2) & s.side).astype(np.float32)


@dataclass(frozen=True)
class Checker(Paint):
    """A checkerboard of ``period`` (metres) squares over the whole surface."""

    period: float
    colour: tuple[float, float, float]

    def coverage(self, s: Surface) -> F32:
        k = np.floor(s.u / np.float32(self.period)) + np.floor(s.v / np.float32(self.period))
        return (k % 2 == 0).astype(np.float32)


@dataclass(frozen=True)
class TablePattern(Paint):
    """A table's own pattern over the whole object: an object the colour of its table.

    ``table`` is a :class:`workers.sim.render.TableScene` (anything with its ``table_colour``);
    the pattern is read at the texture coordinates shifted by ``offset`` (metres, the object's
    place on the table), so the object is as bright as the table round it.
    """

    table: Any
    offset: tuple[float, float] = (0.0, 0.0)
    colour: tuple[float, float, float] = (0.0, 0.0, 0.0)  # unused: the table gives the colour

    def apply(self, albedo: F32, s: Surface) -> None:
        # A different stretch of the pattern than the table's own round the object: u and v swapped.
        uv = np.column_stack([s.v + self.offset[0], s.u + self.offset[1]]).astype(np.float32)
        albedo[:] = self.table.table_colour(uv, np.full(len(uv), 5e-4, np.float32)) / 255


@dataclass(frozen=True)
class Look:
    """How an object is printed: a base colour, then each paint over the last.

    ``mapping`` picks the texture coordinates (see the module's docstring);
    ``gloss`` is the share of a white specular highlight (0: matte).
    """

    name: str
    base: tuple[float, float, float]
    paints: tuple[Paint, ...] = ()
    mapping: Literal["cylinder", "box"] = "cylinder"
    gloss: float = 0.1


class PrintedObject:
    """A :class:`SimObject` wearing a :class:`Look`; inside, mesh and truth are the object's own.

    ``T_world_texture`` (4x4, texture-to-world) fixes the print on the object; by default the
    object's ``T_world_object`` (a superquadric), else the centre of its bounding box with the world's
    axes. ``half_size`` (3,) scales heights; by default the superquadric's size, else half the box.
    """

    def __init__(self, obj: SimObject, look: Look, T_world_texture: ArrayLike | None = None,
                 half_size: ArrayLike | None = None) -> None:
        self.object = obj
        self.look = look
        vertices = obj.mesh()[0]
        if T_world_texture is None:
            T_world_texture = getattr(obj, "T_world_object", None)
        if T_world_texture is None:
            T_world_texture = np.eye(4)
            T_world_texture[:3, 3] = (vertices.min(0) + vertices.max(0)) / 2
        self.T_world_texture = np.asarray(T_world_texture, dtype=np.float64).reshape(4, 4)
        if half_size is None:
            R, t = self.T_world_texture[:3, :3], self.T_world_texture[:3, 3]
            local = (vertices - t) @ R
            half_size = np.abs(local).max(axis=0)
        self.half_size = np.asarray(half_size, dtype=np.float64).reshape(3)

    def inside(self, points_world: ArrayLike) -> NDArray[np.bool_]:
        return self.object.inside(points_world)

    def mesh(self) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
        return self.object.mesh()

    def truth(self) -> dict[str, Any]:
        return self.object.truth()

    def surface(self, points_world: NDArray[np.float64], normals_world: NDArray[np.float64]) -> Surface:
        """Texture coordinates of world points (N, 3) with their outward normals (N, 3)."""
        R, t = self.T_world_texture[:3, :3], self.T_world_texture[:3, 3]
        q = ((points_world - t) @ R).astype(np.float32)
        n = (normals_world @ R).astype(np.float32)
        a = self.half_size.astype(np.float32)
        height = np.clip(q[:, 2] / a[2], -1, 1)
        if self.look.mapping == "cylinder":
            side = np.abs(n[:, 2]) < 0.75
            radius = np.float32((a[0] + a[1]) / 2)
            u = np.where(side, np.arctan2(q[:, 1], q[:, 0]) * radius, q[:, 0])
            v = np.where(side, q[:, 2], q[:, 1])
        else:
            axis = np.argmax(np.abs(n), axis=1)
            side = axis != 2
            # Across each face: its horizontal coordinate (signed so that text reads left to right from
            # outside) and the height; on the top and bottom, x and y.
            sign = np.sign(np.take_along_axis(n, axis[:, None], 1)[:, 0])
            u = np.where(axis == 0, sign * q[:, 1], np.where(axis == 1, -sign * q[:, 0], q[:, 0]))
            v = np.where(side, q[:, 2], q[:, 1])
        return Surface(u.astype(np.float32), v.astype(np.float32), height.astype(np.float32), side)

    def albedo(self, points_world: NDArray[np.float64], normals_world: NDArray[np.float64]) -> F32:
        """BGR albedo in [0, 1], (N, 3) float32, of surface points (N, 3) with normals (N, 3)."""
        s = self.surface(points_world, normals_world)
        albedo = np.empty((len(s.u), 3), dtype=np.float32)
        albedo[:] = np.asarray(self.look.base, dtype=np.float32)
        for paint in self.look.paints:
            paint.apply(albedo, s)
        return albedo


# --- product looks -----------------------------------------------------------------------------

WHITE = (0.92, 0.93, 0.93)
SILVER = (0.72, 0.72, 0.70)


def _mustard(rng: np.random.Generator, half: float) -> Look:
    yellow = hsv_bgr(rng.uniform(46, 54), rng.uniform(0.85, 0.95), rng.uniform(0.85, 0.95))
    red = hsv_bgr(rng.uniform(355, 365), 0.85, 0.8)
    return Look("mustard", yellow, (
        Band(0.72, 1.0, red, caps=True),  # the cap
        Band(-0.55, 0.25, WHITE),  # the label
        Band(-0.35, 0.05, red),
        Text(-0.3, 0.0, WHITE, 0.007, int(rng.integers(1 << 30))),
        Text(-0.52, -0.38, (0.2, 0.25, 0.3), 0.004, int(rng.integers(1 << 30))),
    ), "cylinder", gloss=0.25)


def _sugar_box(rng: np.random.Generator, half: float) -> Look:
    blue = hsv_bgr(rng.uniform(205, 225), rng.uniform(0.7, 0.9), rng.uniform(0.55, 0.75))
    return Look("sugar-box", WHITE, (
        Band(-1.0, -0.35, blue),
        Stripes(0.03, 0.25, blue, angle=np.pi / 2, lo=0.55, hi=0.7),
        Text(-0.2, 0.45, blue, 0.008, int(rng.integers(1 << 30))),
        Text(-0.95, -0.45, WHITE, 0.005, int(rng.integers(1 << 30))),
    ), "box", gloss=0.05)


def _soup_can(rng: np.random.Generator, half: float) -> Look:
    red = hsv_bgr(rng.uniform(352, 362), rng.uniform(0.8, 0.9), rng.uniform(0.7, 0.8))
    gold = hsv_bgr(42, 0.7, 0.8)
    return Look("soup-can", WHITE, (
        Band(0.05, 1.0, red),
        Text(0.3, 0.8, WHITE, 0.009, int(rng.integers(1 << 30))),
        Disc(0.0, -0.15, 0.35 * half, gold, half_height=half),
        Text(-0.9, -0.5, red, 0.005, int(rng.integers(1 << 30))),
        Band(0.97, 1.0, SILVER),  # the rim
    ), "cylinder", gloss=0.2)


def _tin(rng: np.random.Generator, half: float) -> Look:
    blue = hsv_bgr(rng.uniform(215, 235), rng.uniform(0.75, 0.9), rng.uniform(0.45, 0.6))
    yellow = hsv_bgr(rng.uniform(48, 56), 0.85, 0.9)
    return Look("tin", blue, (
        Band(-0.3, 0.3, yellow),
        Text(-0.25, 0.25, blue, 0.006, int(rng.integers(1 << 30))),
        Stripes(0.012, 0.3, yellow, angle=0.0, lo=0.6, hi=0.9),
    ), "cylinder", gloss=0.3)


def _white(rng: np.random.Generator, half: float) -> Look:
    grey = (0.78, 0.79, 0.8)
    return Look("white", WHITE, (Text(-0.6, 0.6, grey, 0.006, int(rng.integers(1 << 30))),),
                "box", gloss=0.05)


def _dark(rng: np.random.Generator, half: float) -> Look:
    dark = hsv_bgr(rng.uniform(200, 240), 0.2, rng.uniform(0.08, 0.12))
    lighter = hsv_bgr(rng.uniform(200, 240), 0.25, rng.uniform(0.16, 0.22))
    return Look("dark", dark, (Stripes(0.02, 0.3, lighter, angle=0.3),), "cylinder", gloss=0.15)


def _printed(rng: np.random.Generator, half: float) -> Look:
    hue = rng.uniform(0, 360)
    base = hsv_bgr(hue, rng.uniform(0.4, 0.9), rng.uniform(0.5, 0.9))
    other = hsv_bgr(hue + rng.uniform(90, 270), rng.uniform(0.5, 0.9), rng.uniform(0.3, 0.95))
    paints: list[Paint] = [Stripes(rng.uniform(0.01, 0.03), rng.uniform(0.2, 0.5), other,
                                   angle=rng.uniform(0, np.pi))]
    if rng.random() < 0.5:
        paints.append(Band(-0.3, 0.3, WHITE))
        paints.append(Text(-0.25, 0.25, other, 0.006, int(rng.integers(1 << 30))))
    else:
        paints.append(Checker(rng.uniform(0.01, 0.02), WHITE))
        paints.append(Band(-0.2, 0.2, other))
    return Look("printed", base, tuple(paints), "box", gloss=0.1)


#: Product looks by name: each draws a look from a generator and the object's half-height (metres).
PRODUCT_LOOKS = {
    "mustard": _mustard,
    "sugar-box": _sugar_box,
    "soup-can": _soup_can,
    "tin": _tin,
    "white": _white,
    "dark": _dark,
    "printed": _printed,
}


def product_look(name: str, rng: np.random.Generator, half_height: float = 0.05) -> Look:
    """The look ``name`` of :data:`PRODUCT_LOOKS`, drawn from ``rng``.

    Raises
    ------
    ValueError
        If no such look exists.
    """
    try:
        return PRODUCT_LOOKS[name](rng, half_height)
    except KeyError:
        raise ValueError(f"unknown look {name!r}; known: {', '.join(PRODUCT_LOOKS)}") from None


def table_look(table: Any, offset: tuple[float, float]) -> Look:
    """A look with the pattern of ``table`` (a TableScene): an object the colour of the table."""
    return Look("table-colour", (0.5, 0.5, 0.5), (TablePattern(table, offset),), "cylinder", gloss=0.05)
