# cython: boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Kernels of core_cy.grasp: the candidates' nominal checks, the hull's points against them, and a
grasp's margins on perturbed copies of the model's sampled surface."""

from libc.math cimport acos, atan2, cos, erf, erfc, fabs, log, pow, sin, sqrt, INFINITY, NAN

from ._superquadric_cy cimport _level

import numpy as np


cdef enum:
    _MAX_GRID = 32  # samples across or along a finger's face
    _MAX_SAMPLES = 2 * _MAX_GRID * _MAX_GRID


cdef inline double _clip_unit(double v) noexcept nogil:
    return -1.0 if v < -1.0 else (1.0 if v > 1.0 else v)


cdef inline double _ratio(double power, double base) noexcept nogil:
    """``base ** (a - 1)`` from ``power = base ** a`` (a > 1, base >= 0): one pow call fewer."""
    return power / base if base > 0 else 0.0


cdef inline double _power(double p, double e1, double e2, int axis) noexcept nogil:
    """The inside-outside function's term of a coordinate: p ** (2 / e), e = e1 on frame axis 2."""
    return pow(p, 2 / e1) if axis == 2 else pow(p, 2 / e2)


cdef inline double _chord(const double* s, double e1, double e2, int k, double* p, double* g) noexcept nogil:
    """Half-chord along axis k (scaled by s[k]) of the superquadric with semi-axes s at the
    point p (absolute values divided by the sizes; p[k] ignored, then set); NaN where the
    line misses, else g is the outward normal (unnormalised, first octant)."""
    cdef double P[3]
    cdef int c
    for c in range(3):
        if c != k:
            P[c] = _power(p[c], e1, e2, c)
    return _chord_of(s, e1, e2, k, p, P, _level_term(P[2], e1, e2), g)


cdef inline double _level_term(double P2, double e1, double e2) noexcept nogil:
    """(1 - P2) ** (e1 / e2): where the superquadric's section at the height of term P2 ends
    (NaN above the top)."""
    return pow(1 - P2, e1 / e2) if P2 < 1 else NAN


cdef inline double _chord_of(const double* s, double e1, double e2, int k, double* p, double* P,
                             double level, double* g) noexcept nogil:
    """:func:`_chord` given the terms P[c] = :func:`_power` of p[c] for c != k (P[k] is set)
    and, for k != 2, level = :func:`_level_term` of P[2].

    The terms are reused for the normal (pow is most of the cost here)."""
    cdef double S, B, h, common
    if k == 2:
        S = P[0] + P[1]
        if not S < 1:
            return NAN
        common = pow(S, e2 / e1)
        B = 1 - common
        if not B > 0:
            return NAN
        h = pow(B, e1 / 2)
        common = common / S if S > 0 else 0.0  # S ** (e2 / e1 - 1)
    else:
        if not P[2] < 1:
            return NAN
        B = level - P[1 - k]
        if not B > 0:
            return NAN
        h = pow(B, e2 / 2)
        # (P[0] + P[1]) ** (e2 / e1 - 1), with P[0] + P[1] = level on the surface.
        common = (1 - P[2]) / level
    P[k] = B  # h ** (2 / e)
    p[k] = h
    g[0] = common * _ratio(P[0], p[0]) / s[0]
    g[1] = common * _ratio(P[1], p[1]) / s[1]
    g[2] = _ratio(P[2], p[2]) / s[2]
    return h * s[k]


cdef inline double _half_chord(const double* s, double e1, double e2, int k, const double* u,
                               double* normal) noexcept nogil:
    """Half the chord along axis k of the centred superquadric with semi-axes s at the point
    u (frame coordinates, u[k] ignored); NaN where the line misses, else normal is the unit
    outward normal at the surface point whose k coordinate is +half, the others u's."""
    cdef double p[3]
    cdef double g[3]
    cdef double h, length
    cdef int c
    for c in range(3):
        p[c] = fabs(u[c]) / s[c]
    h = _chord(s, e1, e2, k, p, g)
    if h != h:
        normal[0], normal[1], normal[2] = 0.0, 0.0, 0.0
        return h
    for c in range(3):
        if c != k and u[c] < 0:
            g[c] = -g[c]
    length = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
    for c in range(3):
        normal[c] = g[c] / length if length > 0 else 0.0
    return h


cdef inline double _min(double a, double b) noexcept nogil:
    return a if a < b else b


def nominal_margins(const double[:, ::1] sizes not None, const double[:, ::1] shape not None,
                    const long[:, ::1] axes not None, const double[::1] slide not None,
                    const double[::1] hull_near not None, const double[::1] column not None,
                    const double[:, ::1] plane_height not None, bint on_plane,
                    double finger_length, double pad_length, double half_open, double half_finger_width,
                    double palm_clearance, double table_clearance, double cone, double length, double angle,
                    double[:, ::1] depth not None, double[:, ::1] dz not None, double[:, ::1] half not None,
                    double[:, :, ::1] margins not None, unsigned char[:, ::1] ok not None):
    """Closed-form checks of each candidate at its four depths.

    sizes (M, 3), shape (M, 2) the candidate's model in its frame (frame axis 2 carries e1);
    axes (M, 3) its closing, approach and across axes; slide (M,) its offset along the
    grasp's x; hull_near (M,) and column (M,) the hull's nearest point towards the palm
    across the palm and between the fingers (grasp z about the model's centre).
    plane_height (M, 3), read if on_plane: the grasp origin's height above the support
    plane at the model's centre, the plane normal's grasp z, and the lowest gripper
    corner's height relative to the grasp origin.
    Writes, per candidate and depth (the pads' centre just inside, halfway, the deepest the
    palm and the plane allow, on the model's widest section): depth (M, 4) past the model's
    near side, dz (M, 4) of the grasp origin from the centre along the approach, half (M, 4)
    the model's half-width between the pads, margins (M, 4, 4) in standard errors (open
    jaws, palm, origin inside, friction cone; -1 where the jaws miss the model), and
    ok (M, 4) 1 where every check passes.
    """
    cdef Py_ssize_t row, d
    cdef double s[3]
    cdef double u[3]
    cdef double normal[3]
    cdef double s_j, near, deepest, shallowest, limit, height, nz, lowest, tilt, palm, h
    cdef double depths[4]
    cdef int i, j, k, c
    cdef bint passes
    with nogil:
        for row in range(sizes.shape[0]):
            i, j, k = <int>axes[row, 0], <int>axes[row, 1], <int>axes[row, 2]
            for c in range(3):
                s[c] = sizes[row, c]
                u[c] = 0.0
            # The model's near side between the fingers (where they slid to), and across the palm.
            u[k] = fabs(slide[row]) - half_finger_width
            if u[k] < 0:
                u[k] = 0.0
            s_j = _half_chord(s, shape[row, 0], shape[row, 1], j, u, normal)
            if s_j != s_j:
                s_j = -INFINITY
            near = _min(-s[j], hull_near[row])  # the hull's, if nearer
            deepest = _min(finger_length - palm_clearance + s_j + near, 2 * s_j + pad_length / 2)
            height, nz, lowest = plane_height[row, 0], plane_height[row, 1], plane_height[row, 2]
            if on_plane and nz < -1e-9:
                # The lowest corner at reach e: height + (e - pad/2 - s_j) nz + lowest >= clearance.
                limit = (height + lowest - table_clearance) / -nz + pad_length / 2 + s_j
                deepest = _min(deepest, limit)
            # The grasp's origin (the pads' centre) lies inside the object, with a margin.
            shallowest = pad_length / 2 + length
            depths[0], depths[1], depths[2] = shallowest, (shallowest + deepest) / 2, deepest
            h = s_j + pad_length / 2  # the pads centred on the model's widest section
            depths[3] = _min(h if h > shallowest else shallowest, deepest)
            for d in range(4):
                depth[row, d] = depths[d]
                dz[row, d] = depths[d] - pad_length / 2 - s_j
                passes = deepest >= shallowest and s_j > 0
                # The hull holds the object: between the fingers it must reach the model's near
                # side (else the model claims more than the views saw), and past the pads' centre.
                passes = passes and column[row] <= -s_j + 0.5 * length and column[row] < dz[row, d]
                if on_plane:
                    passes = passes and height + dz[row, d] * nz + lowest >= table_clearance * 0.999
                # The widest chord the fingers meet: nearest the centre, within their reach.
                u[j] = _min(0.0, depths[d] - s_j)
                h = _half_chord(s, shape[row, 0], shape[row, 1], i, u, normal)
                half[row, d] = h
                tilt = atan2(fabs(normal[j]), normal[i])
                palm = depths[d] - s_j - finger_length  # along the approach from the centre
                margins[row, d, 0] = (half_open - h) / length
                margins[row, d, 1] = (near - palm) / length
                margins[row, d, 2] = (depths[d] - pad_length / 2) / length
                margins[row, d, 3] = (cone - tilt) / angle
                for c in range(4):
                    if margins[row, d, c] != margins[row, d, c]:
                        margins[row, d, c] = -1.0
                    passes = passes and margins[row, d, c] > 0
                ok[row, d] = passes


def surface_samples(const double[:, ::1] sizes not None, const double[:, :, ::1] shapes not None,
                    const long[:, ::1] axes not None, const double[:, ::1] across not None,
                    const double[:, ::1] along not None,
                    double[:, :, :, ::1] points not None, double[:, :, :, ::1] normals not None,
                    unsigned char[:, :, ::1] valid not None):
    """The surface facing each finger, sampled on a grid, in the model's frame.

    sizes (M, 3); shapes (V, M, 2) the exponent variants; axes (M, 3) the frame axes of
    closing, approach and across; across (M, A) and along (M, W) the grid's frame
    coordinates on the across and approach axes. Writes points and unit normals
    (V, M, 2N, 3), N = A W: the first N on the +closing side, the last N mirrored; valid
    (V, M, 2N) 1 where the closing line meets the model.
    """
    cdef Py_ssize_t V = shapes.shape[0], M = sizes.shape[0], A = across.shape[1], W = along.shape[1]
    cdef Py_ssize_t N = A * W, v, m, a, w, n, c
    cdef double s[3]
    cdef double p[3]
    cdef double g[3]
    cdef double q[3]
    cdef double P[3]
    # The terms of the grid's across and along coordinates, once per model (pow is costly).
    cdef double across_terms[_MAX_GRID]
    cdef double along_terms[_MAX_GRID]
    cdef double across_levels[_MAX_GRID]
    cdef double along_levels[_MAX_GRID]
    cdef double h, length, e1, e2
    cdef int i, j, k
    if A > _MAX_GRID or W > _MAX_GRID:
        raise ValueError(f"at most {_MAX_GRID} grid samples across and along, got {A} and {W}")
    with nogil:
        for v in range(V):
            for m in range(M):
                i, j, k = <int>axes[m, 0], <int>axes[m, 1], <int>axes[m, 2]
                e1, e2 = shapes[v, m, 0], shapes[v, m, 1]
                for c in range(3):
                    s[c] = sizes[m, c]
                for a in range(A):
                    across_terms[a] = _power(fabs(across[m, a]) / s[k], e1, e2, k)
                    across_levels[a] = _level_term(across_terms[a], e1, e2) if k == 2 else 0.0
                for w in range(W):
                    along_terms[w] = _power(fabs(along[m, w]) / s[j], e1, e2, j)
                    along_levels[w] = _level_term(along_terms[w], e1, e2) if j == 2 else 0.0
                for a in range(A):
                    for w in range(W):
                        n = a * W + w
                        q[i], q[j], q[k] = 0.0, along[m, w], across[m, a]
                        for c in range(3):
                            p[c] = fabs(q[c]) / s[c]
                        P[j], P[k] = along_terms[w], across_terms[a]
                        h = _chord_of(s, e1, e2, i, p, P, across_levels[a] if k == 2 else along_levels[w], g)
                        if h != h:
                            valid[v, m, n], valid[v, m, N + n] = 0, 0
                            for c in range(3):
                                points[v, m, n, c], points[v, m, N + n, c] = 0.0, 0.0
                                normals[v, m, n, c], normals[v, m, N + n, c] = 0.0, 0.0
                            continue
                        q[i] = h
                        for c in range(3):
                            if c != i and q[c] < 0:
                                g[c] = -g[c]
                        length = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
                        for c in range(3):
                            points[v, m, n, c] = q[c]
                            points[v, m, N + n, c] = -q[c] if c == i else q[c]
                            normals[v, m, n, c] = g[c] / length
                            normals[v, m, N + n, c] = -g[c] / length if c == i else g[c] / length
                        valid[v, m, n], valid[v, m, N + n] = 1, 1


def perturbed_margins(const double[:, :, :, ::1] points not None,
                      const double[:, :, :, ::1] normals not None,
                      const unsigned char[:, :, ::1] valid not None,
                      const double[:, :, ::1] shapes not None,
                      const double[:, ::1] sizes not None,
                      const double[:, :, ::1] frame not None,
                      const long[::1] variant not None,
                      const double[:, :, ::1] scale not None,
                      const double[:, :, ::1] turns not None,
                      const long[::1] rotation_set not None,
                      const double[:, :, ::1] axes not None,
                      const double[:, ::1] shift not None,
                      const double[:, ::1] centre not None,
                      const double[::1] hull not None,
                      double half_width, double palm, double tip, double half_open,
                      double compliance, double cone, double length, double angle,
                      double[:, ::1] work not None,
                      double[:, :, ::1] turned not None,
                      double[:, :, :, ::1] rotations not None,
                      double[::1] score not None):
    """How often each grasp holds under the perturbations of its model: the mean over them
    of the product over its margins m (in standard errors) of the normal CDF of 4 m.

    points, normals : (V, M, 2N, 3) surface samples of grasp m's model (exponent variant
        v), in the model's frame about its centre: the first N face the +y finger, the
        last N the -y one; valid (V, M, 2N) 1 where a sample exists.
    shapes : (V, M, 2) the variants' exponents (e1, e2); sizes (M, 3) the model's
        semi-axes, in its frame (frame axis 2 carries e1).
    frame : (M, 3, 3) model-frame to grasp-frame rotation of each grasp.
    variant : (P,) exponent variant of each perturbation; scale (P, M, 3) stretch of the
        model about its centre along the grasp axes.
    turns : (K, P, 3) the perturbations' turns about the centre (rotation vectors), in a
        frame in which grasp m's axes are the columns of axes[m] (M, 3, 3); rotation_set
        (M,) which of the K sets grasp m takes.
    shift : (P, 3) of the centre, grasp axes; centre (M, 3) the model's centre in each
        grasp frame; hull (M,) the hull's nearest point towards the palm, grasp z.
    length, angle : the standard errors the margins are counted in.
    work : (2N, 3), turned : (V, 2N, 6) and rotations (K, P, 3, 3) scratch.
    score : (M,) written. The margins: open jaws clear (half_open less the farthest
        touch), palm clear (of the perturbed model's nearest point, by its support
        function, and of the hull), the pads' centre line meets the object (minus the
        sampled surface's lowest z across the fingers' width, at most 10), and antipodal
        (the cone less the contacts' worst angle off the line between them, in
        ``angle``). The first and the last are -1 where a finger does not reach the object.
    """
    cdef Py_ssize_t n_grasps = points.shape[1], n_samples = points.shape[2], half = n_samples // 2
    cdef Py_ssize_t n_perturbations = variant.shape[0]
    cdef Py_ssize_t a, b, k, v, side
    cdef double dx, dy, dz, qx, qy, qz, sx, sy, sz, ext
    cdef double top, bottom, near, nx, ny, nz, norm, line_x, line_y, line_z
    cdef double cx[2]
    cdef double cy[2]
    cdef double cz[2]
    cdef double mx[2]
    cdef double my[2]
    cdef double mz[2]
    cdef double count[2]
    cdef double angle1, angle2, w0, w1, w2, e1, e2, p, q, support, nearest
    cdef double r[3][3]
    cdef double t[3][3]
    cdef double ox, oy, oz
    cdef bint reached_up, reached_down
    cdef Py_ssize_t n_variants = points.shape[0], i, c, j, n, touching
    cdef double* sample
    cdef Py_ssize_t[_MAX_SAMPLES] touch
    if n_samples > _MAX_SAMPLES:
        raise ValueError(f"at most {_MAX_SAMPLES} surface samples per grasp, got {n_samples}")
    cdef double margin[4]
    cdef double holds
    with nogil:
        for i in range(turns.shape[0]):
            for b in range(n_perturbations):
                _rodrigues(&turns[i, b, 0], &rotations[i, b, 0, 0])
        for a in range(n_grasps):
            score[a] = 0.0
            # The samples and their normals in the grasp's axes, once per grasp.
            for v in range(n_variants):
                for k in range(n_samples):
                    if not valid[v, a, k]:
                        continue
                    for c in range(3):
                        turned[v, k, c] = (frame[a, c, 0] * points[v, a, k, 0] + frame[a, c, 1] * points[v, a, k, 1]
                                           + frame[a, c, 2] * points[v, a, k, 2])
                        turned[v, k, 3 + c] = (frame[a, c, 0] * normals[v, a, k, 0]
                                               + frame[a, c, 1] * normals[v, a, k, 1]
                                               + frame[a, c, 2] * normals[v, a, k, 2])
            for b in range(n_perturbations):
                v = variant[b]
                sx, sy, sz = scale[b, a, 0], scale[b, a, 1], scale[b, a, 2]
                # The turn in the grasp's axes: axes^T W axes.
                for i in range(3):
                    for c in range(3):
                        t[i][c] = 0.0
                        for j in range(3):
                            t[i][c] += axes[a, j, i] * rotations[rotation_set[a], b, j, c]
                for i in range(3):
                    for c in range(3):
                        r[i][c] = 0.0
                        for j in range(3):
                            r[i][c] += t[i][j] * axes[a, j, c]
                ox, oy, oz = centre[a, 0] + shift[b, 0], centre[a, 1] + shift[b, 1], centre[a, 2] + shift[b, 2]
                # The perturbed model's nearest point towards the palm: its support function in
                # the direction frame^T (scale * r^T e_z), in the model's frame.
                w0, w1, w2 = sx * r[2][0], sy * r[2][1], sz * r[2][2]
                e1, e2 = shapes[v, a, 0], shapes[v, a, 1]
                p, q = 2 / (2 - e2), 2 / (2 - e1)
                dx = fabs((frame[a, 0, 0] * w0 + frame[a, 1, 0] * w1 + frame[a, 2, 0] * w2) * sizes[a, 0])
                dy = fabs((frame[a, 0, 1] * w0 + frame[a, 1, 1] * w1 + frame[a, 2, 1] * w2) * sizes[a, 1])
                dz = fabs((frame[a, 0, 2] * w0 + frame[a, 1, 2] * w1 + frame[a, 2, 2] * w2) * sizes[a, 2])
                support = pow(pow(pow(dx, p) + pow(dy, p), q / p) + pow(dz, q), 1 / q)
                nearest = oz - support
                if hull[a] < nearest:
                    nearest = hull[a]
                margin[1] = (nearest - palm) / length
                top, bottom, near = -INFINITY, -INFINITY, INFINITY
                reached_up, reached_down = False, False
                touching = 0
                sample = &turned[v, 0, 0]
                for k in range(n_samples):
                    if not valid[v, a, k]:
                        continue
                    dx, dy, dz = sample[6 * k] * sx, sample[6 * k + 1] * sy, sample[6 * k + 2] * sz
                    qx = ox + r[0][0] * dx + r[0][1] * dy + r[0][2] * dz
                    if fabs(qx) > half_width:
                        continue
                    qz = oz + r[2][0] * dx + r[2][1] * dy + r[2][2] * dz
                    if qz < near:
                        near = qz
                    if qz < palm or qz > tip:
                        continue
                    qy = oy + r[1][0] * dx + r[1][1] * dy + r[1][2] * dz
                    # Within the pads' reach: kept for the contacts.
                    touch[touching] = k
                    touching += 1
                    work[k, 0], work[k, 1], work[k, 2] = qx, qy, qz
                    if k < half:
                        reached_up = True
                        if qy > top:
                            top = qy
                    else:
                        reached_down = True
                        if -qy > bottom:
                            bottom = -qy
                margin[2] = -near / length
                if margin[2] > 10.0:
                    margin[2] = 10.0
                if not (reached_up and reached_down):
                    margin[0], margin[3] = -1.0, -1.0
                    score[a] += _holds(margin)
                    continue
                for side in range(2):
                    cx[side], cy[side], cz[side] = 0.0, 0.0, 0.0
                    mx[side], my[side], mz[side] = 0.0, 0.0, 0.0
                    count[side] = 0.0
                for n in range(touching):
                    k = touch[n]
                    side = 0 if k < half else 1
                    ext = top - work[k, 1] if side == 0 else bottom + work[k, 1]
                    if ext > compliance:
                        continue
                    # The normal: inverse-stretched, turned, normalised.
                    dx, dy, dz = sample[6 * k + 3] / sx, sample[6 * k + 4] / sy, sample[6 * k + 5] / sz
                    nx = r[0][0] * dx + r[0][1] * dy + r[0][2] * dz
                    ny = r[1][0] * dx + r[1][1] * dy + r[1][2] * dz
                    nz = r[2][0] * dx + r[2][1] * dy + r[2][2] * dz
                    norm = sqrt(nx * nx + ny * ny + nz * nz)
                    if norm > 0:
                        mx[side] += nx / norm
                        my[side] += ny / norm
                        mz[side] += nz / norm
                    cx[side] += work[k, 0]
                    cy[side] += work[k, 1]
                    cz[side] += work[k, 2]
                    count[side] += 1.0
                line_x = cx[0] / count[0] - cx[1] / count[1]
                line_y = cy[0] / count[0] - cy[1] / count[1]
                line_z = cz[0] / count[0] - cz[1] / count[1]
                norm = sqrt(line_x * line_x + line_y * line_y + line_z * line_z)
                angle1, angle2 = 3.141592653589793, 3.141592653589793
                if norm > 0:
                    line_x, line_y, line_z = line_x / norm, line_y / norm, line_z / norm
                    norm = sqrt(mx[0] * mx[0] + my[0] * my[0] + mz[0] * mz[0])
                    if norm > 0:
                        angle1 = acos(_clip_unit((mx[0] * line_x + my[0] * line_y + mz[0] * line_z) / norm))
                    norm = sqrt(mx[1] * mx[1] + my[1] * my[1] + mz[1] * mz[1])
                    if norm > 0:
                        angle2 = acos(_clip_unit(-(mx[1] * line_x + my[1] * line_y + mz[1] * line_z) / norm))
                margin[0] = (half_open - (top if top > bottom else bottom)) / length
                margin[3] = (cone - (angle1 if angle1 > angle2 else angle2)) / angle
                score[a] += _holds(margin)
            score[a] /= n_perturbations


cdef inline double _ndtr(double a) noexcept nogil:
    """The standard normal CDF (as scipy.special.ndtr computes it, with the C library's erf)."""
    cdef double x = a * 0.7071067811865476, y
    if a != a:
        return a
    if fabs(x) < 0.7071067811865476:
        return 0.5 + 0.5 * erf(x)
    y = 0.5 * erfc(fabs(x))
    return 1.0 - y if x > 0 else y


cdef inline double _holds(const double* margin) noexcept nogil:
    """The smoothed "holds" of four margins in standard errors: the product of ndtr(4 m)."""
    return _ndtr(4 * margin[0]) * _ndtr(4 * margin[1]) * _ndtr(4 * margin[2]) * _ndtr(4 * margin[3])


cdef inline void _rodrigues(const double* vector, double* R) noexcept nogil:
    """R (3 x 3, row-major): the rotation by the rotation vector (axis times angle)."""
    cdef double theta = sqrt(vector[0] * vector[0] + vector[1] * vector[1] + vector[2] * vector[2])
    cdef double K[9]
    cdef double x, y, z, sine = sin(theta), versine = 1 - cos(theta)
    cdef int i, j
    x, y, z = (vector[0] / theta, vector[1] / theta, vector[2] / theta) if theta > 1e-300 else (0.0, 0.0, 0.0)
    K[0], K[1], K[2] = 0.0, -z, y
    K[3], K[4], K[5] = z, 0.0, -x
    K[6], K[7], K[8] = -y, x, 0.0
    for i in range(3):
        for j in range(3):
            R[3 * i + j] = ((1.0 if i == j else 0.0) + sine * K[3 * i + j]
                            + versine * (K[3 * i] * K[j] + K[3 * i + 1] * K[3 + j] + K[3 * i + 2] * K[6 + j]))


cdef inline void _load(const double[:, :, ::1] R, Py_ssize_t m, double* r) noexcept nogil:
    """Grasp m's axes (the columns of R[m]) into r (9,), row by row, once per grasp."""
    cdef int c
    for c in range(9):
        r[c] = R[m, c // 3, c % 3]


cdef inline void _to_grasp(const double* r, double dx, double dy, double dz,
                           double* x, double* y, double* z) noexcept nogil:
    """(dx, dy, dz) in the axes r (from :func:`_load`)."""
    x[0] = dx * r[0] + dy * r[3] + dz * r[6]
    y[0] = dx * r[1] + dy * r[4] + dz * r[7]
    z[0] = dx * r[2] + dy * r[5] + dz * r[8]


def hull_reach(const double[:, ::1] offsets not None, const double[:, :, ::1] R not None,
               const double[::1] slide not None, const long[::1] by_axes not None,
               double palm_half_width, double palm_half_span, double finger_half_width, double half_open,
               double[:, ::1] local not None, double[::1] nearest not None, double[::1] column not None):
    """The hull's nearest points along each candidate's approach.

    offsets (P, 3) the hull's points less the model's centre; R (M, 3, 3) the grasp axes
    (columns); slide (M,) each candidate's offset along its x; by_axes (M,) the candidates
    ordered so that those with the same axes (slides of one grasp) follow each other:
    the points are turned once for them. Writes, in each candidate's axes about the
    centre, the lowest z (+inf if none) of the points within the palm's footprint
    (|x - slide| <= palm_half_width, |y| <= palm_half_span) into nearest (M,), and of those
    between the fingers (|x - slide| <= finger_half_width, |y| <= half_open) into column (M,).
    local (P, 3) is scratch.
    """
    cdef Py_ssize_t t, m, previous = -1, p, n_points = offsets.shape[0]
    cdef double x, y, z, near, col
    cdef double r[9]
    cdef bint same
    cdef int c
    with nogil:
        for t in range(by_axes.shape[0]):
            m = by_axes[t]
            same = previous >= 0
            for c in range(9):
                same = same and R[m, c // 3, c % 3] == R[previous, c // 3, c % 3]
            if not same:
                _load(R, m, r)
                for p in range(n_points):
                    _to_grasp(r, offsets[p, 0], offsets[p, 1], offsets[p, 2], &local[p, 0], &local[p, 1], &local[p, 2])
            previous = m
            near, col = INFINITY, INFINITY
            for p in range(n_points):
                x = fabs(local[p, 0] - slide[m])
                y = fabs(local[p, 1])
                z = local[p, 2]
                if x <= palm_half_width and y <= palm_half_span and z < near:
                    near = z
                if x <= finger_half_width and y <= half_open and z < col:
                    col = z
            nearest[m], column[m] = near, col


def in_open_fingers(const double[:, ::1] offsets not None, const double[:, :, ::1] R not None,
                    const double[:, ::1] origin not None, double finger_half_width, double palm, double tip,
                    double half_open, double finger_thickness, unsigned char[::1] hit not None):
    """Whether any point lies where an open finger of a grasp goes.

    offsets (P, 3) the points less the model's centre; R (M, 3, 3) the grasp axes; origin
    (M, 3) each grasp's origin in its axes about the centre. Writes hit (M,): 1 where a point
    has |x| <= finger_half_width, palm <= z <= tip and half_open <= |y| <= half_open +
    finger_thickness in the grasp frame, else 0.
    """
    cdef Py_ssize_t m, p, n_points = offsets.shape[0]
    cdef double x, y, z
    cdef double r[9]
    with nogil:
        for m in range(R.shape[0]):
            hit[m] = 0
            _load(R, m, r)
            for p in range(n_points):
                _to_grasp(r, offsets[p, 0], offsets[p, 1], offsets[p, 2], &x, &y, &z)
                x, y, z = fabs(x - origin[m, 0]), fabs(y - origin[m, 1]), z - origin[m, 2]
                if (x <= finger_half_width and z >= palm and z <= tip and y >= half_open
                        and y <= half_open + finger_thickness):
                    hit[m] = 1
                    break


def pad_extent(const double[:, ::1] offsets not None, const double[:, :, ::1] R not None,
               const double[:, ::1] origin not None, double finger_half_width, double pad_half_length,
               double half_span, double[:, ::1] extent not None):
    """The points' extent along the closing axis under each grasp's pads.

    offsets (P, 3) the points less the model's centre; R (M, 3, 3) the grasp axes; origin
    (M, 3) each grasp's origin in its axes about the centre. Of the points with |x| <=
    finger_half_width, |z| <= pad_half_length and |y| <= half_span in the grasp frame, writes
    extent (M, 3): the largest y, the largest -y (both -inf if none) and their count.
    """
    cdef Py_ssize_t m, p, n_points = offsets.shape[0]
    cdef double x, y, z, top, bottom, count
    cdef double r[9]
    with nogil:
        for m in range(R.shape[0]):
            top, bottom, count = -INFINITY, -INFINITY, 0.0
            _load(R, m, r)
            for p in range(n_points):
                _to_grasp(r, offsets[p, 0], offsets[p, 1], offsets[p, 2], &x, &y, &z)
                x, y, z = x - origin[m, 0], y - origin[m, 1], z - origin[m, 2]
                if fabs(x) <= finger_half_width and fabs(z) <= pad_half_length and fabs(y) <= half_span:
                    count += 1.0
                    if y > top:
                        top = y
                    if -y > bottom:
                        bottom = -y
            extent[m, 0], extent[m, 1], extent[m, 2] = top, bottom, count


def in_finger_path(const double[:, ::1] offsets not None, const double[:, :, ::1] R not None,
                   const double[:, ::1] origin not None, const double[::1] half not None, double finger_half_width,
                   double palm, double tip, double half_open, double finger_thickness, double slack,
                   unsigned char[::1] hit not None):
    """Whether any point lies where a finger of a grasp goes, open or closing onto its part.

    offsets (P, 3) the points (of the other parts of a union) less the model's centre; R (M,
    3, 3) the grasp axes; origin (M, 3) each grasp's origin in its axes about the centre; half
    (M,) the half-width of the grasped part between the pads. Writes hit (M,): 1 where a
    point has |x| <= finger_half_width, palm <= z <= tip and half + slack <= |y| <= half_open
    + finger_thickness in the grasp frame (a finger would meet it first or cut it), else 0.
    """
    cdef Py_ssize_t m, p, n_points = offsets.shape[0]
    cdef double x, y, z
    cdef double r[9]
    if R.shape[0] != origin.shape[0] or R.shape[0] != half.shape[0] or R.shape[0] != hit.shape[0]:
        raise ValueError("R, origin, half and hit need one row per grasp")
    with nogil:
        for m in range(R.shape[0]):
            hit[m] = 0
            _load(R, m, r)
            for p in range(n_points):
                _to_grasp(r, offsets[p, 0], offsets[p, 1], offsets[p, 2], &x, &y, &z)
                x, y, z = fabs(x - origin[m, 0]), fabs(y - origin[m, 1]), z - origin[m, 2]
                if (x <= finger_half_width and z >= palm and z <= tip and y >= half[m] + slack
                        and y <= half_open + finger_thickness):
                    hit[m] = 1
                    break



cdef inline bint _in_union(double px, double py, double pz, const double[:, :, ::1] R, const double[:, ::1] t,
                           const double[:, ::1] box, const double[:, ::1] log_sizes, const double[:, ::1] shapes,
                           const double[::1] limit) noexcept nogil:
    """Whether the point lies inside a part taken some factor times as large (see union_inside), with
    what :func:`_part_constants` made of the parts for that factor."""
    cdef Py_ssize_t p
    cdef double x, y, z
    for p in range(R.shape[0]):
        x = fabs(R[p, 0, 0] * px + R[p, 0, 1] * py + R[p, 0, 2] * pz + t[p, 0])
        y = fabs(R[p, 1, 0] * px + R[p, 1, 1] * py + R[p, 1, 2] * pz + t[p, 1])
        z = fabs(R[p, 2, 0] * px + R[p, 2, 1] * py + R[p, 2, 2] * pz + t[p, 2])
        if x > box[p, 0] or y > box[p, 1] or z > box[p, 2]:
            continue  # outside the part's box: outside the part
        if _level(x, y, z, log_sizes[p, 0], log_sizes[p, 1], log_sizes[p, 2], shapes[p, 0], shapes[p, 1]) < limit[p]:
            return True
    return False


def _part_constants(const double[:, ::1] sizes, const double[:, ::1] shapes, double factor):
    """What :func:`_in_union` asks of each part at every sample, made once per call (with the C
    library's log and pow, as it made them at every sample before): its box taken ``factor`` times
    as large (P, 3), the logs of its sizes (P, 3), and the level below which a point is inside it
    taken so (P,)."""
    cdef Py_ssize_t p, k, count = sizes.shape[0]
    box, log_sizes, limit = np.empty((count, 3)), np.empty((count, 3)), np.empty(count)
    cdef double[:, ::1] box_view = box
    cdef double[:, ::1] log_view = log_sizes
    cdef double[::1] limit_view = limit
    for p in range(count):
        for k in range(3):
            box_view[p, k] = sizes[p, k] * factor
            log_view[p, k] = log(sizes[p, k])
        limit_view[p] = pow(factor, 2.0 / shapes[p, 0])
    return box, log_sizes, limit


def union_inside(const double[:, ::1] points not None, const double[:, :, ::1] R not None,
                 const double[:, ::1] t not None, const double[:, ::1] sizes not None,
                 const double[:, ::1] shapes not None, double factor):
    """Whether any point lies inside the union of superquadrics each taken ``factor`` times as large.

    points (N, 3) in some frame; part p maps them into its own frame as ``R[p] @ x + t[p]``; sizes
    (P, 3), shapes (P, 2). A point is inside part p where its inside-outside value (evaluated as
    core_cy.superquadric.inside_outside does) is below ``factor ** (2 / e1)``: F scales with the
    size as ``F(x; s a) = s ** (-2 / e1) F(x; a)``. Only a point inside the part's box, taken
    ``factor`` times as large, can be inside it, so F is evaluated there alone.
    """
    cdef Py_ssize_t i
    cdef bint found = False
    cdef const double[:, ::1] box
    cdef const double[:, ::1] log_sizes
    cdef const double[::1] limit
    box, log_sizes, limit = _part_constants(sizes, shapes, factor)
    with nogil:
        for i in range(points.shape[0]):
            if _in_union(points[i, 0], points[i, 1], points[i, 2], R, t, box, log_sizes, shapes, limit):
                found = True
                break
    return found


def line_extents(const double[:, :, ::1] lines not None, const double[:, :, ::1] R not None,
                 const double[:, ::1] t not None, const double[:, ::1] sizes not None,
                 const double[:, ::1] shapes not None, double factor, Py_ssize_t[:, ::1] extents not None):
    """The first and last sample of each line inside the union (see :func:`union_inside`).

    lines (C, L, 3): C lines of L samples each. Writes extents (C, 2): the indices of the first and
    the last sample inside, or -1, -1 where none is. Each line is walked in from both ends and
    stops at the union, so only the samples outside it are evaluated, and one inside at each end.
    """
    cdef Py_ssize_t c, j, first, last, n = lines.shape[1]
    cdef const double[:, ::1] box
    cdef const double[:, ::1] log_sizes
    cdef const double[::1] limit
    box, log_sizes, limit = _part_constants(sizes, shapes, factor)
    with nogil:
        for c in range(lines.shape[0]):
            first, last = -1, -1
            for j in range(n):
                if _in_union(lines[c, j, 0], lines[c, j, 1], lines[c, j, 2], R, t, box, log_sizes, shapes, limit):
                    first = j
                    break
            if first >= 0:
                for j in range(n - 1, first - 1, -1):
                    if _in_union(lines[c, j, 0], lines[c, j, 1], lines[c, j, 2], R, t, box, log_sizes, shapes,
                                 limit):
                        last = j
                        break
            extents[c, 0], extents[c, 1] = first, last
