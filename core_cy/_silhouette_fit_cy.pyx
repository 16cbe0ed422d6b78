# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Kernels of the silhouette fit: the superquadric's surface to outline it in a
view, the plane through each edge sample's ray that the outline says is
tangent to the object, and the robust least-squares normal equations of the
11 parameters against those planes.

Parameters ``x`` = (log a1, log a2, log a3, e1, e2, u1, u2, u3, alpha, beta,
gamma): sizes ``a = exp(x[0:3])``, position ``t = t0 + scale * u`` and
orientation ``R = R0 Rz(gamma) Ry(beta) Rx(alpha)``, as in the point fit.
"""

import numpy as np

from libc.math cimport exp, log, fabs, sqrt, cos, sin

from ._superquadric_cy cimport _rotation, _support

cdef double _TINY = 1e-300
# Edges of an outline searched together for a sample's nearest (see _tangent_planes).
cdef Py_ssize_t _RUN = 8


cdef inline void _pose(const double[::1] x, const double[:, ::1] R0, const double[::1] t0, double scale,
                       double R[3][3], double dR[3][3][3], double* a, double* t) noexcept nogil:
    """Sizes a, rotation R (and its derivatives dR) and position t of the parameters x."""
    cdef int k
    _rotation(R0, x[8], x[9], x[10], R, dR)
    for k in range(3):
        a[k] = exp(x[k])
        t[k] = t0[k] + scale * x[5 + k]


def outline_points(const double[::1] x not None, const double[:, ::1] R0 not None, const double[::1] t0 not None,
                   double scale, const double[::1] eta not None, const double[::1] omega not None,
                   const double[:, :, ::1] projections not None, const double[:, ::1] centres not None,
                   double[:, ::1] grid not None, float[:, :, ::1] uv not None, Py_ssize_t[::1] counts not None):
    """Pixels of the surface points that may lie on each view's outline; False if any is behind a camera.

    The surface is sampled on ``eta`` x ``omega`` (signed-power
    parametrisation) and at its poles; a point may lie on the outline where the
    view ray grazes the surface, i.e. where its normal turns from facing the
    camera to facing away between it and a grid neighbour (the poles always
    count). For view v, ``uv[v, :counts[v]]`` gets those points' pixels, whose
    convex hull is the outline. ``grid`` (len(eta) * len(omega) + 2, 6) is
    scratch space (object-frame points and normals). ``x`` as in
    :func:`normal_equations`.
    """
    cdef double[::1] trig = np.empty(4 * omega.shape[0])
    cdef unsigned char[::1] facing = np.empty(eta.shape[0] * omega.shape[0] + 2, np.uint8)
    cdef Py_ssize_t[::1] rows = np.empty(eta.shape[0] * omega.shape[0] + 2, np.intp)
    cdef double[:, ::1] angles = outline_angles(eta, omega)
    cdef bint in_front
    _check_outline(eta.shape[0], angles, projections, centres, grid, uv, counts)
    with nogil:
        in_front = _outline_points(x, R0, t0, scale, eta.shape[0], angles, projections, centres, grid, uv, counts,
                                   trig, facing, rows)
    return in_front


def outline_angles(const double[::1] eta not None, const double[::1] omega not None):
    """(len(eta) + len(omega), 4): for each angle, eta's then omega's, log |cos|, the sign of cos (0
    where it vanishes), log |sin| and the sign of sin: the grid's signed powers, ``sign exp(e log)``,
    without the angles' own trigonometry at every evaluation."""
    cdef Py_ssize_t n_eta = eta.shape[0], k
    cdef double[:, ::1] angles = np.empty((n_eta + omega.shape[0], 4))
    cdef double angle, c
    cdef int side
    for k in range(angles.shape[0]):
        angle = eta[k] if k < n_eta else omega[k - n_eta]
        for side in range(2):
            c = cos(angle) if side == 0 else sin(angle)
            if fabs(c) < _TINY:
                angles[k, 2 * side] = 0.0
                angles[k, 2 * side + 1] = 0.0
            else:
                angles[k, 2 * side] = log(fabs(c))
                angles[k, 2 * side + 1] = 1.0 if c > 0 else -1.0
    return np.asarray(angles)


cdef _check_outline(Py_ssize_t n_eta, const double[:, ::1] angles, const double[:, :, ::1] projections,
                    const double[:, ::1] centres, double[:, ::1] grid, float[:, :, ::1] uv, Py_ssize_t[::1] counts):
    cdef Py_ssize_t n_grid = n_eta * (angles.shape[0] - n_eta), n_views = projections.shape[0]
    if n_eta < 1 or angles.shape[0] <= n_eta or angles.shape[1] != 4:
        raise ValueError("angles must be outline_angles(eta, omega), eta's count n_eta")
    if grid.shape[0] != n_grid + 2 or grid.shape[1] != 6:
        raise ValueError("grid must be (len(eta) * len(omega) + 2, 6)")
    if (projections.shape[1] != 3 or projections.shape[2] != 4 or centres.shape[0] != n_views
            or centres.shape[1] != 3 or uv.shape[0] != n_views or uv.shape[1] < n_grid + 2
            or uv.shape[2] != 2 or counts.shape[0] != n_views):
        raise ValueError("need (V, 3, 4) projections, (V, 3) centres, (V, >= grid, 2) uv and (V,) counts")


cdef bint _outline_points(const double[::1] x, const double[:, ::1] R0, const double[::1] t0, double scale,
                          Py_ssize_t n_eta, const double[:, ::1] angles, const double[:, :, ::1] projections,
                          const double[:, ::1] centres, double[:, ::1] grid, float[:, :, ::1] uv,
                          Py_ssize_t[::1] counts, double[::1] trig, unsigned char[::1] facing,
                          Py_ssize_t[::1] rows) noexcept nogil:
    """As :func:`outline_points`, the angles as :func:`outline_angles` (``n_eta`` of them eta's);
    ``trig`` (4 len(omega)), ``facing`` and ``rows`` (len(grid) each) are scratch."""
    cdef Py_ssize_t n_omega = angles.shape[0] - n_eta, n_grid = n_eta * n_omega
    cdef Py_ssize_t n_views = projections.shape[0], i, j, k, v, row, count, other
    cdef double R[3][3]
    cdef double dR[3][3][3]
    cdef double a[3]
    cdef double t[3]
    cdef double c[3]
    cdef double w[3]
    cdef double e1 = x[3], e2 = x[4], ce, se, ne, nz, hx, hy, hz
    cdef double[::1] co = trig[:n_omega], so = trig[n_omega:2 * n_omega]
    cdef double[::1] nco = trig[2 * n_omega:3 * n_omega], nso = trig[3 * n_omega:]
    cdef bint in_front = True
    cdef Py_ssize_t listed
    _pose(x, R0, t0, scale, R, dR, a, t)
    # Points (a1 C^e1(eta) C^e2(omega), ...) and normals (C^(2-e1)(eta) C^(2-e2)(omega) / a1, ...).
    for j in range(n_omega):
        row = n_eta + j
        co[j] = angles[row, 1] * exp(e2 * angles[row, 0])
        so[j] = angles[row, 3] * exp(e2 * angles[row, 2])
        nco[j] = angles[row, 1] * exp((2.0 - e2) * angles[row, 0])
        nso[j] = angles[row, 3] * exp((2.0 - e2) * angles[row, 2])
    for i in range(n_eta):
        ce = angles[i, 1] * exp(e1 * angles[i, 0])
        se = angles[i, 3] * exp(e1 * angles[i, 2])
        ne = angles[i, 1] * exp((2.0 - e1) * angles[i, 0])
        nz = angles[i, 3] * exp((2.0 - e1) * angles[i, 2]) / a[2]
        for j in range(n_omega):
            row = i * n_omega + j
            grid[row, 0] = a[0] * ce * co[j]
            grid[row, 1] = a[1] * ce * so[j]
            grid[row, 2] = a[2] * se
            grid[row, 3] = ne * nco[j] / a[0]
            grid[row, 4] = ne * nso[j] / a[1]
            grid[row, 5] = nz
    for k in range(2):  # the poles
        grid[n_grid + k, 0] = 0.0
        grid[n_grid + k, 1] = 0.0
        grid[n_grid + k, 2] = -a[2] if k == 0 else a[2]
        grid[n_grid + k, 3] = 0.0
        grid[n_grid + k, 4] = 0.0
        grid[n_grid + k, 5] = -1.0 if k == 0 else 1.0
    for v in range(n_views):
        for k in range(3):  # the camera centre in the object frame
            c[k] = (R[0][k] * (centres[v, 0] - t[0]) + R[1][k] * (centres[v, 1] - t[1])
                    + R[2][k] * (centres[v, 2] - t[2]))
        for row in range(n_grid + 2):
            facing[row] = (grid[row, 3] * (grid[row, 0] - c[0]) + grid[row, 4] * (grid[row, 1] - c[1])
                           + grid[row, 5] * (grid[row, 2] - c[2])) > 0
        # The candidates, row by row of the grid (i, j): its neighbours along omega wrapping round, along
        # eta ending at the poles; then the poles, always candidates. Listed first without a branch (a
        # row's index is written, and kept where it differs from a neighbour), then projected.
        count = 0
        for i in range(n_eta):
            for j in range(n_omega):
                row = i * n_omega + j
                rows[count] = row
                count += ((facing[row] ^ facing[row + 1 if j + 1 < n_omega else row + 1 - n_omega])
                          | (facing[row] ^ facing[row - 1 if j > 0 else row + n_omega - 1])
                          | (facing[row] ^ facing[row + n_omega if i + 1 < n_eta else n_grid + 1])
                          | (facing[row] ^ facing[row - n_omega if i > 0 else n_grid]))
        rows[count] = n_grid
        rows[count + 1] = n_grid + 1
        listed = count + 2
        count = 0
        for other in range(listed):
            row = rows[other]
            for k in range(3):
                w[k] = t[k] + R[k][0] * grid[row, 0] + R[k][1] * grid[row, 1] + R[k][2] * grid[row, 2]
            hz = projections[v, 2, 0] * w[0] + projections[v, 2, 1] * w[1] + projections[v, 2, 2] * w[2] + projections[v, 2, 3]
            if hz <= 1e-12:
                in_front = False
                break
            hx = projections[v, 0, 0] * w[0] + projections[v, 0, 1] * w[1] + projections[v, 0, 2] * w[2] + projections[v, 0, 3]
            hy = projections[v, 1, 0] * w[0] + projections[v, 1, 1] * w[1] + projections[v, 1, 2] * w[2] + projections[v, 1, 3]
            uv[v, count, 0] = <float>(hx / hz)
            uv[v, count, 1] = <float>(hy / hz)
            count += 1
        counts[v] = count
        if not in_front:
            break
    return in_front


def tangent_planes(const float[:, ::1] hull not None, const double[:, ::1] samples not None,
                   const double[:, ::1] K not None, const double[:, ::1] R not None,
                   const double[::1] centre not None, double pixels_per_unit, double[:, ::1] planes not None):
    """The plane through each edge sample's ray with the normal of the outline where it passes nearest.

    ``hull`` (H, 2) is the outline, a convex polygon in either orientation;
    ``samples`` (N, 2) the edge samples (pixels); ``K``, ``R`` (camera-to-world
    rotation) and ``centre`` the camera. Row i of ``planes`` (N, 9) gets the
    plane's unit normal m (world, pointing out of the outline), ``m . centre``,
    the weight that turns the object's reach beyond the plane (world units)
    into pixels, ``|K^T (n, -n . p)| * pixels_per_unit`` (``pixels_per_unit``
    = 1 / the object's depth), and the plane's in-plane unit vector
    ``b = d x m`` across the ray d, with ``b . centre``: turning the plane
    about the ray by psi gives the normal ``cos(psi) m + sin(psi) b``.
    Where the sample lies outside a vertex of the outline, the normal points
    from the vertex to the sample.
    """
    cdef Py_ssize_t n = samples.shape[0]
    cdef double[:, ::1] edges = np.empty((hull.shape[0], 8))
    cdef double[:, ::1] rays = np.empty((n, 3))
    if hull.shape[1] != 2 or hull.shape[0] < 3:
        raise ValueError("hull must be (H, 2) with H >= 3")
    if samples.shape[1] != 2 or planes.shape[0] != n or planes.shape[1] != 9:
        raise ValueError("samples must be (N, 2) and planes (N, 9)")
    if K.shape[0] != 3 or K.shape[1] != 3 or R.shape[0] != 3 or R.shape[1] != 3 or centre.shape[0] != 3:
        raise ValueError("K and R must be (3, 3) and centre (3,)")
    with nogil:
        _rays(samples, 0, n, K, R, rays)
        _tangent_planes(&hull[0, 0], hull.shape[0], samples, 0, n, K, R, centre, pixels_per_unit, rays, planes,
                        edges)


def sample_rays(const double[:, ::1] samples not None, const Py_ssize_t[::1] starts not None,
                const double[:, :, ::1] K not None, const double[:, :, ::1] R not None):
    """(N, 3) each edge sample's ray, a unit direction in the world: view v's samples are
    ``samples[starts[v]:starts[v + 1]]``, its camera ``K[v]`` and ``R[v]`` (camera to world). The
    rays do not change while a fit runs, so they are worked out once, not at every evaluation."""
    cdef Py_ssize_t n_views = K.shape[0], v
    cdef double[:, ::1] rays = np.empty((samples.shape[0], 3))
    if (samples.shape[1] != 2 or starts.shape[0] != n_views + 1 or R.shape[0] != n_views or K.shape[1] != 3
            or K.shape[2] != 3 or R.shape[1] != 3 or R.shape[2] != 3):
        raise ValueError("need (N, 2) samples, (V + 1,) starts and (V, 3, 3) K and R")
    for v in range(n_views):
        if starts[v] < 0 or starts[v] > starts[v + 1] or starts[v + 1] > samples.shape[0]:
            raise ValueError("starts must rise from 0 to at most N")
        _rays(samples, starts[v], starts[v + 1], K[v], R[v], rays)
    return np.asarray(rays)


cdef void _rays(const double[:, ::1] samples, Py_ssize_t first, Py_ssize_t last, const double[:, ::1] K,
                const double[:, ::1] R, double[:, ::1] rays) noexcept nogil:
    """Rows ``first:last`` of :func:`sample_rays` for one camera: K^-1 (p, 1) (upper-triangular K),
    turned into the world and made unit."""
    cdef Py_ssize_t i
    cdef double r0, r1, r2, w0, w1, w2, norm
    for i in range(first, last):
        r1 = (samples[i, 1] - K[1, 2]) / K[1, 1]
        r0 = (samples[i, 0] - K[0, 2] - K[0, 1] * r1) / K[0, 0]
        r2 = 1.0
        w0 = R[0, 0] * r0 + R[0, 1] * r1 + R[0, 2] * r2
        w1 = R[1, 0] * r0 + R[1, 1] * r1 + R[1, 2] * r2
        w2 = R[2, 0] * r0 + R[2, 1] * r1 + R[2, 2] * r2
        norm = sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        rays[i, 0] = w0 / norm
        rays[i, 1] = w1 / norm
        rays[i, 2] = w2 / norm


cdef void _tangent_planes(const float* hull, Py_ssize_t h, const double[:, ::1] samples, Py_ssize_t first,
                          Py_ssize_t last, const double[:, ::1] K, const double[:, ::1] R, const double[::1] centre,
                          double pixels_per_unit, const double[:, ::1] rays, double[:, ::1] planes,
                          double[:, ::1] edges) noexcept nogil:
    """As :func:`tangent_planes`, for samples ``first:last`` into the same rows of ``planes``; ``hull``
    points to H (x, y) pairs, ``rays`` are the samples' :func:`sample_rays`, ``edges`` (>= H, 8) is
    scratch.

    Each sample's nearest edge is the first of the least distance, as a search of every edge finds
    it; but the edges are searched in runs of ``_RUN`` along the outline, and a run whose circle
    lies farther from the sample than the edge nearest the previous sample is passed over whole.
    """
    cdef Py_ssize_t i, j, b, runs = (h + _RUN - 1) // _RUN, last_j, seed = 0
    cdef double ax, ay, ex, ey, tau, dx, dy, d2, best, sign, area, reach
    cdef double best_nx, best_ny, best_dx = 0.0, best_dy = 0.0, px, py, mc0, mc1, mc2, norm, s, w0, w1, w2
    cdef bint at_vertex = False
    area = 0.0
    for j in range(h):
        area += (hull[2 * j] * hull[2 * ((j + 1) % h) + 1] - hull[2 * ((j + 1) % h)] * hull[2 * j + 1])
    # Outward normal of edge (e_x, e_y): (e_y, -e_x) when the polygon runs clockwise on screen
    # (a positive shoelace area in these y-down coordinates), (-e_y, e_x) otherwise.
    sign = 1.0 if area > 0 else -1.0
    for j in range(h):
        ex = hull[2 * ((j + 1) % h)] - hull[2 * j]
        ey = hull[2 * ((j + 1) % h) + 1] - hull[2 * j + 1]
        d2 = ex * ex + ey * ey
        edges[j, 0] = ex
        edges[j, 1] = ey
        edges[j, 2] = 1.0 / d2 if d2 > 0 else 0.0
        norm = sqrt(d2) if d2 > 0 else 1.0
        edges[j, 3] = sign * ey / norm
        edges[j, 4] = -sign * ex / norm
    for b in range(runs):  # each run's circle (centre, radius) holds its vertices, hence its edges
        last_j = min(b * _RUN + _RUN, h)
        ax = 0.0
        ay = 0.0
        for j in range(b * _RUN, last_j + 1):
            ax += hull[2 * (j % h)]
            ay += hull[2 * (j % h) + 1]
        ax /= last_j + 1 - b * _RUN
        ay /= last_j + 1 - b * _RUN
        d2 = 0.0
        for j in range(b * _RUN, last_j + 1):
            dx = hull[2 * (j % h)] - ax
            dy = hull[2 * (j % h) + 1] - ay
            d2 = max(d2, dx * dx + dy * dy)
        edges[b, 5] = ax
        edges[b, 6] = ay
        edges[b, 7] = sqrt(d2)
    for i in range(first, last):
        px = samples[i, 0]
        py = samples[i, 1]
        # The distance to the previous sample's nearest edge bounds this one's (a hair more, for rounding).
        ax = px - hull[2 * seed]
        ay = py - hull[2 * seed + 1]
        tau = min(max((ax * edges[seed, 0] + ay * edges[seed, 1]) * edges[seed, 2], 0.0), 1.0)
        dx = ax - tau * edges[seed, 0]
        dy = ay - tau * edges[seed, 1]
        reach = sqrt(dx * dx + dy * dy) * (1.0 + 1e-9) + 1e-6
        best = 1e300
        best_nx = 0.0
        best_ny = 0.0
        for b in range(runs):
            dx = px - edges[b, 5]
            dy = py - edges[b, 6]
            if dx * dx + dy * dy > (reach + edges[b, 7]) * (reach + edges[b, 7]):
                continue  # the whole run lies farther than the previous sample's nearest edge
            for j in range(b * _RUN, min(b * _RUN + _RUN, h)):
                ax = px - hull[2 * j]
                ay = py - hull[2 * j + 1]
                tau = (ax * edges[j, 0] + ay * edges[j, 1]) * edges[j, 2]
                if tau < 0:
                    tau = 0.0
                elif tau > 1:
                    tau = 1.0
                dx = ax - tau * edges[j, 0]
                dy = ay - tau * edges[j, 1]
                d2 = dx * dx + dy * dy
                if d2 < best:
                    best = d2
                    seed = j
                    best_nx = edges[j, 3]
                    best_ny = edges[j, 4]
                    best_dx = dx
                    best_dy = dy
                    at_vertex = tau == 0.0 or tau == 1.0
        # Outside a vertex, the normal points from it to the sample (worked out for the nearest edge alone).
        if best < 1e300 and at_vertex and best_nx * best_dx + best_ny * best_dy > 0 and best > 1e-12:
            norm = sqrt(best)
            best_nx = best_dx / norm
            best_ny = best_dy / norm
        # The plane through the camera centre and the image line n . u = n . p: K^T (n, -n . p).
        s = best_nx * px + best_ny * py
        mc0 = K[0, 0] * best_nx
        mc1 = K[0, 1] * best_nx + K[1, 1] * best_ny
        mc2 = K[0, 2] * best_nx + K[1, 2] * best_ny - s
        norm = sqrt(mc0 * mc0 + mc1 * mc1 + mc2 * mc2)
        mc0 /= norm
        mc1 /= norm
        mc2 /= norm
        for j in range(3):
            planes[i, j] = R[j, 0] * mc0 + R[j, 1] * mc1 + R[j, 2] * mc2
        planes[i, 3] = planes[i, 0] * centre[0] + planes[i, 1] * centre[1] + planes[i, 2] * centre[2]
        planes[i, 4] = norm * pixels_per_unit
        w0 = rays[i, 0]
        w1 = rays[i, 1]
        w2 = rays[i, 2]
        planes[i, 5] = w1 * planes[i, 2] - w2 * planes[i, 1]
        planes[i, 6] = w2 * planes[i, 0] - w0 * planes[i, 2]
        planes[i, 7] = w0 * planes[i, 1] - w1 * planes[i, 0]
        planes[i, 8] = planes[i, 5] * centre[0] + planes[i, 6] * centre[1] + planes[i, 7] * centre[2]


def part_planes(const double[::1] x not None, const double[:, :, ::1] R0 not None, const double[:, ::1] t0 not None,
                const double[::1] scale not None, Py_ssize_t n_eta, const double[:, ::1] angles not None,
                const double[:, :, ::1] projections not None, const double[:, ::1] centres not None,
                const double[:, ::1] samples not None, const Py_ssize_t[::1] starts not None,
                const double[:, :, ::1] K not None, const double[:, :, ::1] R not None,
                const double[::1] pixels_per_unit not None, const double[:, ::1] rays not None,
                double[:, ::1] grid not None, float[:, :, ::1] uv not None, Py_ssize_t[::1] counts not None,
                double[:, :, ::1] planes not None):
    """Each of P parts' :func:`tangent_planes` in every view, its outline drawn by
    :func:`outline_points`: the silhouette fit's work per evaluation in one call. False (``planes``
    then unfinished) if a part reaches behind a camera or its outline in a view is no polygon.

    Part p has parameters ``x[11 p: 11 p + 11]`` about its frame ``R0[p]``, ``t0[p]``, ``scale[p]``
    (as in :func:`normal_equations`). View v's samples are ``samples[starts[v]:starts[v + 1]]`` (N, 2
    in all), their :func:`sample_rays` ``rays``, and its camera ``K[v]``, ``R[v]`` (camera to world),
    ``centres[v]``, ``pixels_per_unit[v]``; ``planes[p]`` (N, 9) gets part p's rows. The outline is the
    convex hull of ``uv[v, :counts[v]]`` (which this reorders): the polygon ``cv2.convexHull`` draws.
    ``angles`` are :func:`outline_angles` of ``n_eta`` eta's and the omega's; ``grid``, ``uv`` and
    ``counts`` are scratch as in :func:`outline_points`.
    """
    cdef Py_ssize_t n_views = projections.shape[0], n_rows = grid.shape[0], n_parts = R0.shape[0], v, h, p
    cdef double[::1] trig = np.empty(4 * max(angles.shape[0] - n_eta, 0))
    cdef unsigned char[::1] facing = np.empty(n_rows, np.uint8)
    cdef Py_ssize_t[::1] rows = np.empty(n_rows, np.intp)
    cdef double[:, ::1] edges = np.empty((n_rows, 8))
    cdef float[:, ::1] hull = np.empty((2 * n_rows, 2), np.float32)
    cdef bint ok = True
    _check_outline(n_eta, angles, projections, centres, grid, uv, counts)
    if (samples.shape[1] != 2 or starts.shape[0] != n_views + 1 or rays.shape[0] != samples.shape[0]
            or rays.shape[1] != 3 or planes.shape[0] != n_parts or planes.shape[1] != samples.shape[0]
            or planes.shape[2] != 9 or K.shape[0] != n_views or R.shape[0] != n_views
            or pixels_per_unit.shape[0] != n_views or K.shape[1] != 3 or K.shape[2] != 3 or R.shape[1] != 3
            or R.shape[2] != 3):
        raise ValueError("need (N, 2) samples, (V + 1,) starts, (N, 3) rays, (P, N, 9) planes, (V, 3, 3) K and R, "
                         "(V,) scales")
    if (x.shape[0] != 11 * n_parts or R0.shape[1] != 3 or R0.shape[2] != 3 or t0.shape[0] != n_parts
            or t0.shape[1] != 3 or scale.shape[0] != n_parts):
        raise ValueError("need x of 11 per part, (P, 3, 3) R0, (P, 3) t0 and (P,) scale")
    for v in range(n_views):
        if starts[v] < 0 or starts[v] > starts[v + 1] or starts[v + 1] > samples.shape[0]:
            raise ValueError("starts must rise from 0 to at most N")
    with nogil:
        for p in range(n_parts):
            ok = _outline_points(x[11 * p: 11 * p + 11], R0[p], t0[p], scale[p], n_eta, angles, projections,
                                 centres, grid, uv, counts, trig, facing, rows)
            for v in range(n_views):
                if not ok:
                    break
                h = _convex_hull(<_Point*>&uv[v, 0, 0], counts[v], <_Point*>&hull[0, 0])
                if h < 3:
                    ok = False
                    break
                _tangent_planes(&hull[0, 0], h, samples, starts[v], starts[v + 1], K[v], R[v], centres[v],
                                pixels_per_unit[v], rays, planes[p], edges)
            if not ok:
                break
    return ok


ctypedef struct _Point:
    float x
    float y


cdef inline bint _before(_Point p, _Point q) noexcept nogil:
    """p comes before q in (x, y) order."""
    return p.x < q.x or (p.x == q.x and p.y < q.y)


cdef void _sort_points(_Point* points, Py_ssize_t n) noexcept nogil:
    """Sort the points in (x, y) order, in place: a quicksort (median of three) leaving short runs to
    insertion sort, with no call per comparison (points alike in x and y are the same point, so
    any sort gives the same array)."""
    cdef Py_ssize_t stack[128]
    cdef Py_ssize_t top = 0, low, high, i, j, middle
    cdef _Point pivot, swap
    stack[0] = 0
    stack[1] = n - 1
    top = 2
    while top > 0:
        top -= 2
        low = stack[top]
        high = stack[top + 1]
        while high - low > 12:
            middle = low + (high - low) // 2
            if _before(points[middle], points[low]):
                swap = points[middle]; points[middle] = points[low]; points[low] = swap
            if _before(points[high], points[low]):
                swap = points[high]; points[high] = points[low]; points[low] = swap
            if _before(points[high], points[middle]):
                swap = points[high]; points[high] = points[middle]; points[middle] = swap
            pivot = points[middle]
            i = low
            j = high
            while i <= j:
                while _before(points[i], pivot):
                    i += 1
                while _before(pivot, points[j]):
                    j -= 1
                if i <= j:
                    swap = points[i]; points[i] = points[j]; points[j] = swap
                    i += 1
                    j -= 1
            # The larger side waits on the stack, the smaller is sorted next: the stack stays shallow.
            if j - low < high - i:
                if i < high:
                    stack[top] = i
                    stack[top + 1] = high
                    top += 2
                high = j
            else:
                if low < j:
                    stack[top] = low
                    stack[top + 1] = j
                    top += 2
                low = i
        for i in range(low + 1, high + 1):
            swap = points[i]
            j = i - 1
            while j >= low and _before(swap, points[j]):
                points[j + 1] = points[j]
                j -= 1
            points[j + 1] = swap


cdef inline double _turn(_Point o, _Point a, _Point b) noexcept nogil:
    """Twice the signed area of the triangle o, a, b."""
    return (<double>a.x - o.x) * (<double>b.y - o.y) - (<double>a.y - o.y) * (<double>b.x - o.x)


cdef Py_ssize_t _convex_hull(_Point* points, Py_ssize_t n, _Point* hull) noexcept nogil:
    """Andrew's monotone chain: the vertices of the points' convex hull (none in line with its
    neighbours) into ``hull`` (room for 2 n), returning how many; ``points`` get sorted. They are
    cv2.convexHull's vertices, turning the same way, from the last point in (x, y) order along the
    upper chain: where cv2 starts too, but for a few point sets in a thousand (rounded to a tenth of a
    pixel) where it starts elsewhere. The start only decides which of two edges exactly as near a
    sample it takes."""
    cdef Py_ssize_t i, k = 0, lower
    if n < 3:
        return 0
    _sort_points(points, n)
    for i in range(n - 1, -1, -1):
        while k >= 2 and _turn(hull[k - 2], hull[k - 1], points[i]) <= 0:
            k -= 1
        hull[k] = points[i]
        k += 1
    lower = k
    for i in range(1, n):
        while k > lower and _turn(hull[k - 2], hull[k - 1], points[i]) <= 0:
            k -= 1
        hull[k] = points[i]
        k += 1
    return k - 1


cdef inline double _reach(const double* a, const double* e, const double* t, double R[3][3], const double* m,
                          double offset, double* v, double* dh_da, double* dh_de, double* dh_dv) noexcept nogil:
    """How far (world units) the superquadric reaches beyond the plane m . x = offset; v gets R^T m."""
    cdef int k
    for k in range(3):
        v[k] = R[0][k] * m[0] + R[1][k] * m[1] + R[2][k] * m[2]
    return m[0] * t[0] + m[1] * t[1] + m[2] * t[2] + _support(a, e, v, dh_da, dh_de, dh_dv) - offset


cdef enum:
    MAX_PARTS = 6


ctypedef struct _Support:
    double v[3]  # the object-frame direction
    double lT[3]  # log |a_k v_k|
    double lS, lG, h  # as in _superquadric_cy._support
    double rS, rG  # the ratios (the lesser term over the greater) of the two log-sums, for their shares
    bint xS, xG  # whether the first term of each log-sum is the greater


ctypedef struct _Exponents:
    double q1, q2, q12  # 2 / (2 - e1), 2 / (2 - e2) and q1 / q2: a part's, the same for all its samples


cdef inline void _exponents(const double* e, _Exponents* q) noexcept nogil:
    q.q1 = 2.0 / (2.0 - e[0])
    q.q2 = 2.0 / (2.0 - e[1])
    q.q12 = q.q1 / q.q2


cdef inline double _log_sum_ratio(double la, double lb, double* ratio, bint* first) noexcept nogil:
    """log(e^la + e^lb) as ``_log_sum`` works it out (the same arithmetic), the shares left for
    :func:`_shares`: only the chosen plane's support needs them."""
    if la >= lb:
        ratio[0] = exp(lb - la)
        first[0] = True
        return la + log(1.0 + ratio[0])
    ratio[0] = exp(la - lb)
    first[0] = False
    return lb + log(1.0 + ratio[0])


cdef inline void _shares(double ratio, bint first, double* wa, double* wb) noexcept nogil:
    """The shares ``_log_sum`` gives with its log-sum (the same arithmetic)."""
    if first:
        wa[0] = 1.0 / (1.0 + ratio)
        wb[0] = ratio * wa[0]
    else:
        wb[0] = 1.0 / (1.0 + ratio)
        wa[0] = ratio * wb[0]


cdef inline double _support_kept(const double* a, const _Exponents* q, const double* v, _Support* s) noexcept nogil:
    """The support along v (as ``_support_value``, the same arithmetic), keeping in ``s`` what its
    derivatives need: the sample's tangent plane is found among several tried, and only the chosen
    one's derivatives are wanted, from the terms already worked out (:func:`_support_derivatives`)."""
    cdef double T
    cdef int k
    for k in range(3):
        s.v[k] = v[k]
        T = fabs(a[k] * v[k])
        s.lT[k] = log(T if T > _TINY else _TINY)
    s.lS = _log_sum_ratio(q.q2 * s.lT[0], q.q2 * s.lT[1], &s.rS, &s.xS)
    s.lG = _log_sum_ratio(q.q12 * s.lS, q.q1 * s.lT[2], &s.rG, &s.xG)
    s.h = exp(s.lG / q.q1)
    return s.h


cdef inline void _supports_kept3(const double* a, const _Exponents* q, double v[3][3], _Support* s) noexcept nogil:
    """:func:`_support_kept` along three directions, each support the same arithmetic, but step by
    step for all three together: the three chains of logarithms and exponentials do not wait on
    each other, so the processor works on them at once."""
    cdef double T
    cdef int j, k
    for j in range(3):
        for k in range(3):
            s[j].v[k] = v[j][k]
            T = fabs(a[k] * v[j][k])
            s[j].lT[k] = log(T if T > _TINY else _TINY)
    for j in range(3):
        s[j].lS = _log_sum_ratio(q.q2 * s[j].lT[0], q.q2 * s[j].lT[1], &s[j].rS, &s[j].xS)
    for j in range(3):
        s[j].lG = _log_sum_ratio(q.q12 * s[j].lS, q.q1 * s[j].lT[2], &s[j].rG, &s[j].xG)
    for j in range(3):
        s[j].h = exp(s[j].lG / q.q1)


cdef inline void _support_derivatives(const double* a, const double* e, const _Exponents* q, const _Support* s,
                                      double* dh_da, double* dh_de, double* dh_dv) noexcept nogil:
    """dh/da, dh/de and dh/dv of :func:`_support_kept`'s support (as ``_superquadric_cy._support``
    gives them, the same arithmetic)."""
    cdef double q1 = q.q1, q2 = q.q2, h = s.h, lS = s.lS, lG = s.lG, dq1, dq2, w1, w2, g1, g3
    cdef double dT[3]
    cdef int k
    _shares(s.rS, s.xS, &w1, &w2)
    _shares(s.rG, s.xG, &g1, &g3)
    dT[0] = h * exp(q.q12 * lS - lG + (q2 - 1.0) * s.lT[0] - lS)
    dT[1] = h * exp(q.q12 * lS - lG + (q2 - 1.0) * s.lT[1] - lS)
    dT[2] = h * exp((q1 - 1.0) * s.lT[2] - lG)
    dq1 = h * (-lG / (q1 * q1) + (g1 * lS / q2 + g3 * s.lT[2]) / q1)
    dq2 = h * g1 / q2 * (w1 * s.lT[0] + w2 * s.lT[1] - lS / q2)
    dh_de[0] = dq1 * 2.0 / ((2.0 - e[0]) * (2.0 - e[0]))
    dh_de[1] = dq2 * 2.0 / ((2.0 - e[1]) * (2.0 - e[1]))
    for k in range(3):
        dh_da[k] = dT[k] * fabs(s.v[k])
        dh_dv[k] = dT[k] * a[k] * (1.0 if s.v[k] > 0 else (-1.0 if s.v[k] < 0 else 0.0))


cdef inline double _least_reach(const double[:, :, ::1] planes, Py_ssize_t p, Py_ssize_t i, const double* a,
                                const _Exponents* e, const double* t, double R[3][3], const double* cosines,
                                const double* sines, double tilt, double bound, bint eager, double* best_m,
                                _Support* best_support) noexcept nogil:
    """Part p's least reach (world units) beyond the planes through sample i's ray, turned about the
    ray by -tilt, 0, tilt and the parabola's vertex (``e``: the part's :func:`_exponents`); best_m
    gets that plane's normal (its offset is returned through best_m[3]) and best_support its
    support's terms. The plane through the ray untilted comes first: turning it only lowers the
    least reach, so where that reach is already below ``bound`` it is returned at once."""
    cdef double m[3]
    cdef double v[3]
    cdef double reaches[3]
    cdef _Support support
    cdef double best = 1e300, cs, sn, psi, curvature, offset, reach
    cdef int j, k, step
    cdef double ms[3][3]
    cdef double vs[3][3]
    cdef double offsets[3]
    cdef _Support supports[3]
    eager = eager and tilt > 0
    if eager:
        for j in range(3):
            for k in range(3):
                ms[j][k] = cosines[j] * planes[p, i, k] + sines[j] * planes[p, i, 5 + k]
            offsets[j] = cosines[j] * planes[p, i, 3] + sines[j] * planes[p, i, 8]
            for k in range(3):
                vs[j][k] = R[0][k] * ms[j][0] + R[1][k] * ms[j][1] + R[2][k] * ms[j][2]
        _supports_kept3(a, e, vs, supports)
    for step in range(4):
        j = 1 if step == 0 else (0 if step == 1 else step)  # untilted, -tilt, +tilt, the vertex
        if j < 3:
            cs = cosines[j]
            sn = sines[j]
        else:  # the parabola's vertex, if it opens upwards, within the three
            curvature = reaches[0] - 2.0 * reaches[1] + reaches[2]
            if curvature <= 0 or tilt <= 0:
                break
            psi = 0.5 * tilt * (reaches[0] - reaches[2]) / curvature
            if psi < -tilt or psi > tilt:
                break
            cs = cos(psi)
            sn = sin(psi)
        if eager and j < 3:
            for k in range(3):
                m[k] = ms[j][k]
            offset = offsets[j]
            support = supports[j]
            reach = m[0] * t[0] + m[1] * t[1] + m[2] * t[2] + support.h - offset
        else:
            for k in range(3):
                m[k] = cs * planes[p, i, k] + sn * planes[p, i, 5 + k]
            offset = cs * planes[p, i, 3] + sn * planes[p, i, 8]
            for k in range(3):
                v[k] = R[0][k] * m[0] + R[1][k] * m[1] + R[2][k] * m[2]
            reach = m[0] * t[0] + m[1] * t[1] + m[2] * t[2] + _support_kept(a, e, v, &support) - offset
        if j < 3:
            reaches[j] = reach
        if reach < best:
            best = reach
            for k in range(3):
                best_m[k] = m[k]
            best_m[3] = offset
            best_support[0] = support
        if tilt <= 0 or best < bound:
            break
    return best


cdef inline double _box_reach(const double[:, :, ::1] planes, Py_ssize_t p, Py_ssize_t i, const double* a,
                              const double* t, double R[3][3]) noexcept nogil:
    """How far (world units) part p's box reaches beyond the plane through sample i's ray, untilted:
    no less than the part itself does beyond any plane :func:`_least_reach` tries."""
    cdef double reach = -planes[p, i, 3], v
    cdef int k
    for k in range(3):
        reach += planes[p, i, k] * t[k]
        v = R[0][k] * planes[p, i, 0] + R[1][k] * planes[p, i, 1] + R[2][k] * planes[p, i, 2]
        reach += fabs(v) * a[k]
    return reach


def normal_equations(const double[::1] x not None, const double[:, :, ::1] R0 not None,
                     const double[:, ::1] t0 not None, const double[::1] scale not None,
                     const double[:, :, ::1] planes not None, double loss_scale,
                     const double[::1] support_plane not None, double plane_weight, double tilt,
                     double[:, ::1] JtJ not None, double[::1] Jtr not None, bint jacobian=True,
                     Py_ssize_t[::1] owner=None, const unsigned char[::1] doubtful=None):
    """Robust cost of the samples' residuals against a union of P parts and, with ``jacobian``,
    the Gauss-Newton normal equations of its 11 P parameters.

    Part p has parameters ``x[11 p: 11 p + 11]`` about its frame ``R0[p]``, ``t0[p]``,
    ``scale[p]``; ``planes[p]`` (N, 9) are :func:`tangent_planes` of the samples against part
    p's outline. Residual of sample i against part p: ``w (h(m) - m . c)``, how far (pixels)
    the part reaches beyond the plane through the sample's ray, h being its support
    function; positive where the sample lies inside the part's outline. The plane comes
    from a polygon outline; the tangent plane through the ray is the one of least reach, so
    the plane is turned about the ray by -``tilt``, 0 and ``tilt`` (radians), a parabola
    through the three reaches points to a fourth, and the least of them counts. The union's
    outline is the outermost of its parts': the sample's residual is the largest of its
    parts' (the part that reaches farthest past it answers for it, the first of those alike;
    ``owner[i]``, when given, gets which: the part tried first, the one that answered last
    time, is read from it and changes nothing but the time). The loss is ``c^2 (sqrt(1 + (r/c)^2) - 1)`` (c = ``loss_scale``, pixels):
    quadratic for small residuals, linear for large ones. A sample marked in ``doubtful`` (one per
    sample, when given) lies where the segmentation cannot confirm its silhouette's edge: its loss is
    ``c^2 / 2 log(1 + (r/c)^2)``, alike for small residuals, but its pull fading as they grow past c,
    so that a stretch of one view's outline far from what the other samples say (a shadow taken in,
    a dark face left out) does not drag the model to it. With ``plane_weight > 0`` each
    part's reach below ``support_plane`` (n, d; unit n; the object where n . x + d >= 0),
    times ``plane_weight``, is one more residual under the same loss: the lowest part stands
    on the plane, touching it, and no other part reaches below it. Fills ``JtJ`` (11 P, 11 P)
    with J^T W J (block diagonal: each residual is one part's) and ``Jtr`` with J^T W r (W
    the IRLS weights of the loss) and returns the cost.
    """
    cdef Py_ssize_t P = R0.shape[0], n = planes.shape[1], i, j, k, q, p, base, chosen, lowest, first
    cdef double R[MAX_PARTS][3][3]
    cdef double dR[MAX_PARTS][3][3][3]
    cdef double a[MAX_PARTS][3]
    cdef double t[MAX_PARTS][3]
    cdef double below[MAX_PARTS]
    cdef double v[3]
    cdef double m[4]
    cdef double best_m[4]
    cdef double J[11]
    cdef double dh_da[3]
    cdef double dh_de[2]
    cdef double dh_dv[3]
    cdef double c2 = loss_scale * loss_scale, cost = 0.0, r, root, w, weight, offset, reach, best, deepest
    cdef _Support found, kept
    cdef _Exponents exponents[MAX_PARTS]
    cdef bint answered
    cdef double cosines[3]
    cdef double sines[3]
    if P < 1 or P > MAX_PARTS or x.shape[0] != 11 * P or JtJ.shape[0] != 11 * P or JtJ.shape[1] != 11 * P \
            or Jtr.shape[0] != 11 * P:
        raise ValueError(f"need 1 to {MAX_PARTS} parts, x and Jtr of 11 per part, JtJ square of that")
    if (R0.shape[1] != 3 or R0.shape[2] != 3 or t0.shape[0] != P or t0.shape[1] != 3 or scale.shape[0] != P
            or planes.shape[0] != P or planes.shape[2] != 9 or support_plane.shape[0] != 4):
        raise ValueError("R0 must be (P, 3, 3), t0 (P, 3), scale (P,), planes (P, N, 9) and support_plane (4,)")
    if owner is not None and owner.shape[0] != n:
        raise ValueError("owner must have one entry per sample")
    if doubtful is not None and doubtful.shape[0] != n:
        raise ValueError("doubtful must have one entry per sample")
    for p in range(P):
        _rotation(R0[p], x[11 * p + 8], x[11 * p + 9], x[11 * p + 10], R[p], dR[p])
        for k in range(3):
            a[p][k] = exp(x[11 * p + k])
            t[p][k] = t0[p, k] + scale[p] * x[11 * p + 5 + k]
        _exponents(&x[11 * p + 3], &exponents[p])
    with nogil:
        cosines[0] = cos(tilt)
        cosines[1] = 1.0
        cosines[2] = cosines[0]
        sines[0] = -sin(tilt)
        sines[1] = 0.0
        sines[2] = -sines[0]
        if jacobian:
            for j in range(11 * P):
                Jtr[j] = 0.0
                for k in range(11 * P):
                    JtJ[j, k] = 0.0
        lowest = 0
        if plane_weight > 0:
            deepest = -1e300
            for k in range(3):
                m[k] = -support_plane[k]
            for p in range(P):
                below[p] = _reach(a[p], &x[11 * p + 3], t[p], R[p], m, support_plane[3], v, dh_da, dh_de, dh_dv)
                if below[p] > deepest:
                    deepest = below[p]
                    lowest = p
        for i in range(n + (P if plane_weight > 0 else 0)):
            if i < n:
                best = -1e300
                chosen = 0
                answered = False
                # The part that answered last time first: it most likely does again, and then the others
                # are mostly dismissed by their box alone. Which part answers does not depend on the order.
                first = owner[i] if owner is not None and 0 <= owner[i] < P else 0
                for q in range(P):
                    p = first if q == 0 else (q - 1 if q <= first else q)
                    if q > 0:
                        # A part lies within its box, so it reaches no farther past the plane than the box
                        # does: where that is short of the best so far (in pixels), it cannot answer.
                        reach = _box_reach(planes, p, i, a[p], t[p], R[p])
                        if planes[p, i, 4] * reach + 1e-9 * (fabs(planes[p, i, 4] * reach) + 1.0) < best:
                            continue
                    # A part whose reach (in pixels) falls below the best so far cannot answer for the sample.
                    reach = planes[p, i, 4] * _least_reach(planes, p, i, a[p], &exponents[p], t[p], R[p],
                                                          cosines, sines, tilt, best / planes[p, i, 4], q == 0, m,
                                                          &found)
                    # Of parts that reach alike, the first answers.
                    if reach > best or (reach == best and p < chosen):
                        best = reach
                        chosen = p
                        answered = True
                        kept = found
                        for k in range(4):
                            best_m[k] = m[k]
                if owner is not None:
                    owner[i] = chosen
                weight = planes[chosen, i, 4]
                for k in range(4):
                    m[k] = best_m[k]
                offset = m[3]
            else:  # the support plane: each part's reach along -n beyond d
                chosen = i - n
                if chosen != lowest and below[chosen] <= 0:
                    continue  # a part above the plane, not the one standing on it
                for k in range(3):
                    m[k] = -support_plane[k]
                offset = support_plane[3]
                weight = plane_weight
            p = chosen
            base = 11 * p
            if i < n and answered:
                # The chosen plane's residual is the reach already found (the same arithmetic), and its
                # support's derivatives come from the terms kept with it.
                r = best
                if jacobian:
                    _support_derivatives(a[p], &x[base + 3], &exponents[p], &kept, dh_da, dh_de, dh_dv)
            else:
                r = weight * _reach(a[p], &x[base + 3], t[p], R[p], m, offset, v, dh_da, dh_de, dh_dv)
            if doubtful is not None and i < n and doubtful[i]:
                root = 1.0 + r * r / c2  # the IRLS weight's inverse, as for the others
                cost += 0.5 * c2 * log(root)
            else:
                root = sqrt(1.0 + r * r / c2)
                cost += c2 * (root - 1.0)
            if not jacobian:
                continue
            w = 1.0 / root
            for k in range(3):
                J[k] = weight * dh_da[k] * a[p][k]
                J[5 + k] = weight * scale[p] * m[k]
            J[3] = weight * dh_de[0]
            J[4] = weight * dh_de[1]
            for q in range(3):  # d(R^T m)/d angle = dR^T m
                J[8 + q] = 0.0
                for k in range(3):
                    J[8 + q] += dh_dv[k] * (dR[p][q][0][k] * m[0] + dR[p][q][1][k] * m[1] + dR[p][q][2][k] * m[2])
                J[8 + q] *= weight
            for j in range(11):
                Jtr[base + j] += w * J[j] * r
                for k in range(j, 11):
                    JtJ[base + j, base + k] += w * J[j] * J[k]
        if jacobian:
            for j in range(11 * P):
                for k in range(j):
                    JtJ[j, k] = JtJ[k, j]
    return cost
