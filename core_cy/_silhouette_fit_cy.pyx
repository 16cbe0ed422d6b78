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


cdef inline double _signed_power(double c, double e) noexcept nogil:
    cdef double m = fabs(c)
    if m < _TINY:
        return 0.0
    return exp(e * log(m)) if c > 0 else -exp(e * log(m))


def surface(const double[::1] size not None, const double[::1] shape not None,
            const double[:, ::1] R not None, const double[::1] t not None,
            const double[::1] eta not None, const double[::1] omega not None, double[:, ::1] out not None):
    """World points of the surface on the grid ``eta`` x ``omega`` (signed-power parametrisation),
    then its two poles: ``out`` is ``(len(eta) * len(omega) + 2, 3)``."""
    cdef Py_ssize_t n_eta = eta.shape[0], n_omega = omega.shape[0], i, j, k, row
    cdef double ce, se
    cdef double p[3]
    cdef double[::1] co = np.empty(n_omega), so = np.empty(n_omega)
    if out.shape[0] != n_eta * n_omega + 2 or out.shape[1] != 3:
        raise ValueError("out must be (len(eta) * len(omega) + 2, 3)")
    with nogil:
        for j in range(n_omega):
            co[j] = size[0] * _signed_power(cos(omega[j]), shape[1])
            so[j] = size[1] * _signed_power(sin(omega[j]), shape[1])
        for i in range(n_eta):
            ce = _signed_power(cos(eta[i]), shape[0])
            se = size[2] * _signed_power(sin(eta[i]), shape[0])
            for j in range(n_omega):
                p[0] = ce * co[j]
                p[1] = ce * so[j]
                row = i * n_omega + j
                for k in range(3):
                    out[row, k] = t[k] + R[k, 0] * p[0] + R[k, 1] * p[1] + R[k, 2] * se
        for k in range(3):
            out[n_eta * n_omega, k] = t[k] - R[k, 2] * size[2]
            out[n_eta * n_omega + 1, k] = t[k] + R[k, 2] * size[2]


def project(const double[:, ::1] points not None, const double[:, ::1] projection not None,
            float[:, ::1] out not None):
    """Pixel coordinates of world points through a (3, 4) projection; False if any lies behind the camera."""
    cdef Py_ssize_t n = points.shape[0], i
    cdef double hx, hy, hz
    cdef bint in_front = True
    if out.shape[0] != n or out.shape[1] != 2 or points.shape[1] != 3:
        raise ValueError("points must be (N, 3) and out (N, 2)")
    with nogil:
        for i in range(n):
            hz = (projection[2, 0] * points[i, 0] + projection[2, 1] * points[i, 1]
                  + projection[2, 2] * points[i, 2] + projection[2, 3])
            if hz <= 1e-12:
                in_front = False
                break
            hx = (projection[0, 0] * points[i, 0] + projection[0, 1] * points[i, 1]
                  + projection[0, 2] * points[i, 2] + projection[0, 3])
            hy = (projection[1, 0] * points[i, 0] + projection[1, 1] * points[i, 1]
                  + projection[1, 2] * points[i, 2] + projection[1, 3])
            out[i, 0] = <float>(hx / hz)
            out[i, 1] = <float>(hy / hz)
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
    cdef Py_ssize_t h = hull.shape[0], n = samples.shape[0], i, j, best_j
    cdef double ax, ay, ex, ey, length2, tau, qx, qy, dx, dy, d2, best, sign, area
    cdef double nx, ny, best_nx, best_ny, px, py, mc0, mc1, mc2, norm, s, r0, r1, r2, w0, w1, w2
    cdef bint outside
    if hull.shape[1] != 2 or h < 3:
        raise ValueError("hull must be (H, 2) with H >= 3")
    if samples.shape[1] != 2 or planes.shape[0] != n or planes.shape[1] != 9:
        raise ValueError("samples must be (N, 2) and planes (N, 9)")
    with nogil:
        area = 0.0
        for j in range(h):
            area += (hull[j, 0] * hull[(j + 1) % h, 1] - hull[(j + 1) % h, 0] * hull[j, 1])
        # Outward normal of edge (e_x, e_y): (e_y, -e_x) when the polygon runs clockwise on screen
        # (a positive shoelace area in these y-down coordinates), (-e_y, e_x) otherwise.
        sign = 1.0 if area > 0 else -1.0
        for i in range(n):
            px = samples[i, 0]
            py = samples[i, 1]
            best = 1e300
            best_nx = 0.0
            best_ny = 0.0
            best_j = 0
            for j in range(h):
                ax = hull[j, 0]
                ay = hull[j, 1]
                ex = hull[(j + 1) % h, 0] - ax
                ey = hull[(j + 1) % h, 1] - ay
                length2 = ex * ex + ey * ey
                if length2 <= 0:
                    continue
                tau = ((px - ax) * ex + (py - ay) * ey) / length2
                if tau < 0:
                    tau = 0.0
                elif tau > 1:
                    tau = 1.0
                qx = ax + tau * ex
                qy = ay + tau * ey
                dx = px - qx
                dy = py - qy
                d2 = dx * dx + dy * dy
                if d2 < best:
                    best = d2
                    best_j = j
                    norm = sqrt(length2)
                    nx = sign * ey / norm
                    ny = -sign * ex / norm
                    outside = nx * dx + ny * dy > 0
                    if (tau == 0.0 or tau == 1.0) and outside and d2 > 1e-12:
                        norm = sqrt(d2)
                        nx = dx / norm
                        ny = dy / norm
                    best_nx = nx
                    best_ny = ny
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
            # The ray's direction: K^-1 (p, 1) (upper-triangular K), turned into the world.
            r1 = (py - K[1, 2]) / K[1, 1]
            r0 = (px - K[0, 2] - K[0, 1] * r1) / K[0, 0]
            r2 = 1.0
            w0 = R[0, 0] * r0 + R[0, 1] * r1 + R[0, 2] * r2
            w1 = R[1, 0] * r0 + R[1, 1] * r1 + R[1, 2] * r2
            w2 = R[2, 0] * r0 + R[2, 1] * r1 + R[2, 2] * r2
            norm = sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            w0 /= norm
            w1 /= norm
            w2 /= norm
            planes[i, 5] = w1 * planes[i, 2] - w2 * planes[i, 1]
            planes[i, 6] = w2 * planes[i, 0] - w0 * planes[i, 2]
            planes[i, 7] = w0 * planes[i, 1] - w1 * planes[i, 0]
            planes[i, 8] = planes[i, 5] * centre[0] + planes[i, 6] * centre[1] + planes[i, 7] * centre[2]


cdef inline double _reach(const double* a, const double* e, const double* t, double R[3][3], const double* m,
                          double offset, double* v, double* dh_da, double* dh_de, double* dh_dv) noexcept nogil:
    """How far (world units) the superquadric reaches beyond the plane m . x = offset; v gets R^T m."""
    cdef int k
    for k in range(3):
        v[k] = R[0][k] * m[0] + R[1][k] * m[1] + R[2][k] * m[2]
    return m[0] * t[0] + m[1] * t[1] + m[2] * t[2] + _support(a, e, v, dh_da, dh_de, dh_dv) - offset


def normal_equations(const double[::1] x not None, const double[:, ::1] R0 not None,
                     const double[::1] t0 not None, double scale, const double[:, ::1] planes not None,
                     double loss_scale, const double[::1] support_plane not None, double plane_weight,
                     double tilt, double[:, ::1] JtJ not None, double[::1] Jtr not None, bint jacobian=True):
    """Robust cost of the samples' residuals and, with ``jacobian``, the Gauss-Newton normal equations.

    Residual of sample i: ``w_i (h(m) - m . c)``, how far (pixels) the
    superquadric reaches beyond the plane through its ray, h being its support
    function; positive where the sample lies inside the outline. The plane of
    :func:`tangent_planes` comes from a polygon outline; the tangent plane
    through the ray is the one of least reach, so the plane is turned about
    the ray by -``tilt``, 0 and ``tilt`` (radians), a parabola through the
    three reaches points to a fourth, and the least of them counts. The loss
    is ``c^2 (sqrt(1 + (r/c)^2) - 1)`` (c = ``loss_scale``, pixels):
    quadratic for small residuals, linear for large ones. With
    ``plane_weight > 0`` the superquadric's reach below ``support_plane`` (n,
    d; unit n; the object where n . x + d >= 0) is one more residual, times
    ``plane_weight``, under the same loss: the object stands on the plane,
    touching it. Fills ``JtJ`` (11, 11) with J^T W J and ``Jtr`` with J^T W r
    (W the IRLS weights of the loss) and returns the cost.
    """
    cdef Py_ssize_t n = planes.shape[0], i, j, k, q, rows
    cdef double R[3][3]
    cdef double dR[3][3][3]
    cdef double a[3]
    cdef double v[3]
    cdef double m[3]
    cdef double best_m[3]
    cdef double J[11]
    cdef double dh_da[3]
    cdef double dh_de[2]
    cdef double dh_dv[3]
    cdef double t[3]
    cdef double c2 = loss_scale * loss_scale, cost = 0.0, r, root, w, weight, offset, best_offset
    cdef double psi, cs, sn, reach, best, r_minus, r_zero, r_plus, curvature
    cdef double angles[3]
    cdef double reaches[3]
    if x.shape[0] != 11 or JtJ.shape[0] != 11 or JtJ.shape[1] != 11 or Jtr.shape[0] != 11:
        raise ValueError("x and Jtr must have 11 entries, JtJ 11 x 11")
    if planes.shape[1] != 9 or support_plane.shape[0] != 4:
        raise ValueError("planes must be (N, 9) and support_plane (4,)")
    with nogil:
        _rotation(R0, x[8], x[9], x[10], R, dR)
        for k in range(3):
            a[k] = exp(x[k])
            t[k] = t0[k] + scale * x[5 + k]
        if jacobian:
            for j in range(11):
                Jtr[j] = 0.0
                for k in range(11):
                    JtJ[j, k] = 0.0
        rows = n + 1 if plane_weight > 0 else n
        for i in range(rows):
            if i < n:
                weight = planes[i, 4]
                angles[0] = -tilt
                angles[1] = 0.0
                angles[2] = tilt
                best = 1e300
                for j in range(4):
                    if j < 3:
                        psi = angles[j]
                    else:  # the parabola's vertex, if it opens upwards, within the three
                        r_minus, r_zero, r_plus = reaches[0], reaches[1], reaches[2]
                        curvature = r_minus - 2.0 * r_zero + r_plus
                        if curvature <= 0 or tilt <= 0:
                            break
                        psi = 0.5 * tilt * (r_minus - r_plus) / curvature
                        if psi < -tilt or psi > tilt:
                            break
                    cs = cos(psi)
                    sn = sin(psi)
                    for k in range(3):
                        m[k] = cs * planes[i, k] + sn * planes[i, 5 + k]
                    offset = cs * planes[i, 3] + sn * planes[i, 8]
                    reach = _reach(a, &x[3], t, R, m, offset, v, dh_da, dh_de, dh_dv)
                    if j < 3:
                        reaches[j] = reach
                    if reach < best:
                        best = reach
                        best_offset = offset
                        for k in range(3):
                            best_m[k] = m[k]
                    if tilt <= 0:
                        break
                for k in range(3):
                    m[k] = best_m[k]
                offset = best_offset
            else:  # the support plane: the superquadric's reach along -n beyond d
                for k in range(3):
                    m[k] = -support_plane[k]
                offset = support_plane[3]
                weight = plane_weight
            r = weight * _reach(a, &x[3], t, R, m, offset, v, dh_da, dh_de, dh_dv)
            root = sqrt(1.0 + r * r / c2)
            cost += c2 * (root - 1.0)
            if not jacobian:
                continue
            w = 1.0 / root
            for k in range(3):
                J[k] = weight * dh_da[k] * a[k]
                J[5 + k] = weight * scale * m[k]
            J[3] = weight * dh_de[0]
            J[4] = weight * dh_de[1]
            for q in range(3):  # d(R^T m)/d angle = dR^T m
                J[8 + q] = 0.0
                for k in range(3):
                    J[8 + q] += dh_dv[k] * (dR[q][0][k] * m[0] + dR[q][1][k] * m[1] + dR[q][2][k] * m[2])
                J[8 + q] *= weight
            for j in range(11):
                Jtr[j] += w * J[j] * r
                for k in range(j, 11):
                    JtJ[j, k] += w * J[j] * J[k]
        if jacobian:
            for j in range(11):
                for k in range(j):
                    JtJ[j, k] = JtJ[k, j]
    return cost
