# cython: language_level=3
"""Shared by the kernels that work on superquadrics: the rotation of the fit's
parameters, a stable log-sum, and the support function (defined in the .pyx)."""

from libc.math cimport exp, log, sin, cos


cdef inline void _rotation(const double[:, ::1] R0, double alpha, double beta,
                           double gamma, double R[3][3], double dR[3][3][3]) noexcept nogil:
    """R = R0 @ Rz(gamma) @ Ry(beta) @ Rx(alpha) and dR/d(alpha, beta, gamma)."""
    cdef double ca = cos(alpha), sa = sin(alpha)
    cdef double cb = cos(beta), sb = sin(beta)
    cdef double cg = cos(gamma), sg = sin(gamma)
    cdef double Rx[3][3]
    cdef double Ry[3][3]
    cdef double Rz[3][3]
    cdef double dRx[3][3]
    cdef double dRy[3][3]
    cdef double dRz[3][3]
    cdef double A[3][3]
    cdef double B[3][3]
    cdef int i, j, k, m
    for i in range(3):
        for j in range(3):
            Rx[i][j] = 0.0; Ry[i][j] = 0.0; Rz[i][j] = 0.0
            dRx[i][j] = 0.0; dRy[i][j] = 0.0; dRz[i][j] = 0.0
    Rx[0][0] = 1.0; Rx[1][1] = ca; Rx[1][2] = -sa; Rx[2][1] = sa; Rx[2][2] = ca
    dRx[1][1] = -sa; dRx[1][2] = -ca; dRx[2][1] = ca; dRx[2][2] = -sa
    Ry[1][1] = 1.0; Ry[0][0] = cb; Ry[0][2] = sb; Ry[2][0] = -sb; Ry[2][2] = cb
    dRy[0][0] = -sb; dRy[0][2] = cb; dRy[2][0] = -cb; dRy[2][2] = -sb
    Rz[2][2] = 1.0; Rz[0][0] = cg; Rz[0][1] = -sg; Rz[1][0] = sg; Rz[1][1] = cg
    dRz[0][0] = -sg; dRz[0][1] = -cg; dRz[1][0] = cg; dRz[1][1] = -sg
    # m = 0: d/dalpha, 1: d/dbeta, 2: d/dgamma, 3: R itself
    for m in range(4):
        for i in range(3):
            for j in range(3):
                A[i][j] = 0.0
                for k in range(3):
                    A[i][j] += R0[i, k] * (dRz[k][j] if m == 2 else Rz[k][j])
        for i in range(3):
            for j in range(3):
                B[i][j] = 0.0
                for k in range(3):
                    B[i][j] += A[i][k] * (dRy[k][j] if m == 1 else Ry[k][j])
        for i in range(3):
            for j in range(3):
                A[i][j] = 0.0
                for k in range(3):
                    A[i][j] += B[i][k] * (dRx[k][j] if m == 0 else Rx[k][j])
                if m == 3:
                    R[i][j] = A[i][j]
                else:
                    dR[m][i][j] = A[i][j]


cdef inline double _log_sum(double la, double lb, double* wa, double* wb) noexcept nogil:
    """log(e^la + e^lb), and the shares e^la / (e^la + e^lb), e^lb / (...) in wa, wb."""
    cdef double r
    if la >= lb:
        r = exp(lb - la)
        wa[0] = 1.0 / (1.0 + r)
        wb[0] = r * wa[0]
        return la + log(1.0 + r)
    r = exp(la - lb)
    wb[0] = 1.0 / (1.0 + r)
    wa[0] = r * wb[0]
    return lb + log(1.0 + r)



cdef inline double _level(double x, double y, double z, double la1, double la2, double la3,
                          double e1, double e2) noexcept nogil:
    """The inside-outside function F at |x|, |y|, |z| in the object's frame (la: the logs of the
    sizes), in log space (``u^p = exp(p log u)``); |x| below 1e-300 is taken as that (log stays finite)."""
    cdef double w1, w2
    cdef double tiny = 1e-300
    cdef double logA = _log_sum(2.0 / e2 * (log(x if x > tiny else tiny) - la1),
                                2.0 / e2 * (log(y if y > tiny else tiny) - la2), &w1, &w2)
    return exp(_log_sum(e2 / e1 * logA, 2.0 / e1 * (log(z if z > tiny else tiny) - la3), &w1, &w2))


cdef double _support(const double* a, const double* e, const double* v, double* dh_da,
                     double* dh_de, double* dh_dv) noexcept nogil

cdef double _support_value(const double* a, const double* e, const double* v) noexcept nogil
