# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Kernel of the edge samples: where, along a line across a silhouette's edge, the
image turns from the object's colour to the background's."""

from libc.math cimport floor

cdef enum:
    MAX_CHANNELS = 4


cdef inline void _bilinear(const unsigned char[:, :, ::1] image, double u, double v,
                           double* out) noexcept nogil:
    """Bilinear sample of every channel at (u, v), the coordinates clamped into the image."""
    cdef Py_ssize_t height = image.shape[0], width = image.shape[1], channels = image.shape[2]
    cdef Py_ssize_t col, row, k
    cdef double fu, fv
    if u < 0:
        u = 0
    if v < 0:
        v = 0
    if u > width - 1:
        u = width - 1
    if v > height - 1:
        v = height - 1
    col = <Py_ssize_t>floor(u)
    row = <Py_ssize_t>floor(v)
    if col > width - 2:
        col = width - 2
    if row > height - 2:
        row = height - 2
    fu = u - col
    fv = v - row
    for k in range(channels):
        out[k] = ((1.0 - fv) * ((1.0 - fu) * image[row, col, k] + fu * image[row, col + 1, k])
                  + fv * ((1.0 - fu) * image[row + 1, col, k] + fu * image[row + 1, col + 1, k]))


cdef bint _crossing(const unsigned char[:, :, ::1] image, double px, double py, double nx, double ny,
                    double reach, double step, Py_ssize_t samples, Py_ssize_t ends, double min_contrast,
                    double* crossing) noexcept nogil:
    """The crossing of the profile through (px, py) along (nx, ny) (see :func:`edge_crossings`)."""
    cdef Py_ssize_t channels = image.shape[2], j, k
    cdef double inner[MAX_CHANNELS]
    cdef double outer[MAX_CHANNELS]
    cdef double colour[MAX_CHANNELS]
    cdef double difference[MAX_CHANNELS]
    cdef double contrast2, t, a, previous, previous_t, best, candidate
    for k in range(channels):
        inner[k] = 0.0
        outer[k] = 0.0
    for j in range(ends):
        _bilinear(image, px - (reach - j * step) * nx, py - (reach - j * step) * ny, colour)
        for k in range(channels):
            inner[k] += colour[k] / ends
        _bilinear(image, px + (reach - j * step) * nx, py + (reach - j * step) * ny, colour)
        for k in range(channels):
            outer[k] += colour[k] / ends
    contrast2 = 0.0
    for k in range(channels):
        difference[k] = inner[k] - outer[k]
        contrast2 += difference[k] * difference[k]
    if contrast2 < min_contrast * min_contrast:
        return False
    best = 1e300
    previous = 1.0
    previous_t = -reach
    for j in range(samples):
        t = -reach + j * step
        _bilinear(image, px + t * nx, py + t * ny, colour)
        a = 0.0
        for k in range(channels):
            a += (colour[k] - outer[k]) * difference[k]
        a /= contrast2
        if j > 0 and previous >= 0.5 and a < 0.5:
            candidate = previous_t + (previous - 0.5) / (previous - a) * (t - previous_t)
            if (candidate if candidate >= 0 else -candidate) < (best if best >= 0 else -best):
                best = candidate
        previous = a
        previous_t = t
    if best >= 1e300:
        return False
    crossing[0] = best
    return True


def edge_crossings(const unsigned char[:, :, ::1] image not None, const double[:, ::1] points not None,
                   const double[:, ::1] normals not None, double reach, double step, double min_contrast,
                   double[::1] shift not None, unsigned char[::1] found not None):
    """For each point, how far along its normal the image crosses half-way between the colours at its ends.

    The profile runs from ``-reach`` to ``+reach`` along the normal in steps of
    ``step`` px; its ends (the mean of the samples within one pixel of each)
    are the colours of the edge's two sides, and each sample is placed between
    them by projection onto their difference (1 = the ``-reach`` side, 0 = the
    other), so the normal may point either way. ``shift[i]`` is the crossing
    of 1/2 nearest the point, linearly interpolated, and found once more on a
    profile centred there if it lay more than 0.05 px away; ``found[i]`` is
    0 where the ends differ by less than ``min_contrast`` grey levels or no
    crossing exists (``shift`` is then 0). Works for any number of channels
    up to 4 (a mask is a one-channel image).
    """
    cdef Py_ssize_t n = points.shape[0], i, samples, ends, attempt
    cdef Py_ssize_t channels = image.shape[2]
    cdef double moved = 0.0
    if points.shape[1] != 2 or normals.shape[0] != n or normals.shape[1] != 2:
        raise ValueError("points and normals must be (N, 2) arrays of the same length")
    if shift.shape[0] != n or found.shape[0] != n:
        raise ValueError("shift and found must have one entry per point")
    if not 1 <= channels <= MAX_CHANNELS or image.shape[0] < 2 or image.shape[1] < 2:
        raise ValueError("image must be (H, W, C) with H, W >= 2 and 1 <= C <= 4")
    if not (reach > 0 and step > 0 and reach >= 2 * step):
        raise ValueError("need reach >= 2 * step > 0")
    samples = <Py_ssize_t>floor(2 * reach / step + 0.5) + 1
    ends = <Py_ssize_t>floor(1.0 / step + 0.5)
    if ends < 1:
        ends = 1
    if 2 * ends >= samples:
        ends = samples // 2 - 1 if samples >= 4 else 1
    with nogil:
        for i in range(n):
            shift[i] = 0.0
            found[i] = 0
            # Twice: the ends of a profile centred off the edge lie unevenly deep in the edge's blur,
            # which pulls the crossing; centred on the first crossing, they lie evenly.
            for attempt in range(2):
                if not _crossing(image, points[i, 0] + shift[i] * normals[i, 0],
                                 points[i, 1] + shift[i] * normals[i, 1], normals[i, 0], normals[i, 1],
                                 reach, step, samples, ends, min_contrast, &moved):
                    break
                shift[i] += moved
                found[i] = 1
                if moved < 0.05 and moved > -0.05:
                    break


def smoothest_path(const double[:, ::1] cost not None, double step_cost, Py_ssize_t max_step,
                   Py_ssize_t[::1] path not None):
    """The path around a closed loop that is cheapest in ``cost`` plus ``step_cost`` per unit of change.

    ``cost`` is (S, D): S positions around a closed loop and D choices at each (the candidate offsets
    of an edge along the loop's normal); ``path[s]`` receives the choice at position s. Between
    neighbouring positions the choice changes by at most ``max_step``, at ``step_cost`` per unit.
    The loop is closed by going round it twice and keeping the second round, by when the path no
    longer depends on where the first round began (dynamic programming, O(S D max_step)).
    """
    cdef Py_ssize_t S = cost.shape[0], D = cost.shape[1], rounds = 2 * S, s, d, j, src, best_d
    cdef double best, candidate
    if path.shape[0] != S:
        raise ValueError("path needs one entry per position of the loop")
    if S == 0 or D == 0:
        return
    if max_step < 0:
        raise ValueError("max_step must be >= 0")
    import numpy as np
    accumulated_np = np.empty(D, np.float64)
    following_np = np.empty(D, np.float64)
    back_np = np.empty((rounds, D), np.intp)
    cdef double[::1] accumulated = accumulated_np
    cdef double[::1] following = following_np
    cdef Py_ssize_t[:, ::1] back = back_np
    with nogil:
        for d in range(D):
            accumulated[d] = cost[0, d]
            back[0, d] = d
        for s in range(1, rounds):
            for d in range(D):
                best = 1e300
                best_d = d
                for j in range(-max_step, max_step + 1):
                    src = d - j
                    if src < 0 or src >= D:
                        continue
                    candidate = accumulated[src] + step_cost * (j if j >= 0 else -j)
                    if candidate < best:
                        best = candidate
                        best_d = src
                following[d] = best + cost[s % S, d]
                back[s, d] = best_d
            for d in range(D):
                accumulated[d] = following[d]
        best_d = 0
        for d in range(1, D):
            if accumulated[d] < accumulated[best_d]:
                best_d = d
        for s in range(rounds - 1, S - 1, -1):
            path[s - S] = best_d
            best_d = back[s, best_d]
