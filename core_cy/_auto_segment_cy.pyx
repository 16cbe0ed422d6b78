# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Kernel of the ``auto`` segmentation's noise level: the median of an evidence map's finite values and the
median of their distances from it, each found by selection in one copy of the values, not by sorting."""

from cython cimport floating
from libc.math cimport fabs, fabsf, floor, isfinite, rint, signbit, sqrt, sqrtf
from libc.stdlib cimport free, malloc

import numpy as np


cdef void _select(floating* values, Py_ssize_t count, Py_ssize_t k) noexcept nogil:
    """Reorder ``values[:count]`` so that ``values[k]`` is the value a sort would put there, none before it
    greater and none after it smaller (Hoare's quickselect, pivot the median of three; plain C, so that the
    kernels need no C++ compiler)."""
    cdef Py_ssize_t low = 0, high = count - 1, i, j, middle
    cdef floating pivot, swap
    while high > low:
        middle = low + (high - low) // 2
        # The median of three as the pivot; the smaller and larger stay at the ends, where they stop the scans.
        if values[middle] < values[low]:
            swap = values[middle]; values[middle] = values[low]; values[low] = swap
        if values[high] < values[low]:
            swap = values[high]; values[high] = values[low]; values[low] = swap
        if values[high] < values[middle]:
            swap = values[high]; values[high] = values[middle]; values[middle] = swap
        pivot = values[middle]
        i, j = low, high
        while i <= j:
            while values[i] < pivot:
                i += 1
            while values[j] > pivot:
                j -= 1
            if i <= j:
                swap = values[i]; values[i] = values[j]; values[j] = swap
                i += 1
                j -= 1
        # Now values[low..j] <= pivot <= values[i..high], and every value between them equals the pivot.
        if k <= j:
            high = j
        elif k >= i:
            low = i
        else:
            return


#: Of this many values or more, the median is looked for between two of a sample's first (_bracketed_median).
cdef Py_ssize_t _BRACKETED = 4096
#: The sample's size, and how many of its ranks either side of the middle's the bracket spans.
cdef Py_ssize_t _SAMPLE = 1024, _BRACKET_RANKS = 64


cdef bint _bracketed_median(floating* values, Py_ssize_t count, floating* found) noexcept nogil:
    """The median of ``values[:count]`` into ``found``, True, when it lies between two values of an evenly spaced
    sample that bracket the middle; False when it does not (the caller selects among all). One pass copies out
    the values between them, a small share of all: the selection then runs over those alone."""
    cdef Py_ssize_t middle = count // 2, k, below = 0, between = 0, rank, low_rank, high_rank
    cdef floating low, high, value, upper, lower
    cdef floating* sample = <floating*>malloc(_SAMPLE * sizeof(floating))
    cdef floating* inside = <floating*>malloc(count * sizeof(floating))
    if sample == NULL or inside == NULL:
        free(sample)
        free(inside)
        return False
    for k in range(_SAMPLE):
        sample[k] = values[(k * count) // _SAMPLE]
    rank = (middle * _SAMPLE) // count
    low_rank, high_rank = max(rank - _BRACKET_RANKS, 0), min(rank + _BRACKET_RANKS, _SAMPLE - 1)
    _select(sample, _SAMPLE, low_rank)
    low = sample[low_rank]
    _select(sample, _SAMPLE, high_rank)
    high = sample[high_rank]
    free(sample)
    for k in range(count):
        value = values[k]
        # Without branches, which the values' order would make a guess.
        inside[between] = value
        between += (value >= low) & (value <= high)
        below += value < low
    if not (below <= middle < below + between):
        free(inside)
        return False
    rank = middle - below
    _select(inside, between, rank)
    upper = inside[rank]
    if count % 2:
        found[0] = upper
    else:
        # The value just below the middle: the largest of those the selection left below it, or, the middle
        # being the bracket's first, of those under the bracket (there are some: middle >= 1).
        if rank > 0:
            lower = inside[0]
            for k in range(1, rank):
                if inside[k] > lower:
                    lower = inside[k]
        else:
            lower = low
            for k in range(count):
                if values[k] < low and (lower == low or values[k] > lower):
                    lower = values[k]
        found[0] = (lower + upper) / 2
    free(inside)
    return True


cdef floating _median_in_place(floating* values, Py_ssize_t count) noexcept nogil:
    """The median of ``values[:count]`` (count >= 1), reordering them; of an even count, the mean of the two
    middle values, summed and halved in the values' own precision as NumPy's median does."""
    cdef Py_ssize_t middle = count // 2, k
    cdef floating upper, lower, found
    if count >= _BRACKETED and _bracketed_median(values, count, &found):
        return found
    _select(values, count, middle)
    upper = values[middle]
    if count % 2:
        return upper
    # After the selection every value below the middle one is no greater: the largest of them is the other.
    lower = values[0]
    for k in range(1, middle):
        if values[k] > lower:
            lower = values[k]
    return (lower + upper) / 2


#: Whole numbers up to this are counted, not selected: a grey image filtered by an integer kernel holds them.
cdef Py_ssize_t _COUNTED = 65535


cdef Py_ssize_t _counted_integers_below(const floating[::1] values) noexcept nogil:
    """One more than the largest of ``values`` if every one of them is a whole number from 0 to
    :data:`_COUNTED`, else 0: such values' median is found by counting them."""
    cdef Py_ssize_t k, whole, largest = 0
    cdef floating value
    for k in range(values.shape[0]):
        value = values[k]
        # A negative zero is left to the selection, which keeps it as it is.
        if not (value >= 0 and value <= _COUNTED) or signbit(value):
            return 0
        whole = <Py_ssize_t>value
        if value != whole:
            return 0
        if whole > largest:
            largest = whole
    return largest + 1


cdef floating _counted_median(const floating[::1] values, Py_ssize_t[::1] counts) noexcept nogil:
    """The median of whole ``values`` (at least one) under ``counts``'s length, found by counting them into
    ``counts`` (zeros); of an even count, the mean of the two middle values, as NumPy's median gives it."""
    cdef Py_ssize_t n = values.shape[0], k, value, below = 0, middle = n // 2
    cdef floating upper = 0, lower = -1
    for k in range(n):
        counts[<Py_ssize_t>values[k]] += 1
    # The values at sorted positions middle - 1 and middle.
    for value in range(counts.shape[0]):
        if lower < 0 and below + counts[value] > middle - 1:
            lower = value
        if below + counts[value] > middle:
            upper = value
            break
        below += counts[value]
    if n % 2:
        return upper
    return (lower + upper) / 2


def median(floating[::1] values not None):
    """NumPy's ``np.median`` of ``values`` (1-D, contiguous, finite, at least one), by selection in a copy, or
    by counting them where they are all small whole numbers (many alike, which selection sorts out slowly)."""
    cdef Py_ssize_t n = values.shape[0], counted
    if n == 0:
        raise ValueError("the median of no values")
    with nogil:
        counted = _counted_integers_below(values)
    cdef Py_ssize_t[::1] counts
    cdef floating middle
    if counted:
        counts = np.zeros(counted, np.intp)
        with nogil:
            middle = _counted_median(values, counts)
        return float(middle)
    buffer = np.array(values, copy=True)
    cdef floating[::1] copy = buffer
    cdef floating found
    with nogil:
        found = _median_in_place(&copy[0], n)
    return float(found)


def median_and_spread(floating[::1] evidence not None):
    """(median, median absolute deviation) of the finite values of ``evidence`` (1-D, contiguous), or None
    when none is finite. Equal to NumPy's ``np.median`` of the finite values and of their absolute
    differences from that median, computed in the values' precision."""
    cdef Py_ssize_t n = evidence.shape[0], count = 0, k
    buffer = np.empty(n, dtype=np.float32 if floating is float else np.float64)
    cdef floating[::1] values = buffer
    cdef floating median, spread
    with nogil:
        for k in range(n):
            if isfinite(evidence[k]):
                values[count] = evidence[k]
                count += 1
        if count == 0:
            median = 0
        else:
            median = _median_in_place(&values[0], count)
            for k in range(count):
                values[k] = fabs(values[k] - median)
            spread = _median_in_place(&values[0], count)
    if count == 0:
        return None
    return float(median), float(spread)


def plane_homography_maps(const double[:, ::1] H not None, const double[::1] across not None, double height,
                          Py_ssize_t column0, Py_ssize_t row0, double unit_u, double unit_v,
                          float[:, :, ::1] maps not None, unsigned char[:, ::1] valid not None):
    """Fill ``maps`` ((h, w, 2) float32) with where each pixel (column0 + c, row0 + r) of a grid falls in
    another view through a plane's homography ``H`` (3x3, to the other's full-resolution pixels, scaled by
    the ray's n . d = ``across`` . x), in units of ``unit_u`` x ``unit_v`` full-resolution pixels with
    pixel centres on integers; and ``valid`` ((h, w) uint8) with 1 where the pixel's ray meets the plane
    in front of both cameras (t = -``height`` / n . d > 0, and a positive depth in the other).

    The same arithmetic, in the same order, as NumPy on the whole grid: u = (H[0, 0] c + H[0, 1] r +
    H[0, 2]) / (H[2, 0] c + ...), then ((u + 0.5) / unit_u - 0.5) rounded to float32."""
    cdef Py_ssize_t rows = maps.shape[0], columns = maps.shape[1], r, c
    cdef double i, j, x, y, z, meets, t
    if maps.shape[2] != 2 or valid.shape[0] != rows or valid.shape[1] != columns:
        raise ValueError("maps must be (h, w, 2) and valid (h, w)")
    if H.shape[0] != 3 or H.shape[1] != 3 or across.shape[0] != 3:
        raise ValueError("H must be 3x3 and across of length 3")
    with nogil:
        for r in range(rows):
            j = <double>(row0 + r)
            for c in range(columns):
                i = <double>(column0 + c)
                x = H[0, 0] * i + H[0, 1] * j + H[0, 2]
                y = H[1, 0] * i + H[1, 1] * j + H[1, 2]
                z = H[2, 0] * i + H[2, 1] * j + H[2, 2]
                meets = across[0] * i + across[1] * j + across[2]
                t = -height / meets
                valid[r, c] = isfinite(t) and t > 0 and z / meets > 0
                maps[r, c, 0] = <float>((x / z + 0.5) / unit_u - 0.5)
                maps[r, c, 1] = <float>((y / z + 0.5) / unit_v - 0.5)


cdef inline double _coarse_pixel(const double[:, ::1] projection, double x, double y, double z, double sx,
                                 double sy, double* u, double* v) noexcept nogil:
    """The depth of world point (x, y, z) by a pinhole ``projection`` (3, 4), and its nearest coarse pixel
    (``u`` column, ``v`` row; rounded half to even) in coarse pixels ``sx`` x ``sy`` full-resolution ones."""
    cdef double hu, hv, hz
    hu = projection[0, 0] * x + projection[0, 1] * y + projection[0, 2] * z + projection[0, 3]
    hv = projection[1, 0] * x + projection[1, 1] * y + projection[1, 2] * z + projection[1, 3]
    hz = projection[2, 0] * x + projection[2, 1] * y + projection[2, 2] * z + projection[2, 3]
    u[0] = rint((hu / hz + 0.5) / sx - 0.5)
    v[0] = rint((hv / hz + 0.5) / sy - 0.5)
    return hz


cdef inline bint _in_image(double u, double v, Py_ssize_t width, Py_ssize_t height) noexcept nogil:
    """Whether coarse pixel (``u``, ``v``) lies within an image of ``width`` x ``height``."""
    return isfinite(u) and isfinite(v) and u >= 0 and v >= 0 and u < width and v < height


def project_into_mask(const double[:, ::1] points not None, const double[:, ::1] projection not None,
                      double sx, double sy, const unsigned char[:, ::1] mask not None,
                      long long[:, ::1] pixels not None, unsigned char[::1] seen not None,
                      double[::1] depth not None, unsigned char[::1] hit not None):
    """Project world ``points`` (N, 3) by a pinhole ``projection`` (3, 4) into the coarse image of ``mask``
    (h, w; coarse pixels ``sx`` x ``sy`` full-resolution ones, centres on integers), filling per point:
    ``pixels`` (N, 2) the nearest coarse pixel (column, row; rounded half to even), ``depth`` (N,),
    ``seen`` (N,) 1 where the point is in front of the camera and within the image, and ``hit`` (N,) 1
    where it is seen inside the mask or not seen at all (a point out of a view's image is not carved)."""
    cdef Py_ssize_t n = points.shape[0], k
    cdef Py_ssize_t height = mask.shape[0], width = mask.shape[1]
    cdef double hz, u, v
    cdef long long column, row
    if points.shape[1] != 3 or projection.shape[0] != 3 or projection.shape[1] != 4:
        raise ValueError("points must be (N, 3) and projection (3, 4)")
    if pixels.shape[0] != n or pixels.shape[1] != 2 or seen.shape[0] != n or depth.shape[0] != n or hit.shape[0] != n:
        raise ValueError("pixels must be (N, 2) and seen, depth and hit (N,)")
    with nogil:
        for k in range(n):
            hz = _coarse_pixel(projection, points[k, 0], points[k, 1], points[k, 2], sx, sy, &u, &v)
            depth[k] = hz
            if hz > 0 and _in_image(u, v, width, height):
                column, row = <long long>u, <long long>v
                pixels[k, 0], pixels[k, 1] = column, row
                seen[k] = 1
                hit[k] = mask[row, column] > 0
            else:
                pixels[k, 0], pixels[k, 1] = -1, -1
                seen[k] = 0
                hit[k] = 1


cdef inline bint _same_shape(const float[:, ::1] array, Py_ssize_t rows, Py_ssize_t columns) noexcept:
    return array.shape[0] == rows and array.shape[1] == columns


def windowed_correlation(const float[:, ::1] mean_a not None, const float[:, ::1] variance_a not None,
                         const float[:, ::1] flat_a not None, const float[:, ::1] mean_b not None,
                         const float[:, ::1] square_mean_b not None, const float[:, ::1] product_mean not None,
                         float contrast, float flat, float[:, ::1] correlation not None,
                         unsigned char[:, ::1] textured not None):
    """Fill ``correlation`` with the normalised cross-correlation of two grey images over a window, and
    ``textured`` with 1 where both windows hold a texture that stands clear of the noise, from the windows'
    means: of ``a`` (its mean, variance and the variance below which it is flat, made once for every image
    it is compared with), of ``b`` and of ``b * b``, and of ``a * b``. ``b``'s window is flat below
    max((``contrast`` x its mean)^2, ``flat``). All (h, w) float32; in float32, in NumPy's order:

        variance_b = maximum(square_mean_b - mean_b * mean_b, 0)
        correlation = (product_mean - mean_a * mean_b) / sqrt(variance_a * variance_b + 1e-6)
        textured = (variance_a > flat_a) & (variance_b > maximum((contrast * mean_b) ** 2, flat))"""
    cdef Py_ssize_t rows = correlation.shape[0], columns = correlation.shape[1], r, c
    cdef float mb, variance_b, spread, floor_b, tiny = 1e-6
    if not (_same_shape(mean_a, rows, columns) and _same_shape(variance_a, rows, columns)
            and _same_shape(flat_a, rows, columns) and _same_shape(mean_b, rows, columns)
            and _same_shape(square_mean_b, rows, columns) and _same_shape(product_mean, rows, columns)
            and textured.shape[0] == rows and textured.shape[1] == columns):
        raise ValueError("every array must have correlation's shape")
    with nogil:
        for r in range(rows):
            for c in range(columns):
                mb = mean_b[r, c]
                variance_b = square_mean_b[r, c] - mb * mb
                # NumPy's maximum keeps its first argument when the two compare equal, or when it is NaN.
                if not (variance_b >= 0 or variance_b != variance_b):
                    variance_b = 0
                spread = contrast * mb
                floor_b = spread * spread
                if not (floor_b >= flat or floor_b != floor_b):
                    floor_b = flat
                correlation[r, c] = (product_mean[r, c] - mean_a[r, c] * mb) / sqrtf(
                    variance_a[r, c] * variance_b + tiny)
                textured[r, c] = variance_a[r, c] > flat_a[r, c] and variance_b > floor_b


def any_within(const float[:, ::1] points not None, const float[:, ::1] samples not None, double radius,
               bint inclusive, unsigned char[::1] found not None):
    """Fill ``found`` ((N,) uint8) with 1 where some of the ``samples`` (S, 3) lies within ``radius`` of
    ``points[i]`` (N, 3): at a distance under it, or at most it if ``inclusive``. The distance is scipy's
    cKDTree's, the square root of the squared differences summed channel by channel in double, so that
    the answer is the nearest sample's distance compared with ``radius`` as before.

    Only whether some sample is near counts, not which: the samples are put in cells a hair wider than the
    radius, and each point looks in its own cell and the 26 around it (a sample within the radius differs
    from the point by less than a cell in every channel, by a margin that the rounding of a division cannot
    bridge), stopping at the first sample near enough."""
    cdef Py_ssize_t n = points.shape[0], count = samples.shape[0], i, k, s, a, b, c
    cdef double low[3]
    cdef double high[3]
    cdef Py_ssize_t dims[3]
    cdef Py_ssize_t at[3]
    cdef double cell, d, d2, distance, coordinate, extent = 0.0
    cdef Py_ssize_t cells, index, start, stop
    if points.shape[1] != 3 or samples.shape[1] != 3 or found.shape[0] != n:
        raise ValueError("points must be (N, 3), samples (S, 3) and found (N,)")
    if not (radius > 0 and isfinite(radius)):
        raise ValueError("the radius must be positive and finite")
    if count == 0:
        found[:] = 0
        return
    for k in range(3):
        low[k] = high[k] = samples[0, k]
        for s in range(1, count):
            low[k] = min(low[k], <double>samples[s, k])
            high[k] = max(high[k], <double>samples[s, k])
        if not (isfinite(low[k]) and isfinite(high[k])):
            raise ValueError("the samples must be finite")
        extent = max(extent, high[k] - low[k])
    # Cells a hair wider than the radius, and no more than 64 a side however far the samples spread.
    cell = max(radius * (1.0 + 1e-9), extent / 64.0)
    for k in range(3):
        dims[k] = <Py_ssize_t>floor((high[k] - low[k]) / cell) + 1
    cells = dims[0] * dims[1] * dims[2]
    # The samples sorted by cell (a counting sort): cell q holds order[starts[q]:starts[q + 1]].
    starts_array = np.zeros(cells + 1, np.intp)
    order_array = np.empty(count, np.intp)
    cell_of_array = np.empty(count, np.intp)
    cdef Py_ssize_t[::1] starts = starts_array, order = order_array, cell_of = cell_of_array
    with nogil:
        for s in range(count):
            index = 0
            for k in range(3):
                index = index * dims[k] + <Py_ssize_t>floor((samples[s, k] - low[k]) / cell)
            cell_of[s] = index
            starts[index + 1] += 1
        for index in range(cells):
            starts[index + 1] += starts[index]
        for s in range(count):
            order[starts[cell_of[s]]] = s
            starts[cell_of[s]] += 1
        for index in range(cells, 0, -1):
            starts[index] = starts[index - 1]
        starts[0] = 0
        for i in range(n):
            found[i] = 0
            for k in range(3):
                coordinate = floor((points[i, k] - low[k]) / cell)
                # Out of the cells and their neighbours (or not a number): no sample is near.
                if not (coordinate >= -1 and coordinate <= dims[k]):
                    break
                at[k] = <Py_ssize_t>coordinate
            else:
                for a in range(max(at[0] - 1, 0), min(at[0] + 2, dims[0])):
                    for b in range(max(at[1] - 1, 0), min(at[1] + 2, dims[1])):
                        for c in range(max(at[2] - 1, 0), min(at[2] + 2, dims[2])):
                            index = (a * dims[1] + b) * dims[2] + c
                            start, stop = starts[index], starts[index + 1]
                            for s in range(start, stop):
                                d = <double>points[i, 0] - <double>samples[order[s], 0]
                                d2 = d * d
                                d = <double>points[i, 1] - <double>samples[order[s], 1]
                                d2 = d2 + d * d
                                d = <double>points[i, 2] - <double>samples[order[s], 2]
                                d2 = d2 + d * d
                                distance = sqrt(d2)
                                if distance < radius or (inclusive and distance == radius):
                                    found[i] = 1
                                    break
                            if found[i]:
                                break
                        if found[i]:
                            break
                    if found[i]:
                        break


def add_relit_grain(const float[:, ::1] own not None, const float[:, ::1] own_light not None,
                    const float[:, ::1] theirs not None, const float[:, ::1] their_light not None,
                    const unsigned char[:, ::1] inside not None, const Py_ssize_t[::1] rows not None,
                    const Py_ssize_t[::1] columns not None, float[:, :, ::1] sums not None,
                    float[:, ::1] seeing not None):
    """Add to ``sums`` ((h, w, 3) float32) and ``seeing`` ((h, w)) one other view's share of
    :func:`auto_segment._plane_grain_sums`, at the fine pixels whose coarse pixel (``inside[rows[r],
    columns[c]]``) that view sees: the view's grain ``own`` brought back to the other's light (``own_light``
    and ``their_light``, each blurred), times the other's grain ``theirs``, ``theirs`` squared, the former
    squared; and 1. All float32, in NumPy's order:

        lit = maximum((own_light + 1) / (their_light + 1), 0.05)
        relit = own / lit
        sums[sees] += stack([relit * theirs, theirs * theirs, relit * relit])[sees]; seeing[sees] += 1"""
    cdef Py_ssize_t height = own.shape[0], width = own.shape[1], r, c
    cdef float one = 1.0, least = 0.05, lit, relit, grain
    if not (_same_shape(own_light, height, width) and _same_shape(theirs, height, width)
            and _same_shape(their_light, height, width) and _same_shape(seeing, height, width)
            and sums.shape[0] == height and sums.shape[1] == width and sums.shape[2] == 3
            and rows.shape[0] == height and columns.shape[0] == width):
        raise ValueError("every array must have own's shape, rows and columns its sides")
    for r in range(height):
        if rows[r] < 0 or rows[r] >= inside.shape[0]:
            raise IndexError("a row out of inside")
    for c in range(width):
        if columns[c] < 0 or columns[c] >= inside.shape[1]:
            raise IndexError("a column out of inside")
    with nogil:
        for r in range(height):
            for c in range(width):
                if not inside[rows[r], columns[c]]:
                    continue
                lit = (own_light[r, c] + one) / (their_light[r, c] + one)
                # NumPy's maximum keeps its first argument when the two compare equal, or when it is NaN.
                if not (lit >= least or lit != lit):
                    lit = least
                relit = own[r, c] / lit
                grain = theirs[r, c]
                sums[r, c, 0] += relit * grain
                sums[r, c, 1] += grain * grain
                sums[r, c, 2] += relit * relit
                seeing[r, c] += one



cdef inline float _chroma_distance(float blue, float green, float red, const float* table_chroma) noexcept nogil:
    """The L1 distance of a pixel's chromaticity from the table's, summed in NumPy's channel order."""
    cdef float distance = fabsf(blue - table_chroma[0]) + fabsf(green - table_chroma[1])
    return distance + fabsf(red - table_chroma[2])


def shadow_like_pixels(const float[:, :, :] image not None, const unsigned char[:, :] table not None,
                       double dimmer, unsigned char[:, ::1] found not None):
    """Set ``found`` ((h, w) uint8) to 1 at the ``table`` pixels of ``image`` ((h, w, 3) float32 BGR) whose
    chromaticity lies near the table pixels' median one (within 0.12, or as far as nine in ten of the lit
    table's pixels lie from it, whichever is more, up to 0.3), and whose brightness is under ``dimmer`` times
    their median (:func:`auto_segment._shadow_like`); the rest are left alone. In float32, in NumPy's order:

        pixels = image[table]; brightness = pixels.sum(axis=1) + 3; chroma = pixels / brightness[:, None]
        off = abs(chroma - median of each channel of chroma).sum(axis=1) * 3
        dark = brightness < dimmer * median(brightness)
        spread = sorted(off[~dark])[(count(~dark) - 1) * 9 // 10]   # 0 where none is lit
        found[table] = (off < min(max(0.12, spread), 0.3)) & dark"""
    cdef Py_ssize_t height = image.shape[0], width = image.shape[1], r, c, k, n, count = 0, lit
    cdef float three = 3.0, near = 0.12, widest = 0.3, bright, limit, off
    cdef float table_chroma[3]
    if image.shape[2] != 3 or table.shape[0] != height or table.shape[1] != width:
        raise ValueError("image must be (h, w, 3) and table (h, w)")
    if found.shape[0] != height or found.shape[1] != width:
        raise ValueError("found must be (h, w)")
    for r in range(height):
        for c in range(width):
            count += table[r, c] != 0
    if count == 0:
        return
    brightness_array = np.empty(count, np.float32)
    chroma_array = np.empty((3, count), np.float32)
    scratch_array = np.empty(count, np.float32)
    cdef float[::1] brightness = brightness_array, scratch = scratch_array
    cdef float[:, ::1] chroma = chroma_array
    with nogil:
        n = 0
        for r in range(height):
            for c in range(width):
                if table[r, c]:
                    bright = image[r, c, 0] + image[r, c, 1]
                    bright = bright + image[r, c, 2]
                    bright = bright + three
                    brightness[n] = bright
                    for k in range(3):
                        chroma[k, n] = image[r, c, k] / bright
                    n += 1
        # The medians by selection in a scratch copy: the chromaticities are needed again below.
        for k in range(3):
            scratch[:] = chroma[k, :]
            table_chroma[k] = _median_in_place(&scratch[0], count)
        scratch[:] = brightness
        limit = <float>(dimmer * <double>_median_in_place(&scratch[0], count))
        # A textured table (a cutting mat's grid, a print) has many colours, and its shadow keeps each of
        # them darkened: a pixel of its shadow lies as far from the median colour as the lit table's do
        # (nine in ten of them), where that is farther than a plain table's 0.12; but no farther than 0.3, or
        # a colour as far from the table's as an object's (a blue box's on a green grid) would pass for it.
        lit = 0
        for n in range(count):
            if not brightness[n] < limit:
                scratch[lit] = _chroma_distance(chroma[0, n], chroma[1, n], chroma[2, n], table_chroma) * three
                lit += 1
        if lit:
            _select(&scratch[0], lit, (lit - 1) * 9 // 10)
            near = min(max(near, scratch[(lit - 1) * 9 // 10]), widest)
        n = 0
        for r in range(height):
            for c in range(width):
                if table[r, c]:
                    off = _chroma_distance(chroma[0, n], chroma[1, n], chroma[2, n], table_chroma)
                    found[r, c] = off * three < near and brightness[n] < limit
                    n += 1


def ratio_disagreement(const float[:, :, ::1] own not None, const float[:, :, ::1] low not None,
                       const float[:, :, ::1] high not None, float[:, ::1] disagreement not None):
    """Fill ``disagreement`` ((h, w) float32) with how far each pixel's channels of ``own`` ((h, w, 3)) lie
    outside another view's range ``low`` to ``high`` there, summed over the channels
    (:func:`auto_segment._ratio_parallax`). In float32, in NumPy's order:

        (maximum(low - own, 0) + maximum(own - high, 0)).sum(axis=2)"""
    cdef Py_ssize_t height = own.shape[0], width = own.shape[1], r, c, k
    cdef float below, above, total, zero = 0.0
    if not (own.shape[2] == 3 and low.shape[0] == height and low.shape[1] == width and low.shape[2] == 3
            and high.shape[0] == height and high.shape[1] == width and high.shape[2] == 3
            and _same_shape(disagreement, height, width)):
        raise ValueError("own, low and high must be (h, w, 3) and disagreement (h, w)")
    with nogil:
        for r in range(height):
            for c in range(width):
                for k in range(3):
                    below = low[r, c, k] - own[r, c, k]
                    # NumPy's maximum keeps its first argument when the two compare equal, or when it is NaN.
                    if not (below >= zero or below != below):
                        below = zero
                    above = own[r, c, k] - high[r, c, k]
                    if not (above >= zero or above != above):
                        above = zero
                    if k == 0:
                        total = below + above
                    else:
                        total = total + (below + above)
                disagreement[r, c] = total


def shadow_look(const float[:, :, ::1] image not None, const float[:, :, ::1] empty not None, float offset,
                float darkest, float lightest, float hue_shift, unsigned char[:, ::1] found not None):
    """Fill ``found`` ((h, w) uint8) with 1 where ``image`` ((h, w, 3) float32 BGR) is darker than ``empty``
    (its brightness over empty's, each with ``offset`` added to every channel, between ``darkest`` and
    ``lightest``, exclusive) with about its chromaticity (each channel over the sum, ``offset`` added, the
    differences' magnitudes summed under ``hue_shift``): :func:`auto_segment._shadow_of_table`. In float32,
    in NumPy's order:

        a, b = image + offset, empty + offset
        hue = abs(a / a.sum(axis=2)[..., None] - b / b.sum(axis=2)[..., None]).sum(axis=2)
        ratio = (image.sum(axis=2) + 3 * offset) / (empty.sum(axis=2) + 3 * offset)
        found = (ratio < lightest) & (ratio > darkest) & (hue < hue_shift)"""
    cdef Py_ssize_t height = image.shape[0], width = image.shape[1], r, c
    cdef float a0, a1, a2, b0, b1, b2, sum_a, sum_b, hue, ratio, three_offsets = 3 * offset
    if not (image.shape[2] == 3 and empty.shape[0] == height and empty.shape[1] == width and empty.shape[2] == 3
            and found.shape[0] == height and found.shape[1] == width):
        raise ValueError("image and empty must be (h, w, 3) and found (h, w)")
    with nogil:
        for r in range(height):
            for c in range(width):
                a0, a1, a2 = image[r, c, 0] + offset, image[r, c, 1] + offset, image[r, c, 2] + offset
                b0, b1, b2 = empty[r, c, 0] + offset, empty[r, c, 1] + offset, empty[r, c, 2] + offset
                sum_a = a0 + a1
                sum_a = sum_a + a2
                sum_b = b0 + b1
                sum_b = sum_b + b2
                hue = fabsf(a0 / sum_a - b0 / sum_b) + fabsf(a1 / sum_a - b1 / sum_b)
                hue = hue + fabsf(a2 / sum_a - b2 / sum_b)
                ratio = image[r, c, 0] + image[r, c, 1]
                ratio = ratio + image[r, c, 2]
                sum_b = empty[r, c, 0] + empty[r, c, 1]
                sum_b = sum_b + empty[r, c, 2]
                ratio = (ratio + three_offsets) / (sum_b + three_offsets)
                found[r, c] = ratio < lightest and ratio > darkest and hue < hue_shift


def channel_sum(const floating[:, :, :] image not None, floating[:, ::1] brightness not None):
    """Fill ``brightness`` ((h, w)) with the sum of each pixel's three channels of ``image`` ((h, w, 3), of the
    same type, any strides), left to right as NumPy's ``image.sum(axis=2)`` adds them."""
    cdef Py_ssize_t height = image.shape[0], width = image.shape[1], r, c
    if image.shape[2] != 3 or brightness.shape[0] != height or brightness.shape[1] != width:
        raise ValueError("image must be (h, w, 3) and brightness (h, w)")
    with nogil:
        for r in range(height):
            for c in range(width):
                brightness[r, c] = image[r, c, 0] + image[r, c, 1]
                brightness[r, c] = brightness[r, c] + image[r, c, 2]


cdef inline bint _column_sample(const double[:, ::1] projection, const double[::1] plane, double x, double y,
                                double z, double drop, double share, double sx, double sy, double* u,
                                double* v) noexcept nogil:
    """:func:`_coarse_pixel` of the point ``share`` of the way from world point (x, y, z) down the normal of
    ``plane`` to its foot (``drop`` below it), and whether that point lies in front of the camera. The point is
    taken as NumPy's ``point - (share * drop) * normal`` gives it."""
    cdef double step = share * drop
    return _coarse_pixel(projection, x - step * plane[0], y - step * plane[1], z - step * plane[2], sx, sy, u,
                         v) > 0


def columns_meet_mask(const double[:, ::1] points not None, const double[::1] plane not None,
                      const double[:, ::1] projection not None, double sx, double sy,
                      const unsigned char[:, ::1] mask not None, const double[::1] shares not None,
                      unsigned char[::1] met not None):
    """Fill ``met`` (N,) with 1 where the column under world point ``points[k]`` (N, 3), down the normal of
    ``plane`` (4,: unit normal, then offset) to the plane, meets ``mask`` (h, w) in the coarse image of a
    pinhole ``projection`` (3, 4) (coarse pixels ``sx`` x ``sy`` full-resolution ones, centres on integers): a
    sample of the column, at any of ``shares`` (of the point's height: 0 the point, 1 its foot), that the view
    sees (in front of the camera, within the image) at a pixel (the nearest, rounded half to even) inside the
    mask; 0 where none does. A column stops at its first sample in the mask.

    A column whose two ends, in front of the camera, fall beside the mask's bounding box on one side is not
    sampled between them: a pinhole maps a segment in front of it onto a segment, so every sample falls there
    too (the box is widened by a pixel for the rounding of the samples' own coordinates)."""
    cdef Py_ssize_t n = points.shape[0], count = shares.shape[0], k, s, r, c
    cdef Py_ssize_t height = mask.shape[0], width = mask.shape[1]
    cdef double left = width, right = -1, top = height, bottom = -1
    cdef double x, y, z, drop, u, v, u_end, v_end
    if points.shape[1] != 3 or plane.shape[0] != 4 or projection.shape[0] != 3 or projection.shape[1] != 4:
        raise ValueError("points must be (N, 3), plane (4,) and projection (3, 4)")
    if met.shape[0] != n:
        raise ValueError("met must be (N,)")
    with nogil:
        for r in range(height):
            for c in range(width):
                if mask[r, c]:
                    left, right, top, bottom = min(left, c), max(right, c), min(top, r), max(bottom, r)
        left, right, top, bottom = left - 1, right + 1, top - 1, bottom + 1
        for k in range(n):
            met[k] = 0
            if right < 0 or count == 0:  # an empty mask, or no sample
                continue
            x, y, z = points[k, 0], points[k, 1], points[k, 2]
            drop = x * plane[0] + y * plane[1] + z * plane[2] + plane[3]
            if (_column_sample(projection, plane, x, y, z, drop, shares[0], sx, sy, &u, &v)
                    and _column_sample(projection, plane, x, y, z, drop, shares[count - 1], sx, sy, &u_end, &v_end)
                    and ((u < left and u_end < left) or (u > right and u_end > right)
                         or (v < top and v_end < top) or (v > bottom and v_end > bottom))):
                continue
            for s in range(count):
                if (_column_sample(projection, plane, x, y, z, drop, shares[s], sx, sy, &u, &v)
                        and _in_image(u, v, width, height) and mask[<Py_ssize_t>v, <Py_ssize_t>u]):
                    met[k] = 1
                    break
