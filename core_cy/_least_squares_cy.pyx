# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Kernel of the Levenberg-Marquardt step: the damped normal equations solved by Cholesky, within bounds."""

from libc.math cimport INFINITY, fabs, sqrt

cdef enum:
    MAX_PARAMETERS = 66  # six parts of a union, 11 each

# A parameter this near a bound (relative to 1 + the bound's size) is on it: a step shortened to end on
# a bound, x + step (bound - x) / step, lands on it only to within rounding, and a parameter left a
# rounding error inside its bound, not held there, would cut every later step that pushes it out to
# nothing (the descent then stops as if converged, or not, as the platform's last bit falls).
cdef double ON_BOUND = 1e-12


cdef inline bint _on(double value, double bound) noexcept nogil:
    """Whether ``value`` lies on a finite ``bound`` to within rounding."""
    return value == bound or (fabs(bound) < INFINITY and fabs(value - bound) <= ON_BOUND * (1.0 + fabs(bound)))


cdef bint _cholesky_array(double A[MAX_PARAMETERS][MAX_PARAMETERS], double damping, Py_ssize_t n,
                          double L[MAX_PARAMETERS][MAX_PARAMETERS]) noexcept nogil:
    """L L^T = A + damping diag(A + 1e-12); False if that is not positive definite."""
    cdef Py_ssize_t i, j, k
    cdef double total
    for i in range(n):
        for j in range(i + 1):
            total = A[i][j]
            if i == j:
                total += damping * (A[i][i] + 1e-12)
            for k in range(j):
                total -= L[i][k] * L[j][k]
            if i == j:
                if total <= 0:
                    return False
                L[i][i] = sqrt(total)
            else:
                L[i][j] = total / L[j][j]
    return True


def bounded_step(const double[:, ::1] JtJ not None, const double[::1] Jtr not None, double damping,
                 const double[::1] x not None, const double[::1] low not None, const double[::1] high not None,
                 double[::1] trial not None):
    """One damped Gauss-Newton step from x within [low, high]: writes ``trial`` and returns the
    decrease the quadratic model of the cost promises, or -1 if the damped matrix is singular.

    A parameter on a bound (to within rounding) that the step would push beyond it is held there (the
    system is solved without it); the step is then shortened to end on the first bound it meets, along
    which the model only falls, so the promise stays a fair test of convergence, and a parameter that
    ends within rounding of a bound is set on it.
    """
    cdef Py_ssize_t n = Jtr.shape[0]
    cdef double promise
    if (JtJ.shape[0] != n or JtJ.shape[1] != n or x.shape[0] != n or low.shape[0] != n or high.shape[0] != n
            or trial.shape[0] != n or n > MAX_PARAMETERS):
        raise ValueError(f"need an (n, n) matrix and n-vectors, n <= {MAX_PARAMETERS}")
    with nogil:
        promise = _bounded_step(JtJ, Jtr, damping, x, low, high, trial, n)
    return promise


cdef double _bounded_step(const double[:, ::1] JtJ, const double[::1] Jtr, double damping, const double[::1] x,
                          const double[::1] low, const double[::1] high, double[::1] trial,
                          Py_ssize_t n) noexcept nogil:
    cdef Py_ssize_t i, j, k
    cdef double L[MAX_PARAMETERS][MAX_PARAMETERS]
    cdef double A[MAX_PARAMETERS][MAX_PARAMETERS]
    cdef double g[MAX_PARAMETERS]
    cdef double y[MAX_PARAMETERS]
    cdef double step[MAX_PARAMETERS]
    cdef bint held[MAX_PARAMETERS]
    cdef double total, fraction, room, promise
    cdef bint any_held
    cdef int attempt
    for i in range(n):
        held[i] = False
    for attempt in range(2):
        for i in range(n):
            g[i] = 0.0 if held[i] else Jtr[i]
            for j in range(n):
                A[i][j] = (1.0 if i == j else 0.0) if (held[i] or held[j]) else JtJ[i, j]
        if not _cholesky_array(A, damping, n, L):
            return -1.0
        for i in range(n):  # L y = -g
            total = -g[i]
            for k in range(i):
                total -= L[i][k] * y[k]
            y[i] = total / L[i][i]
        for i in range(n - 1, -1, -1):  # L^T step = y
            total = y[i]
            for k in range(i + 1, n):
                total -= L[k][i] * step[k]
            step[i] = total / L[i][i]
        any_held = False
        for i in range(n):
            if not held[i] and (((x[i] <= low[i] or _on(x[i], low[i])) and step[i] < 0)
                                or ((x[i] >= high[i] or _on(x[i], high[i])) and step[i] > 0)):
                held[i] = True
                any_held = True
        if not any_held:
            break
    fraction = 1.0
    for i in range(n):
        if step[i] > 0:
            room = (high[i] - x[i]) / step[i]
        elif step[i] < 0:
            room = (low[i] - x[i]) / step[i]
        else:
            continue
        if room < fraction:
            fraction = room if room > 0 else 0.0
    promise = 0.0
    for i in range(n):
        step[i] *= fraction
        trial[i] = x[i] + step[i]
        if trial[i] < low[i] or _on(trial[i], low[i]):
            trial[i] = low[i]
        elif trial[i] > high[i] or _on(trial[i], high[i]):
            trial[i] = high[i]
        promise -= Jtr[i] * step[i]
        for j in range(n):
            promise -= 0.5 * step[i] * JtJ[i, j] * step[j]
    return promise
