"""Known objects for simulated scans: superquadrics, a cup stack, a lumpy figure.

Every object lives in world coordinates (metres, z up, the table is z = 0) and
offers the same three things (:class:`SimObject`): an inside test for
volumetric scoring, a closed triangle mesh for rendering, and a JSON-able
ground truth.

Superquadric and lumpy meshes are built by pushing a grid on the unit cube's
surface radially onto the object (both are star-shaped about their centre).
The grid is denser towards the cube's edges, which is where a box-like
superquadric bends, so the same grid serves boxes and ellipsoids. Objects are
meant to be immutable: each caches its mesh.
"""
from __future__ import annotations

from typing import Any, Protocol, Sequence, runtime_checkable

import numpy as np

from robocell.core_cy.meshes import vertex_normals  # noqa: F401  (the one; renderers import it from here too)
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "COMPOUNDS",
    "COMPOUND_KINDS",
    "EVERYDAY",
    "FAMILIES",
    "CompoundObject",
    "CupStack",
    "LumpyFigure",
    "SimObject",
    "SuperquadricObject",
    "YCB_LIKE",
    "box",
    "compound",
    "cylinder",
    "ellipsoid",
    "rotation_z",
    "rounded_box",
    "vertex_normals",
]

Mesh = tuple[NDArray[np.float64], NDArray[np.int32]]

#: Shape exponents (e1, e2) of the superquadric families.
FAMILIES: dict[str, tuple[float, float]] = {
    "box": (0.1, 0.1),
    "cylinder": (0.1, 1.0),
    "ellipsoid": (1.0, 1.0),
    "rounded-box": (0.4, 0.4),
}

# A quarter turn about the object's x axis, written out exactly so that a lying
# object's lowest point lands on z = 0 without a cos(pi/2) = 6e-17 residue.
_LYING = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@runtime_checkable
class SimObject(Protocol):
    """What the renderer and the scorer need from a known object."""

    def inside(self, points_world: ArrayLike) -> NDArray[np.bool_]:
        """(N, 3) world points -> (N,) bool, True inside the object."""
        ...

    def mesh(self) -> Mesh:
        """Closed, outward-oriented mesh: vertices (V, 3) float64 world, faces (F, 3) int32."""
        ...

    def truth(self) -> dict[str, Any]:
        """JSON-able ground truth, with a ``"kind"`` key."""
        ...


def rotation_z(yaw_deg: float) -> NDArray[np.float64]:
    """(3, 3) rotation about the world z axis by ``yaw_deg`` degrees."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _cube_grid(n: int = 32) -> Mesh:
    """Unit-cube surface grid: points (V, 3) on max|c| = 1, faces (F, 3) outward.

    ``n`` cells per face edge (even, so face centres are vertices). Spacing is
    sin-shaped, denser near the cube's edges; vertices on shared edges are
    merged, so the mesh is closed.
    """
    m = n // 2
    half = np.sin(0.5 * np.pi * np.arange(m + 1) / m)
    t = np.concatenate([-half[::-1], half[1:]])  # exactly symmetric, contains 0 and +-1
    u, v = np.meshgrid(t, t, indexing="ij")
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    tri = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    pts, faces = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            p = np.empty(((n + 1) ** 2, 3))
            p[:, axis] = sign
            p[:, (axis + 1) % 3] = u.ravel()
            p[:, (axis + 2) % 3] = v.ravel()
            faces.append(tri + sum(len(q) for q in pts))
            pts.append(p)
    all_pts = np.concatenate(pts)
    uniq, inverse = np.unique(np.round(all_pts, 12), axis=0, return_inverse=True)
    f = inverse.reshape(-1)[np.concatenate(faces)]
    # Orient every triangle away from the origin (the cube is star-shaped about it).
    tv = uniq[f]
    normal = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])
    flip = np.einsum("ij,ij->i", normal, tv.sum(axis=1)) < 0
    f[flip] = f[flip][:, ::-1]
    return uniq, f.astype(np.int32)


class SuperquadricObject:
    """A superquadric with half-sizes ``size`` (a1, a2, a3), exponents ``shape`` (e1, e2).

    Parameters
    ----------
    size : (3,) array_like of float
        Half-sizes a1, a2, a3 along the object's x, y, z axes (metres).
    shape : (2,) array_like of float
        Exponents e1 (z profile), e2 (xy cross-section), each in (0, 2).
    T_world_object : (4, 4) array_like of float
        Object-to-world rigid transform.

    Examples
    --------
    >>> box = SuperquadricObject.on_table("box", [0.05, 0.03, 0.02], (0.6, 0.0))
    >>> float(box.mesh()[0][:, 2].min())
    0.0
    """

    def __init__(self, size: ArrayLike, shape: ArrayLike, T_world_object: ArrayLike) -> None:
        self.size = np.asarray(size, dtype=np.float64).reshape(3)
        self.shape = np.asarray(shape, dtype=np.float64).reshape(2)
        self.T_world_object = np.asarray(T_world_object, dtype=np.float64).reshape(4, 4)
        if np.any(self.size <= 0):
            raise ValueError(f"size must be positive, got {self.size.tolist()}")
        if np.any(self.shape <= 0) or np.any(self.shape >= 2):
            raise ValueError(f"shape exponents must lie in (0, 2), got {self.shape.tolist()}")
        self._mesh: Mesh | None = None

    @classmethod
    def on_table(
        cls,
        family: str | Sequence[float],
        size: ArrayLike,
        position_xy: ArrayLike,
        yaw_deg: float = 0.0,
        lying: bool = False,
    ) -> SuperquadricObject:
        """Stand a superquadric on the table, its lowest point exactly at z = 0.

        ``family`` is a key of :data:`FAMILIES` or an (e1, e2) pair. Upright, the
        object's z axis points up; ``lying`` first turns it a quarter turn about
        its own x axis (its z axis then lies horizontal, its y axis points up),
        then ``yaw_deg`` turns it about the world z axis.
        """
        shape = FAMILIES[family] if isinstance(family, str) else family
        R = rotation_z(yaw_deg) @ (_LYING if lying else np.eye(3))
        T = np.eye(4)
        T[:3, :3] = R
        T[:2, 3] = np.asarray(position_xy, dtype=np.float64).reshape(2)
        # Lowest world z of the body = t_z - h(R^T e_z), h the support function.
        T[2, 3] = cls(size, shape, np.eye(4)).support(R[2])
        return cls(size, shape, T)

    def support(self, direction_object: ArrayLike) -> float:
        """max over the body of ``direction . p``, p in the object frame.

        The gauge of a superquadric is a nested norm,
        ``||(||(x/a1, y/a2)||_p, |z/a3|)||_q`` with p = 2/e2, q = 2/e1, so its
        support function is the nested dual norm with exponents p/(p-1), q/(q-1)
        applied to (a1 n1, a2 n2, a3 n3). Exact, no sampling.
        """
        u = np.abs(np.asarray(direction_object, dtype=np.float64) * self.size)
        e1, e2 = self.shape
        ps, qs = 2.0 / (2.0 - e2), 2.0 / (2.0 - e1)
        inner = (u[0] ** ps + u[1] ** ps) ** (1.0 / ps)
        return float((inner**qs + u[2] ** qs) ** (1.0 / qs))

    def _F(self, p: NDArray[np.float64]) -> NDArray[np.float64]:
        """Inside-outside function of (N, 3) object-frame points."""
        e1, e2 = self.shape
        q = np.abs(p) / self.size
        with np.errstate(over="ignore"):  # far points overflow to inf: still outside
            xy = q[:, 0] ** (2.0 / e2) + q[:, 1] ** (2.0 / e2)
            return xy ** (e2 / e1) + q[:, 2] ** (2.0 / e1)

    def inside(self, points_world: ArrayLike) -> NDArray[np.bool_]:
        """(N, 3) world points -> (N,) bool, F <= 1 in the object frame."""
        P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        R, t = self.T_world_object[:3, :3], self.T_world_object[:3, 3]
        return self._F((P - t) @ R) <= 1.0

    def mesh(self) -> Mesh:
        """Closed mesh with every vertex exactly on the surface, (V, 3) and (F, 3)."""
        if self._mesh is None:
            cube, faces = _cube_grid()
            d = cube * self.size
            # F is homogeneous of degree 2/e1 under scaling, so F(s d) = 1 at s = F(d)^(-e1/2).
            s = self._F(d) ** (-self.shape[0] / 2.0)
            p = d * s[:, None]
            R, t = self.T_world_object[:3, :3], self.T_world_object[:3, 3]
            self._mesh = (p @ R.T + t, faces)
        return self._mesh

    def truth(self) -> dict[str, Any]:
        return {
            "kind": "superquadric",
            "size": self.size.tolist(),
            "shape": self.shape.tolist(),
            "T_world_object": self.T_world_object.tolist(),
        }


def box(
    size: ArrayLike, position_xy: ArrayLike, yaw_deg: float = 0.0, lying: bool = False
) -> SuperquadricObject:
    """A box (e1 = e2 = 0.1) on the table, see :meth:`SuperquadricObject.on_table`."""
    return SuperquadricObject.on_table("box", size, position_xy, yaw_deg, lying)


def cylinder(
    size: ArrayLike, position_xy: ArrayLike, yaw_deg: float = 0.0, lying: bool = False
) -> SuperquadricObject:
    """A cylinder along the object's z axis (e1 = 0.1, e2 = 1) on the table."""
    return SuperquadricObject.on_table("cylinder", size, position_xy, yaw_deg, lying)


def ellipsoid(
    size: ArrayLike, position_xy: ArrayLike, yaw_deg: float = 0.0, lying: bool = False
) -> SuperquadricObject:
    """An ellipsoid (e1 = e2 = 1) on the table."""
    return SuperquadricObject.on_table("ellipsoid", size, position_xy, yaw_deg, lying)


def rounded_box(
    size: ArrayLike, position_xy: ArrayLike, yaw_deg: float = 0.0, lying: bool = False
) -> SuperquadricObject:
    """A box with rounded edges (e1 = e2 = 0.4) on the table."""
    return SuperquadricObject.on_table("rounded-box", size, position_xy, yaw_deg, lying)


def _bbox_truth(mesh: Mesh) -> dict[str, list[float]]:
    v = mesh[0]
    return {"bbox_min": v.min(axis=0).tolist(), "bbox_max": v.max(axis=0).tolist()}


class CupStack:
    """Two solid truncated-cone cups stacked on the table at ``position_xy``.

    The lower cup stands upright (narrow end down). The upper one is either
    inverted, rim on rim (``top_inverted=True``), or upright and nested in the
    lower one, its base ``nest_offset`` above the lower cup's base.
    """

    def __init__(
        self,
        position_xy: ArrayLike,
        bottom_radius: float = 0.025,
        top_radius: float = 0.038,
        height: float = 0.06,
        top_inverted: bool = True,
        nest_offset: float = 0.02,
    ) -> None:
        if not 0 < bottom_radius <= top_radius or height <= 0:
            raise ValueError("need 0 < bottom_radius <= top_radius and height > 0")
        self.position_xy = np.asarray(position_xy, dtype=np.float64).reshape(2)
        self.rb, self.rt, self.h = float(bottom_radius), float(top_radius), float(height)
        self.top_inverted = bool(top_inverted)
        self.nest_offset = float(nest_offset)
        # Each cup: (z of its base, +1 for opening upwards, -1 for inverted).
        top = (2 * self.h, -1.0) if self.top_inverted else (self.nest_offset, 1.0)
        self._cups = [(0.0, 1.0), top]
        self._mesh: Mesh | None = None

    def _cup_radius(self, z: NDArray[np.float64], base: float, up: float) -> NDArray[np.float64]:
        """Radius at height z (NaN outside the cup's height range)."""
        s = (z - base) * up / self.h  # 0 at the narrow end, 1 at the rim
        return np.where((s >= 0) & (s <= 1), self.rb + (self.rt - self.rb) * s, np.nan)

    def inside(self, points_world: ArrayLike) -> NDArray[np.bool_]:
        P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        r = np.linalg.norm(P[:, :2] - self.position_xy, axis=1)
        out = np.zeros(len(P), dtype=bool)
        for base, up in self._cups:
            out |= r <= np.nan_to_num(self._cup_radius(P[:, 2], base, up), nan=-1.0)
        return out

    def level(self, points_world: ArrayLike) -> NDArray[np.float64]:
        """A level function of the stack: at most 1 exactly where :meth:`inside` holds, continuous,
        growing outwards (its gradient on the surface is the outward normal's direction). Per cup:
        the larger of the radius over the cup's radius at that height and how far along the cup's
        axis from its middle (1 at both ends); the stack's is the smaller of its cups'."""
        P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        r = np.linalg.norm(P[:, :2] - self.position_xy, axis=1)
        out = np.full(len(P), np.inf)
        for base, up in self._cups:
            s = (P[:, 2] - base) * up / self.h
            radius = np.maximum(self.rb + (self.rt - self.rb) * s, 1e-9)
            out = np.minimum(out, np.maximum(r / radius, np.abs(2 * s - 1)))
        return out

    @classmethod
    def from_truth(cls, truth: dict[str, Any]) -> CupStack:
        """The stack a :meth:`truth` describes."""
        return cls(truth["position_xy"], truth["bottom_radius"], truth["top_radius"], truth["height"],
                   truth["top_inverted"], truth["nest_offset"])

    def _cone(self, base: float, up: float, n_seg: int = 72, n_rings: int = 8) -> Mesh:
        """One closed cup: a side of ``n_rings`` rings plus two flat caps.

        The caps get their own rim vertices so that smooth vertex normals do not
        round the cups' sharp rims.
        """
        ang = 2 * np.pi * np.arange(n_seg) / n_seg
        ring = np.stack([np.cos(ang), np.sin(ang)], 1)
        s = np.linspace(0.0, 1.0, n_rings + 1)
        z = base + up * self.h * s
        r = self.rb + (self.rt - self.rb) * s
        side = np.concatenate([np.column_stack([ring * ri, np.full(n_seg, zi)]) for ri, zi in zip(r, z)])
        i, j = np.meshgrid(np.arange(n_rings), np.arange(n_seg), indexing="ij")
        a, b = i * n_seg + j, i * n_seg + (j + 1) % n_seg
        faces = [np.stack([a, b, b + n_seg], -1).reshape(-1, 3), np.stack([a, b + n_seg, a + n_seg], -1).reshape(-1, 3)]
        verts = [side]
        for k in (0, n_rings):  # caps at both ends
            start = sum(len(v) for v in verts)
            cap = np.vstack([np.column_stack([ring * r[k], np.full(n_seg, z[k])]), [[0.0, 0.0, z[k]]]])
            jj = np.arange(n_seg)
            faces.append(np.stack([jj, (jj + 1) % n_seg, np.full(n_seg, n_seg)], -1) + start)
            verts.append(cap)
        v = np.concatenate(verts)
        f = np.concatenate(faces)
        # Orient outward: away from the cup's axis point at the face's height.
        tv = v[f]
        normal = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])
        centre = np.array([0.0, 0.0, base + up * self.h / 2])
        flip = np.einsum("ij,ij->i", normal, tv.mean(axis=1) - centre) < 0
        f[flip] = f[flip][:, ::-1]
        v[:, :2] += self.position_xy
        return v, f.astype(np.int32)

    def mesh(self) -> Mesh:
        """Both cups' closed meshes in one array pair (they overlap where they touch)."""
        if self._mesh is None:
            (v0, f0), (v1, f1) = (self._cone(base, up) for base, up in self._cups)
            self._mesh = (np.vstack([v0, v1]), np.vstack([f0, f1 + len(v0)]).astype(np.int32))
        return self._mesh

    def truth(self) -> dict[str, Any]:
        return {
            "kind": "cup-stack",
            "position_xy": self.position_xy.tolist(),
            "bottom_radius": self.rb,
            "top_radius": self.rt,
            "height": self.h,
            "top_inverted": self.top_inverted,
            "nest_offset": self.nest_offset,
            **_bbox_truth(self.mesh()),
        }


class LumpyFigure:
    """An irregular blob on the table: an ellipsoid with a smooth random radius.

    In direction d from its centre the surface lies at
    ``r(d) = r_ellipsoid(d) * exp(amplitude * f(d))``, f a sum of ``n_waves``
    random plane waves of low frequency drawn from ``seed``, scaled to unit
    standard deviation (exp keeps the radius positive, so the blob stays
    star-shaped). The centre sits at 0.7 of the downward radius above the table
    and everything below z = 0 is cut off, which leaves a flat base.
    """

    def __init__(
        self,
        position_xy: ArrayLike,
        radii: ArrayLike = (0.05, 0.04, 0.045),
        seed: int = 0,
        amplitude: float = 0.2,
        n_waves: int = 6,
    ) -> None:
        self.radii = np.asarray(radii, dtype=np.float64).reshape(3)
        self.seed, self.amplitude = int(seed), float(amplitude)
        rng = np.random.default_rng(self.seed)
        g = rng.normal(size=(n_waves, 3))
        self._dirs = g / np.linalg.norm(g, axis=1, keepdims=True)
        self._freq = rng.uniform(2.5, 5.0, n_waves)
        self._phase = rng.uniform(0, 2 * np.pi, n_waves)
        self._weight = rng.uniform(0.5, 1.0, n_waves)
        down = float(self._radius(np.array([[0.0, 0.0, -1.0]]))[0])
        self.centre = np.array([*np.asarray(position_xy, dtype=np.float64).reshape(2), 0.7 * down])
        self._mesh: Mesh | None = None

    def _radius(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        """Surface distance from the centre along (N, 3) unit directions."""
        r_ell = 1.0 / np.sqrt(((d / self.radii) ** 2).sum(axis=1))
        # Each wave has variance w^2 / 2: divide by the sum's standard deviation.
        f = np.sin(self._freq * (d @ self._dirs.T) + self._phase) @ self._weight
        return r_ell * np.exp(self.amplitude * f / np.sqrt((self._weight**2).sum() / 2))

    def inside(self, points_world: ArrayLike) -> NDArray[np.bool_]:
        P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        q = P - self.centre
        dist = np.linalg.norm(q, axis=1)
        d = q / np.where(dist > 0, dist, 1.0)[:, None]
        return (dist <= self._radius(d)) & (P[:, 2] >= 0.0)

    def level(self, points_world: ArrayLike) -> NDArray[np.float64]:
        """A level function of the figure: at most 1 exactly where :meth:`inside` holds, continuous,
        growing outwards: the larger of the distance from the centre over the surface's in that
        direction, and the depth below the table over the centre's height (plus 1)."""
        P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        q = P - self.centre
        dist = np.linalg.norm(q, axis=1)
        d = q / np.where(dist > 0, dist, 1.0)[:, None]
        return np.maximum(dist / self._radius(d), 1.0 - P[:, 2] / self.centre[2])

    @classmethod
    def from_truth(cls, truth: dict[str, Any]) -> LumpyFigure:
        """The figure a :meth:`truth` describes (its waves follow from its seed)."""
        return cls(truth["centre"][:2], truth["radii"], truth["seed"], truth["amplitude"])

    def mesh(self) -> Mesh:
        if self._mesh is None:
            cube, faces = _cube_grid()
            d = cube / np.linalg.norm(cube, axis=1, keepdims=True)
            v = self.centre + d * self._radius(d)[:, None]
            v[:, 2] = np.maximum(v[:, 2], 0.0)  # the flat base
            self._mesh = (v, faces)
        return self._mesh

    def truth(self) -> dict[str, Any]:
        return {
            "kind": "lumpy",
            "centre": self.centre.tolist(),
            "radii": self.radii.tolist(),
            "seed": self.seed,
            "amplitude": self.amplitude,
            **_bbox_truth(self.mesh()),
        }


class CompoundObject:
    """A union of superquadric parts, one rigid object (a mug and its handle, say).

    The parts may overlap; their meshes are drawn together (the z-buffer keeps
    what is in front) and ``truth()`` lists them as DESIGN.md §3's ``parts``.
    """

    def __init__(self, name: str, parts: Sequence[SuperquadricObject]) -> None:
        if not parts:
            raise ValueError("a compound object needs at least one part")
        self.name = str(name)
        self.parts = tuple(parts)
        self._mesh: Mesh | None = None

    def inside(self, points_world: ArrayLike) -> NDArray[np.bool_]:
        P = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        out = np.zeros(len(P), dtype=bool)
        for part in self.parts:
            out |= part.inside(P)
        return out

    def mesh(self) -> Mesh:
        if self._mesh is None:
            vertices, faces, offset = [], [], 0
            for part in self.parts:
                v, f = part.mesh()
                vertices.append(v)
                faces.append(f + offset)
                offset += len(v)
            self._mesh = (np.vstack(vertices), np.vstack(faces).astype(np.int32))
        return self._mesh

    def truth(self) -> dict[str, Any]:
        parts = [{key: part.truth()[key] for key in ("size", "shape", "T_world_object")} for part in self.parts]
        return {"kind": "compound", "name": self.name, "parts": parts, **_bbox_truth(self.mesh())}


def _placed(family: str | Sequence[float], size: ArrayLike, R: ArrayLike, centre: ArrayLike) -> SuperquadricObject:
    shape = FAMILIES[family] if isinstance(family, str) else family
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, centre
    return SuperquadricObject(size, shape, T)


def _cup_stack(rng: np.random.Generator) -> list[tuple]:
    """Two cups (short cylinders), the upper one a little narrower or wider, standing on the lower."""
    r1, h1 = rng.uniform(0.022, 0.037), rng.uniform(0.025, 0.04)
    r2, h2 = float(np.clip(r1 + rng.uniform(-0.008, 0.008), 0.018, 0.038)), rng.uniform(0.02, 0.035)
    return [("cylinder", (r1, r1, h1), np.eye(3), (0.0, 0.0, h1)),
            ("cylinder", (r2, r2, h2), np.eye(3), (0.0, 0.0, 2 * h1 + h2 - 0.002))]


def _mug(rng: np.random.Generator) -> list[tuple]:
    """A cylinder with a C-shaped handle of three bars on one side."""
    r, h = rng.uniform(0.025, 0.036), rng.uniform(0.035, 0.05)
    reach, bar = rng.uniform(0.018, 0.028), rng.uniform(0.004, 0.006)
    span = rng.uniform(0.45, 0.7) * h  # half the handle's height
    wide = rng.uniform(0.005, 0.008)  # half the handle's width (tangential)
    z0 = h
    out_x = r + reach - bar
    return [("cylinder", (r, r, h), np.eye(3), (0.0, 0.0, z0)),
            ("rounded-box", ((reach + 0.004) / 2, wide, bar), np.eye(3), (r + (reach - 0.004) / 2, 0.0, z0 + span)),
            ("rounded-box", ((reach + 0.004) / 2, wide, bar), np.eye(3), (r + (reach - 0.004) / 2, 0.0, z0 - span)),
            ("rounded-box", (bar, wide, span + bar), np.eye(3), (out_x, 0.0, z0))]


def _box_and_ball(rng: np.random.Generator) -> list[tuple]:
    """A lying box with a ball resting on its top, sunk 2 mm into it so that the two are one body."""
    a = (rng.uniform(0.03, 0.06), rng.uniform(0.015, 0.035), rng.uniform(0.012, 0.03))
    ball = rng.uniform(0.012, min(0.03, a[1] + 0.01))
    offset = rng.uniform(-0.5, 0.5) * (a[0] - ball)
    return [("box", a, np.eye(3), (0.0, 0.0, a[2])),
            ("ellipsoid", (ball, ball, ball), np.eye(3), (offset, 0.0, 2 * a[2] + ball - 0.002))]


def _l_of_boxes(rng: np.random.Generator) -> list[tuple]:
    """Two boxes in an L: a lying bar, and an upright block standing on one of its ends."""
    bar = (rng.uniform(0.04, 0.07), rng.uniform(0.012, 0.03), rng.uniform(0.01, 0.02))
    post = (rng.uniform(0.012, 0.025), bar[1], rng.uniform(0.025, 0.05))
    x = bar[0] - post[0]
    return [("box", bar, np.eye(3), (0.0, 0.0, bar[2])),
            ("box", post, np.eye(3), (x, 0.0, 2 * bar[2] + post[2] - 0.002))]


#: Compound objects: name -> a function drawing its parts (family, size, R, centre in its own frame).
#: These four make the grasp benchmark's compound scenes (workers.sim.grasp_set), which stay as they are.
COMPOUNDS = {"cups": _cup_stack, "mug": _mug, "box-and-ball": _box_and_ball, "l-boxes": _l_of_boxes}

# A part lying along the object's x axis (its own z axis turned onto x), or along y: exact, no cos residue.
_ALONG_X = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
_ALONG_Y = _LYING
# Parts that touch are sunk this far into each other, so that their union is one body.
_SINK = 0.002


def _bottle(rng: np.random.Generator) -> list[tuple]:
    """A round body, a domed shoulder (the upper half of a flattened ellipsoid) and a narrow neck."""
    r, h = rng.uniform(0.025, 0.035), rng.uniform(0.035, 0.055)
    shoulder = rng.uniform(0.4, 0.6) * r
    neck_r, neck_h = rng.uniform(0.008, 0.013), rng.uniform(0.012, 0.022)
    neck_base = 2 * h + shoulder * np.sqrt(1 - (neck_r / r) ** 2) - _SINK
    return [("cylinder", (r, r, h), np.eye(3), (0.0, 0.0, h)),
            ("ellipsoid", (r, r, shoulder), np.eye(3), (0.0, 0.0, 2 * h)),
            ("cylinder", (neck_r, neck_r, neck_h), np.eye(3), (0.0, 0.0, neck_base + neck_h))]


def _dumbbell(rng: np.random.Generator) -> list[tuple]:
    """A bar lying along x between two round weights, all resting on the table."""
    weight_r, weight_w = rng.uniform(0.022, 0.032), rng.uniform(0.01, 0.018)
    bar_r, half_length = rng.uniform(0.007, 0.011), rng.uniform(0.045, 0.065)
    end = half_length - weight_w
    return [("cylinder", (bar_r, bar_r, half_length - _SINK), _ALONG_X, (0.0, 0.0, weight_r)),
            ("cylinder", (weight_r, weight_r, weight_w), _ALONG_X, (-end, 0.0, weight_r)),
            ("cylinder", (weight_r, weight_r, weight_w), _ALONG_X, (end, 0.0, weight_r))]


def _t_of_bars(rng: np.random.Generator) -> list[tuple]:
    """Two flat bars lying in a T: a stem along x, a cross bar along y across one of its ends."""
    thick = rng.uniform(0.008, 0.015)
    stem = (rng.uniform(0.04, 0.065), rng.uniform(0.01, 0.018), thick)
    cross = (rng.uniform(0.01, 0.018), rng.uniform(0.035, 0.06), thick)
    return [("box", stem, np.eye(3), (0.0, 0.0, thick)),
            ("box", cross, np.eye(3), (stem[0] + cross[0] - _SINK, 0.0, thick))]


def _offset_boxes(rng: np.random.Generator) -> list[tuple]:
    """Two boxes of different heights side by side on the table, one shifted along the other's side."""
    a = (rng.uniform(0.02, 0.04), rng.uniform(0.02, 0.04), rng.uniform(0.02, 0.045))
    b = (rng.uniform(0.015, 0.035), rng.uniform(0.015, 0.035), rng.uniform(0.012, 0.035))
    shift = rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 0.7) * min(a[1], b[1])
    return [("box", a, np.eye(3), (0.0, 0.0, a[2])),
            ("box", b, np.eye(3), (a[0] + b[0] - _SINK, shift, b[2]))]


def _stacked_boxes(rng: np.random.Generator) -> list[tuple]:
    """A smaller box standing on a larger one, off its centre."""
    a = (rng.uniform(0.03, 0.05), rng.uniform(0.025, 0.045), rng.uniform(0.012, 0.03))
    b = (rng.uniform(0.012, 0.7 * a[0]), rng.uniform(0.012, 0.7 * a[1]), rng.uniform(0.012, 0.03))
    dx, dy = (rng.uniform(-1, 1) * (a[0] - b[0]), rng.uniform(-1, 1) * (a[1] - b[1]))
    return [("box", a, np.eye(3), (0.0, 0.0, a[2])),
            ("box", b, np.eye(3), (dx, dy, 2 * a[2] + b[2] - _SINK))]


def _spray_bottle(rng: np.random.Generator) -> list[tuple]:
    """A rounded body, a head on it and a nozzle sticking out of the head to one side (+x)."""
    body = (rng.uniform(0.02, 0.03), rng.uniform(0.015, 0.025), rng.uniform(0.04, 0.06))
    head = (rng.uniform(0.012, 0.018), rng.uniform(0.01, 0.014), rng.uniform(0.012, 0.02))
    nozzle = (rng.uniform(0.01, 0.016), rng.uniform(0.004, 0.006), rng.uniform(0.004, 0.006))
    head_z = 2 * body[2] + head[2] - _SINK
    return [("rounded-box", body, np.eye(3), (0.0, 0.0, body[2])),
            ("box", head, np.eye(3), (0.0, 0.0, head_z)),
            ("box", nozzle, np.eye(3), (head[0] + nozzle[0] - _SINK, 0.0, head_z + head[2] - nozzle[2]))]


def _table_lamp(rng: np.random.Generator) -> list[tuple]:
    """A flat round base, a thin pole standing on it and a wide shade on top."""
    base_r, base_h = rng.uniform(0.03, 0.045), rng.uniform(0.004, 0.007)
    pole_r, pole_h = rng.uniform(0.004, 0.007), rng.uniform(0.025, 0.045)
    shade_r, shade_h = rng.uniform(0.03, 0.045), rng.uniform(0.015, 0.025)
    pole_z = 2 * base_h + pole_h - _SINK
    return [("cylinder", (base_r, base_r, base_h), np.eye(3), (0.0, 0.0, base_h)),
            ("cylinder", (pole_r, pole_r, pole_h), np.eye(3), (0.0, 0.0, pole_z)),
            ((0.3, 1.0), (shade_r, shade_r, shade_h), np.eye(3), (0.0, 0.0, pole_z + pole_h + shade_h - _SINK))]


def _box_and_can(rng: np.random.Generator) -> list[tuple]:
    """A lying box with a can lying on its top, across it (along y), off its centre."""
    a = (rng.uniform(0.035, 0.06), rng.uniform(0.03, 0.045), rng.uniform(0.012, 0.03))
    can_r, can_h = rng.uniform(0.014, 0.022), rng.uniform(0.025, 0.04)
    offset = rng.uniform(-0.5, 0.5) * (a[0] - can_r)
    return [("box", a, np.eye(3), (0.0, 0.0, a[2])),
            ("cylinder", (can_r, can_r, can_h), _ALONG_Y, (offset, 0.0, 2 * a[2] + can_r - _SINK))]


def _hammer(rng: np.random.Generator) -> list[tuple]:
    """A hammer lying on the table: a long handle along x, and a head across its end (along y)."""
    grip, half_length = rng.uniform(0.008, 0.012), rng.uniform(0.06, 0.08)
    head = (rng.uniform(0.012, 0.016), rng.uniform(0.03, 0.045), rng.uniform(0.012, 0.016))
    return [("rounded-box", (half_length, grip, grip), np.eye(3), (0.0, 0.0, grip)),
            ("box", head, np.eye(3), (half_length + head[0] - _SINK, 0.0, head[2]))]


#: Everyday compound objects (issue 21's ten, with stacked and offset boxes): the compound benchmark's.
EVERYDAY = {
    "bottle": _bottle, "mug": _mug, "dumbbell": _dumbbell, "t-bars": _t_of_bars, "offset-boxes": _offset_boxes,
    "spray-bottle": _spray_bottle, "lamp": _table_lamp, "box-and-can": _box_and_can, "l-boxes": _l_of_boxes,
    "hammer": _hammer, "stacked-boxes": _stacked_boxes,
}

# Products of the YCB object set (Calli et al. 2015) as unions of superquadrics, at their published
# sizes (full extents in mm in each docstring), standing or lying as they rest on a table; the sizes
# are fixed (a product has one size), only the pose is drawn.


def _mustard_bottle(rng: np.random.Generator) -> list[tuple]:
    """006 mustard bottle, 96 x 58 x 190: a flattened rounded body and its cap, a little off-centre."""
    body = (0.046, 0.029, 0.0775)
    return [("rounded-box", body, np.eye(3), (0.0, 0.0, body[2])),
            ("cylinder", (0.012, 0.012, 0.0175), np.eye(3), (0.012, 0.0, 2 * body[2] + 0.0175 - _SINK))]


def _bleach_bottle(rng: np.random.Generator) -> list[tuple]:
    """021 bleach cleanser, 98 x 65 x 250, as a jug: a rounded body, its cap to the front (+x) and
    a handle of three bars at the back of its upper half."""
    body = (0.049, 0.0325, 0.11)
    reach, bar, wide, span = 0.024, 0.006, 0.01, 0.03
    z = 2 * body[2] - span - 0.015
    return [("rounded-box", body, np.eye(3), (0.0, 0.0, body[2])),
            ("cylinder", (0.014, 0.014, 0.015), np.eye(3), (0.02, 0.0, 2 * body[2] + 0.015 - _SINK)),
            ("rounded-box", ((reach + 0.004) / 2, wide, bar), np.eye(3), (-body[0] - (reach - 0.004) / 2, 0.0, z + span)),
            ("rounded-box", ((reach + 0.004) / 2, wide, bar), np.eye(3), (-body[0] - (reach - 0.004) / 2, 0.0, z - span)),
            ("rounded-box", (bar, wide, span + bar), np.eye(3), (-body[0] - reach + bar, 0.0, z))]


def _cracker_box(rng: np.random.Generator) -> list[tuple]:
    """003 cracker box, 60 x 158 x 210, standing."""
    return [("box", (0.03, 0.079, 0.105), np.eye(3), (0.0, 0.0, 0.105))]


def _sugar_box(rng: np.random.Generator) -> list[tuple]:
    """004 sugar box, 38 x 89 x 175, standing."""
    return [("box", (0.019, 0.0445, 0.0875), np.eye(3), (0.0, 0.0, 0.0875))]


def _soup_can(rng: np.random.Generator) -> list[tuple]:
    """005 tomato soup can, 66 x 101."""
    return [("cylinder", (0.033, 0.033, 0.0505), np.eye(3), (0.0, 0.0, 0.0505))]


def _tuna_can(rng: np.random.Generator) -> list[tuple]:
    """007 tuna fish can, 85 x 33."""
    return [("cylinder", (0.0425, 0.0425, 0.0165), np.eye(3), (0.0, 0.0, 0.0165))]


def _potted_meat_can(rng: np.random.Generator) -> list[tuple]:
    """010 potted meat can, 50 x 97 x 82: a box with well rounded edges, standing."""
    return [((0.25, 0.25), (0.025, 0.0485, 0.041), np.eye(3), (0.0, 0.0, 0.041))]


def _ycb_mug(rng: np.random.Generator) -> list[tuple]:
    """025 mug, 80 across and 82 tall, its C-shaped handle reaching 37 out (117 in all)."""
    r, h, reach, bar, wide, span = 0.04, 0.041, 0.037, 0.006, 0.008, 0.024
    return [("cylinder", (r, r, h), np.eye(3), (0.0, 0.0, h)),
            ("rounded-box", ((reach + 0.004) / 2, wide, bar), np.eye(3), (r + (reach - 0.004) / 2, 0.0, h + span)),
            ("rounded-box", ((reach + 0.004) / 2, wide, bar), np.eye(3), (r + (reach - 0.004) / 2, 0.0, h - span)),
            ("rounded-box", (bar, wide, span + bar), np.eye(3), (r + reach - bar, 0.0, h))]


def _power_drill(rng: np.random.Generator) -> list[tuple]:
    """035 power drill, 184 x 187 x 57, standing on its battery: the battery, the grip on it and
    the barrel across the grip's top, reaching forward (+x)."""
    battery, grip, barrel_r, barrel_half = (0.045, 0.0285, 0.02), (0.02, 0.0175, 0.05), 0.028, 0.092
    grip_z = 2 * battery[2] + grip[2] - _SINK
    return [("rounded-box", battery, np.eye(3), (0.0, 0.0, battery[2])),
            ("rounded-box", grip, np.eye(3), (-0.015, 0.0, grip_z)),
            ("cylinder", (barrel_r, barrel_r, barrel_half), _ALONG_X,
             (barrel_half - 0.05, 0.0, grip_z + grip[2] + barrel_r - _SINK))]


def _ycb_hammer(rng: np.random.Generator) -> list[tuple]:
    """048 hammer, 330 long, its head 130 across: lying on the table, the handle along x."""
    handle, head = (0.14, 0.014, 0.014), (0.018, 0.065, 0.017)
    return [("rounded-box", handle, np.eye(3), (0.0, 0.0, handle[2])),
            ("box", head, np.eye(3), (handle[0] + head[0] - _SINK, 0.0, head[2]))]


def _banana(rng: np.random.Generator) -> list[tuple]:
    """011 banana, 190 long and 36 thick, lying on the table: three round pieces bent in a flat arc
    (each end piece turned 30 degrees from the middle one)."""
    r, half = 0.018, 0.038
    out = [("ellipsoid", (r, r, half + 0.006), _ALONG_X, (0.0, 0.0, r))]
    for side in (-1.0, 1.0):
        turn = rotation_z(side * 30.0)
        centre = np.array([side * half, 0.0, r]) + turn @ np.array([side * (half - _SINK), 0.0, 0.0])
        out.append(("ellipsoid", (r * 0.9, r * 0.9, half + 0.006), turn @ _ALONG_X, tuple(centre)))
    return out


#: YCB-like products (issue 21's "real products"): the YCB set's sizes, each a union of superquadrics.
YCB_LIKE = {
    "mustard-bottle": _mustard_bottle, "bleach-bottle": _bleach_bottle, "cracker-box": _cracker_box,
    "sugar-box": _sugar_box, "soup-can": _soup_can, "tuna-can": _tuna_can, "potted-meat-can": _potted_meat_can,
    "ycb-mug": _ycb_mug, "power-drill": _power_drill, "ycb-hammer": _ycb_hammer, "banana": _banana,
}
#: Every compound object :func:`compound` makes.
COMPOUND_KINDS = {**COMPOUNDS, **EVERYDAY, **YCB_LIKE}


def compound(name: str, position_xy: ArrayLike, yaw_deg: float = 0.0, seed: int = 0) -> CompoundObject:
    """A compound object of :data:`COMPOUND_KINDS` with sizes drawn from ``seed``, on the table at
    ``position_xy``, turned ``yaw_deg`` about the vertical.

    Examples
    --------
    >>> mug = compound("mug", (0.6, 0.0), seed=1)
    >>> len(mug.truth()["parts"]), round(float(mug.mesh()[0][:, 2].min()), 9)
    (4, 0.0)
    """
    if name not in COMPOUND_KINDS:
        raise ValueError(f"no compound object {name!r}: one of {', '.join(COMPOUND_KINDS)}")
    parts = COMPOUND_KINDS[name](np.random.default_rng(seed))
    R = rotation_z(yaw_deg)
    xy = np.append(np.asarray(position_xy, dtype=np.float64).reshape(2), 0.0)
    return CompoundObject(name, [_placed(family, size, R @ R_part, R @ np.asarray(centre) + xy)
                                 for family, size, R_part, centre in parts])
