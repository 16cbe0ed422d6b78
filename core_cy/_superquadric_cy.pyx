# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels of the superquadrics: inside-outside values, the support
function, and the fit's objective with its analytic gradient.

Object frame: ``X = R^T (p - t)``. Inside-outside function::

    F = ((|x|/a1)^(2/e2) + (|y|/a2)^(2/e2))^(e2/e1) + (|z|/a3)^(2/e1)

evaluated in log space (``u^p = exp(p log u)``) so that the steep powers of a
box-like shape (2/e = 20) neither overflow nor lose the small terms.
"""

from libc.math cimport exp, log, log1p, fabs, copysign, sqrt

# |x| below this is treated as this: keeps log() finite at the axes' planes.
cdef double _TINY = 1e-300


cdef double _support(const double* a, const double* e, const double* v, double* dh_da,
                     double* dh_de, double* dh_dv) noexcept nogil:
    """Support along object-frame v of the superquadric (a, e) centred at the origin.

    ``h = ((|a1 v1|^q2 + |a2 v2|^q2)^(q1/q2) + |a3 v3|^q1)^(1/q1)``, ``q = 2 / (2 - e)``
    (the nested dual norm; e < 2), in log space. Writes dh/da, dh/de, dh/dv.
    """
    cdef double q1 = 2.0 / (2.0 - e[0]), q2 = 2.0 / (2.0 - e[1])
    cdef double lT[3]
    cdef double dT[3]
    cdef double T, lS, lG, h, g1, g3, w1, w2, dq1, dq2
    cdef int k
    for k in range(3):
        T = fabs(a[k] * v[k])
        lT[k] = log(T if T > _TINY else _TINY)
    lS = _log_sum(q2 * lT[0], q2 * lT[1], &w1, &w2)  # S = T1^q2 + T2^q2
    lG = _log_sum(q1 / q2 * lS, q1 * lT[2], &g1, &g3)  # G = S^(q1/q2) + T3^q1 = h^q1
    h = exp(lG / q1)
    dT[0] = h * exp(q1 / q2 * lS - lG + (q2 - 1.0) * lT[0] - lS)
    dT[1] = h * exp(q1 / q2 * lS - lG + (q2 - 1.0) * lT[1] - lS)
    dT[2] = h * exp((q1 - 1.0) * lT[2] - lG)
    dq1 = h * (-lG / (q1 * q1) + (g1 * lS / q2 + g3 * lT[2]) / q1)
    dq2 = h * g1 / q2 * (w1 * lT[0] + w2 * lT[1] - lS / q2)
    dh_de[0] = dq1 * 2.0 / ((2.0 - e[0]) * (2.0 - e[0]))
    dh_de[1] = dq2 * 2.0 / ((2.0 - e[1]) * (2.0 - e[1]))
    for k in range(3):
        dh_da[k] = dT[k] * fabs(v[k])
        dh_dv[k] = dT[k] * a[k] * (1.0 if v[k] > 0 else (-1.0 if v[k] < 0 else 0.0))
    return h


cdef double _support_value(const double* a, const double* e, const double* v) noexcept nogil:
    """:func:`_support` without the derivatives."""
    cdef double q1 = 2.0 / (2.0 - e[0]), q2 = 2.0 / (2.0 - e[1])
    cdef double lT[3]
    cdef double T, w1, w2
    cdef int k
    for k in range(3):
        T = fabs(a[k] * v[k])
        lT[k] = log(T if T > _TINY else _TINY)
    return exp(_log_sum(q1 / q2 * _log_sum(q2 * lT[0], q2 * lT[1], &w1, &w2), q1 * lT[2], &w1, &w2) / q1)


def support(const double[::1] size not None, const double[::1] shape not None,
            const double[::1] v not None):
    """Support (max of v . x) of the superquadric at the origin along object-frame v."""
    cdef double dh_da[3]
    cdef double dh_de[2]
    cdef double dh_dv[3]
    return _support(&size[0], &shape[0], &v[0], dh_da, dh_de, dh_dv)


def inside_outside(const double[:, ::1] points not None, const double[:, ::1] R not None,
                   const double[::1] t not None, const double[::1] size not None,
                   const double[::1] shape not None, double[::1] out not None):
    """Fill ``out[i]`` with F of ``points[i]`` (world) for the pose (R, t)."""
    cdef Py_ssize_t i, n = points.shape[0]
    cdef double la1 = log(size[0]), la2 = log(size[1]), la3 = log(size[2])
    cdef double e1 = shape[0], e2 = shape[1]
    cdef double qx, qy, qz
    with nogil:
        for i in range(n):
            qx = points[i, 0] - t[0]
            qy = points[i, 1] - t[1]
            qz = points[i, 2] - t[2]
            out[i] = _level(fabs(R[0, 0] * qx + R[1, 0] * qy + R[2, 0] * qz),
                            fabs(R[0, 1] * qx + R[1, 1] * qy + R[2, 1] * qz),
                            fabs(R[0, 2] * qx + R[1, 2] * qy + R[2, 2] * qz), la1, la2, la3, e1, e2)


cdef inline double _jaklic(const double* params, double R[3][3], double dR[3][3][3], double s,
                          const double* log_size, double qx, double qy, double qz, double* J) noexcept nogil:
    """Residual ``r = sqrt(a1 a2 a3) (F^e1 - 1)`` of the point at world offset q from the centre,
    and its derivatives by the 11 parameters in J (``s = sqrt(a1 a2 a3)``, log_size = log a)."""
    cdef double a1 = params[0], a2 = params[1], a3 = params[2], e1 = params[3], e2 = params[4]
    cdef double p2e1 = 2.0 / e1, p2e2 = 2.0 / e2, e2e1 = e2 / e1
    cdef double x, y, z, ax, ay, az, lu, lv, lw, wU, wV, wP, wQ, logA, logF, Fe, r, D, PU, PV, QW, gx, gy, gz
    cdef int j, m
    x = R[0][0] * qx + R[1][0] * qy + R[2][0] * qz
    y = R[0][1] * qx + R[1][1] * qy + R[2][1] * qz
    z = R[0][2] * qx + R[1][2] * qy + R[2][2] * qz
    ax = fabs(x)
    ay = fabs(y)
    az = fabs(z)
    if ax < _TINY:
        ax = _TINY
    if ay < _TINY:
        ay = _TINY
    if az < _TINY:
        az = _TINY
    lu = log(ax) - log_size[0]
    lv = log(ay) - log_size[1]
    lw = log(az) - log_size[2]
    # F = A^(e2/e1) + Q with A = U + V; w* are the shares U/A, V/A, P/F, Q/F
    logA = _log_sum(p2e2 * lu, p2e2 * lv, &wU, &wV)
    logF = _log_sum(e2e1 * logA, p2e1 * lw, &wP, &wQ)
    Fe = exp(e1 * logF)
    r = s * (Fe - 1.0)
    # D = F dr/dF; dF/dx = (2/e1) P/A U/x = (2/e1) F wP wU / x, dF/dz = (2/e1) F wQ / z
    D = s * e1 * Fe
    PU = p2e1 * D * wP * wU
    PV = p2e1 * D * wP * wV
    QW = p2e1 * D * wQ
    J[0] = (0.5 * r - PU) / a1
    J[1] = (0.5 * r - PV) / a2
    J[2] = (0.5 * r - QW) / a3
    J[3] = (e1 * s * Fe * logF - D * (e2e1 * logA * wP + p2e1 * lw * wQ)) / e1
    J[4] = D * wP * (logA - p2e2 * (wU * lu + wV * lv)) / e1
    gx = PU / copysign(ax, x)  # dF/dx has the sign of x
    gy = PV / copysign(ay, y)
    gz = QW / copysign(az, z)
    # X = R^T (p - t): dr/dt = -R g, dr/dangle = q^T dR g
    for j in range(3):
        J[5 + j] = -(R[j][0] * gx + R[j][1] * gy + R[j][2] * gz)
    for m in range(3):
        J[8 + m] = (qx * (dR[m][0][0] * gx + dR[m][0][1] * gy + dR[m][0][2] * gz)
                    + qy * (dR[m][1][0] * gx + dR[m][1][1] * gy + dR[m][1][2] * gz)
                    + qz * (dR[m][2][0] * gx + dR[m][2][1] * gy + dR[m][2][2] * gz))
    return r


cdef inline double _depth_below(const double* params, double R[3][3], double dR[3][3][3],
                                const double[::1] plane, double* J) noexcept nogil:
    """How far the superquadric reaches below the plane n . x + d = 0 (unit n; the support along -n
    beyond it), and its derivatives by the 11 parameters in J."""
    cdef double down[3]
    cdef double v[3]
    cdef double dh_da[3]
    cdef double dh_de[2]
    cdef double dh_dv[3]
    cdef double depth
    cdef int j, k, m
    for j in range(3):
        down[j] = -plane[j]
    for k in range(3):  # the direction in the object frame, R^T down
        v[k] = R[0][k] * down[0] + R[1][k] * down[1] + R[2][k] * down[2]
    depth = (_support(&params[0], &params[3], v, dh_da, dh_de, dh_dv)
             - (plane[0] * params[5] + plane[1] * params[6] + plane[2] * params[7]) - plane[3])
    for k in range(3):
        J[k] = dh_da[k]
        J[5 + k] = -plane[k]
    J[3] = dh_de[0]
    J[4] = dh_de[1]
    for m in range(3):  # d(R^T down)/d angle = dR^T down
        J[8 + m] = 0.0
        for k in range(3):
            J[8 + m] += dh_dv[k] * (dR[m][0][k] * down[0] + dR[m][1][k] * down[1] + dR[m][2][k] * down[2])
    return depth


def objective(const double[::1] params not None, const double[:, ::1] R0 not None,
              const double[:, ::1] points not None, double inside_weight,
              bint cauchy, double cauchy_scale, const double[::1] plane not None,
              double plane_weight, double[::1] grad not None):
    """Mean loss over the points, plus the plane penalty, and its gradient by ``params``.

    ``params`` = (a1, a2, a3, e1, e2, tx, ty, tz, alpha, beta, gamma) with
    R = R0 Rz(gamma) Ry(beta) Rx(alpha). Residual ``r = sqrt(a1 a2 a3) (F^e1 - 1)``;
    loss ``inside_weight r^2`` inside (F < 1), outside ``r^2`` or the Cauchy
    loss ``c^2 log(1 + r^2 / c^2)``. If ``plane_weight > 0``, ``plane`` = (n, d)
    with unit n, and ``plane_weight * depth^2`` is added, depth being how far
    the superquadric reaches below n.x + d = 0 (its support along -n minus
    n.t + d), when positive. The gradient (11,) is written to ``grad``.
    """
    cdef Py_ssize_t i, n = points.shape[0]
    cdef double R[3][3]
    cdef double dR[3][3][3]
    cdef double J[11]
    cdef double log_size[3]
    cdef double s = sqrt(params[0] * params[1] * params[2])
    cdef double c2 = cauchy_scale * cauchy_scale, r, u, dl, depth, loss = 0.0
    cdef int j
    with nogil:
        _rotation(R0, params[8], params[9], params[10], R, dR)
        for j in range(3):
            log_size[j] = log(params[j])
        for j in range(11):
            grad[j] = 0.0
        for i in range(n):
            r = _jaklic(&params[0], R, dR, s, log_size, points[i, 0] - params[5], points[i, 1] - params[6],
                        points[i, 2] - params[7], J)
            if r < 0.0:  # inside: F < 1
                loss += inside_weight * r * r
                dl = 2.0 * inside_weight * r
            elif cauchy:
                u = r * r / c2
                loss += c2 * log1p(u)
                dl = 2.0 * r / (1.0 + u)
            else:
                loss += r * r
                dl = 2.0 * r
            for j in range(11):
                grad[j] += dl * J[j]
        for j in range(11):
            grad[j] /= n
        loss /= n
        if plane_weight > 0.0:
            depth = _depth_below(&params[0], R, dR, plane, J)
            if depth > 0.0:
                loss += plane_weight * depth * depth
                for j in range(11):
                    grad[j] += 2.0 * plane_weight * depth * J[j]
    return loss


def jaklic_normal_equations(const double[::1] params not None, const double[:, ::1] R0 not None,
                            const double[:, ::1] points not None, const double[::1] plane not None,
                            double plane_weight, double[:, ::1] JtJ not None, double[::1] Jtr not None):
    """The plain Jaklic cost and its Gauss-Newton normal equations, for Levenberg-Marquardt.

    Residuals ``r_i / sqrt(n)``, ``r = sqrt(a1 a2 a3) (F^e1 - 1)``, plus, with
    ``plane_weight > 0``, ``sqrt(plane_weight) * depth`` where the superquadric
    reaches ``depth > 0`` below the plane (as in :func:`objective`); the cost
    is half their sum of squares, the same as :func:`objective` with
    ``inside_weight = 1`` and the squared loss, halved. ``params`` as there.
    Fills ``JtJ`` (11, 11) and ``Jtr`` (11,), and returns the cost.
    """
    cdef Py_ssize_t i, n = points.shape[0]
    cdef double R[3][3]
    cdef double dR[3][3][3]
    cdef double J[11]
    cdef double log_size[3]
    cdef double s = sqrt(params[0] * params[1] * params[2]), root_n = sqrt(<double>n)
    cdef double r, cost = 0.0, weight = sqrt(plane_weight) if plane_weight > 0 else 0.0
    cdef int j, k
    if params.shape[0] != 11 or JtJ.shape[0] != 11 or JtJ.shape[1] != 11 or Jtr.shape[0] != 11:
        raise ValueError("params and Jtr must have 11 entries, JtJ 11 x 11")
    if points.shape[1] != 3 or n < 1 or plane.shape[0] != 4:
        raise ValueError("points must be (N, 3) with N >= 1, plane (4,)")
    with nogil:
        _rotation(R0, params[8], params[9], params[10], R, dR)
        for j in range(3):
            log_size[j] = log(params[j])
        for j in range(11):
            Jtr[j] = 0.0
            for k in range(11):
                JtJ[j, k] = 0.0
        for i in range(n + 1):
            if i < n:
                r = _jaklic(&params[0], R, dR, s, log_size, points[i, 0] - params[5], points[i, 1] - params[6],
                            points[i, 2] - params[7], J) / root_n
                for j in range(11):
                    J[j] /= root_n
            else:
                if weight == 0.0:
                    break
                r = _depth_below(&params[0], R, dR, plane, J)
                if r <= 0.0:
                    break
                r *= weight
                for j in range(11):
                    J[j] *= weight
            cost += 0.5 * r * r
            for j in range(11):
                Jtr[j] += J[j] * r
                for k in range(j, 11):
                    JtJ[j, k] += J[j] * J[k]
        for j in range(11):
            for k in range(j):
                JtJ[j, k] = JtJ[k, j]
    return cost
