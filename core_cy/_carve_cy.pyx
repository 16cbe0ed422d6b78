# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Kernel of the shrink step: move each point along its direction onto a silhouette edge."""

from libc.math cimport floor, sqrt

cdef double _MIN_DEPTH = 1e-12
# Halvings of the step that brackets the edge before the last interpolation: 3 px / 2^4 < 0.2 px.
cdef int _BISECTIONS = 4


cdef inline double _bilinear(const float[:, ::1] image, double u, double v) noexcept nogil:
    # Callers keep (u, v) within [0, W-1] x [0, H-1].
    cdef Py_ssize_t height = image.shape[0], width = image.shape[1]
    cdef Py_ssize_t col = <Py_ssize_t>floor(u), row = <Py_ssize_t>floor(v)
    if col > width - 2:
        col = width - 2
    if row > height - 2:
        row = height - 2
    cdef double fu = u - col, fv = v - row
    return ((1.0 - fv) * ((1.0 - fu) * image[row, col] + fu * image[row, col + 1])
            + fv * ((1.0 - fu) * image[row + 1, col] + fu * image[row + 1, col + 1]))


def carve_view(const double[:, ::1] directions not None, double[::1] radii not None,
               unsigned char[::1] observed not None, const double[::1] centre not None,
               const double[:, ::1] projection not None, const float[:, ::1] occupancy not None,
               double level=0.5, double step=3.0):
    """Shrink the points ``centre + radii[i] * directions[i]`` onto one view's silhouette.

    ``occupancy`` is the silhouette as floats in [0, 1], smooth enough that
    bilinear interpolation crossing ``level`` marks the edge to sub-pixel
    accuracy. A point projecting outside the image, or behind the camera, is
    unknown for this view and stays. A point outside the silhouette moves to
    where the ray through the first edge pixel on the image segment towards the
    centre's projection meets its direction line; with no edge on that segment,
    to the centre. The segment is walked in steps of ``step`` px and the
    crossing bracketed by bisection, then interpolated: a silhouette narrower
    than ``step`` across the segment can be stepped over. ``radii`` is updated
    in place, and ``observed[i]`` set to 1 for every point this view sees;
    returns how many moved.
    """
    cdef Py_ssize_t n = directions.shape[0], i
    cdef Py_ssize_t height = occupancy.shape[0], width = occupancy.shape[1]
    cdef double h0x, h0y, h0z, hux, huy, huz, px, py, pz, u, v, cu, cv, du, dv, length
    cdef double t, t_prev, s, s_prev, edge_t, eu, ev, ax, ay, bx, by, denominator, radius, t_mid, s_mid
    cdef int k
    cdef Py_ssize_t carved = 0
    cdef bint found
    if directions.shape[1] != 3 or radii.shape[0] != n or observed.shape[0] != n or centre.shape[0] != 3:
        raise ValueError("directions must be (N, 3), radii and observed (N,), centre (3,)")
    if projection.shape[0] != 3 or projection.shape[1] != 4:
        raise ValueError("projection must be (3, 4)")
    if height < 2 or width < 2:
        raise ValueError("occupancy must be at least 2x2")
    if step <= 0:
        raise ValueError("step must be positive")

    with nogil:
        h0x = projection[0, 0] * centre[0] + projection[0, 1] * centre[1] + projection[0, 2] * centre[2] + projection[0, 3]
        h0y = projection[1, 0] * centre[0] + projection[1, 1] * centre[1] + projection[1, 2] * centre[2] + projection[1, 3]
        h0z = projection[2, 0] * centre[0] + projection[2, 1] * centre[1] + projection[2, 2] * centre[2] + projection[2, 3]
        if h0z > _MIN_DEPTH:
            cu = h0x / h0z
            cv = h0y / h0z
            for i in range(n):
                radius = radii[i]
                hux = projection[0, 0] * directions[i, 0] + projection[0, 1] * directions[i, 1] + projection[0, 2] * directions[i, 2]
                huy = projection[1, 0] * directions[i, 0] + projection[1, 1] * directions[i, 1] + projection[1, 2] * directions[i, 2]
                huz = projection[2, 0] * directions[i, 0] + projection[2, 1] * directions[i, 1] + projection[2, 2] * directions[i, 2]
                pz = h0z + radius * huz
                if pz <= _MIN_DEPTH:
                    continue
                u = (h0x + radius * hux) / pz
                v = (h0y + radius * huy) / pz
                if u < 0 or v < 0 or u > width - 1 or v > height - 1:
                    continue
                observed[i] = 1
                s_prev = _bilinear(occupancy, u, v)
                if s_prev >= level:
                    continue
                du = cu - u
                dv = cv - v
                length = sqrt(du * du + dv * dv)
                found = False
                if length > 0:
                    du = du / length
                    dv = dv / length
                    t_prev = 0.0
                    t = 0.0
                    while t < length:
                        t = t + step
                        if t > length:
                            t = length
                        s = _bilinear(occupancy, u + t * du, v + t * dv)
                        if s >= level:
                            for k in range(_BISECTIONS):
                                t_mid = 0.5 * (t_prev + t)
                                s_mid = _bilinear(occupancy, u + t_mid * du, v + t_mid * dv)
                                if s_mid >= level:
                                    t = t_mid
                                    s = s_mid
                                else:
                                    t_prev = t_mid
                                    s_prev = s_mid
                            edge_t = t_prev + (level - s_prev) / (s - s_prev) * (t - t_prev)
                            found = True
                            break
                        t_prev = t
                        s_prev = s
                carved += 1
                if not found:
                    radii[i] = 0.0
                    continue
                # The edge pixel e lies on the projection of centre + r * direction;
                # solve e = (h0.xy + r hu.xy) / (h0.z + r hu.z) for r.
                eu = u + edge_t * du
                ev = v + edge_t * dv
                ax = eu * huz - hux
                ay = ev * huz - huy
                bx = h0x - eu * h0z
                by = h0y - ev * h0z
                denominator = ax * ax + ay * ay
                if denominator > 0:
                    s = (ax * bx + ay * by) / denominator
                    if s < 0:
                        s = 0.0
                    if s < radius:
                        radii[i] = s
    return carved
