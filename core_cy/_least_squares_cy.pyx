# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Kernel of the Levenberg-Marquardt step: a damped normal-equations solve by Cholesky."""

from libc.math cimport sqrt

cdef enum:
    MAX_PARAMETERS = 16


cdef bint _cholesky(const double[:, ::1] JtJ, double damping, Py_ssize_t n,
                    double L[MAX_PARAMETERS][MAX_PARAMETERS]) noexcept nogil:
    """L L^T = JtJ + damping diag(JtJ + 1e-12); False if that is not positive definite."""
    cdef Py_ssize_t i, j, k
    cdef double total
    for i in range(n):
        for j in range(i + 1):
            total = JtJ[i, j]
            if i == j:
                total += damping * (JtJ[i, i] + 1e-12)
            for k in range(j):
                total -= L[i][k] * L[j][k]
            if i == j:
                if total <= 0:
                    return False
                L[i][i] = sqrt(total)
            else:
                L[i][j] = total / L[j][j]
    return True


def damped_step(const double[:, ::1] JtJ not None, const double[::1] Jtr not None, double damping,
                double[::1] step not None):
    """Solve ``(JtJ + damping diag(JtJ)) step = -Jtr``; False if the matrix is not positive definite.

    A zero diagonal entry is damped as if it were 1e-12 (a parameter no residual sees stays put).
    """
    cdef Py_ssize_t n = Jtr.shape[0], i, k
    cdef double L[MAX_PARAMETERS][MAX_PARAMETERS]
    cdef double y[MAX_PARAMETERS]
    cdef double total
    cdef bint positive
    if JtJ.shape[0] != n or JtJ.shape[1] != n or step.shape[0] != n or n > MAX_PARAMETERS:
        raise ValueError(f"need an (n, n) matrix and two n-vectors, n <= {MAX_PARAMETERS}")
    with nogil:
        positive = _cholesky(JtJ, damping, n, L)
        if positive:
            for i in range(n):  # L y = -Jtr
                total = -Jtr[i]
                for k in range(i):
                    total -= L[i][k] * y[k]
                y[i] = total / L[i][i]
            for i in range(n - 1, -1, -1):  # L^T step = y
                total = y[i]
                for k in range(i + 1, n):
                    total -= L[k][i] * step[k]
                step[i] = total / L[i][i]
    return positive
