"""
What a level looks like after a step: strain and finiteness (the blow-up check), energy.

Each spring is counted once, from the end it leaves by an even stencil entry (rightwards,
downwards, or diagonally down).
"""

import math

from hcloth_ros.core.kernels.jit import BORROW, JIT, serial_and_parallel
from hcloth_ros.core.kernels.layout import (chunk_count, interleaved_dot, row3,
                                            STENCIL_DC, STENCIL_DR,
                                            stencil_span)
from hcloth_ros.core.kernels.springs import spring_vector
import numba
from numba import prange
import numpy as np


@numba.njit(**BORROW)
def _strain_row(q, rest, r, s, magnitude, positive):
    """
    Compute the strains ``|d| / L - 1`` of the springs leaving row r in direction s.

    Their magnitudes (finite ones, else 0) and positive parts go into the buffers; returns
    ``(springs, finite springs)``.
    """
    lo, hi = stencil_span(r, s, q.shape[1], q.shape[2])
    if hi <= lo:
        return 0, 0
    xp, yp, zp = row3(q, r, lo)
    xn, yn, zn = row3(q, r + STENCIL_DR[s], lo + STENCIL_DC[s])
    finite = 0
    for i in range(hi - lo):
        e = spring_vector(xn, yn, zn, xp, yp, zp, i)[3] / rest[s] - 1.0
        ok = math.isfinite(e)
        finite += ok
        magnitude[i] = abs(e) if ok else 0.0
        positive[i] = e if ok & (e > 0.0) else 0.0    # &, not `and`: no branch
    return hi - lo, finite


@numba.njit(**JIT)
def _stats_rows(q, qd, rest, r0, r1, row_max, row_sum, row_count, row_bad):
    cols = q.shape[2]
    magnitude = np.empty(cols)
    ones = np.ones(cols)
    positive = np.empty(cols)
    positive_bits = positive.view(np.int64)
    for r in range(r0, r1):
        bad = 0
        for d in range(q.shape[0]):
            x, v = q[d, r], qd[d, r]
            for c in range(cols):
                bad += not (math.isfinite(x[c]) & math.isfinite(v[c]))
        top = 0             # bit pattern of the largest strain (>= 0.0) so far
        count = 0
        total = 0.0
        for s in range(0, 2 * rest.shape[0] // 3, 2):    # 0, 2, 4, 6: stretch springs
            m, finite = _strain_row(q, rest, r, s, magnitude, positive)
            count += finite
            bad += m - finite
            # the largest: bit patterns of non-negative floats order like the floats, and
            # an integer max reduction vectorises (exact in any order)
            for i in range(m):
                top = max(top, positive_bits[i])
            # the sum of |e| in eight interleaved partial sums (vectorises): a reordered
            # sum of non-negative terms, within ~m * 1.1e-16 of the sequential one
            total += interleaved_dot(magnitude, ones, m)
        positive_bits[0] = top
        row_max[r] = positive[0]
        row_sum[r] = total
        row_count[r] = count
        row_bad[r] = 1.0 if bad > 0 else 0.0


def strain_stats(q, qd, rest):
    """
    Return the largest and mean strain of stretch springs and whether all is finite.

    ``(max_strain, mean_strain, finite)``: relative stretch of structural and shear
    springs, and whether every position, velocity and strain is finite.

    A non-finite strain counts as not finite and is left out of the max and the mean.
    """
    rows, cols = q.shape[1], q.shape[2]
    row_max, row_sum = np.zeros(rows), np.zeros(rows)
    row_count, row_bad = np.zeros(rows), np.zeros(rows)
    chunks = chunk_count(rows, cols)
    for ch in prange(chunks):
        _stats_rows(q, qd, rest, ch * rows // chunks, (ch + 1) * rows // chunks, row_max,
                    row_sum, row_count, row_bad)
    largest, total, count, bad = 0.0, 0.0, 0.0, 0.0
    for r in range(rows):           # loops: numpy's reductions cost a second to compile
        largest = max(largest, row_max[r])
        total += row_sum[r]
        count += row_count[r]
        bad = max(bad, row_bad[r])
    return largest, total / max(count, 1.0), bad == 0.0


strain_stats, strain_stats_parallel = serial_and_parallel(strain_stats)


@numba.njit(**BORROW)
def _energy_row(q, qd, mass, rest, stiffness, contraction, gravity, r):
    """Kinetic, gravitational and elastic energy of row r's points and springs (J)."""
    rows, cols = mass.shape
    kinetic = potential = elastic = 0.0
    for c in range(cols):
        m = mass[r, c]
        v2 = qd[0, r, c] ** 2 + qd[1, r, c] ** 2 + qd[2, r, c] ** 2
        kinetic += 0.5 * m * v2
        potential -= m * (gravity[0] * q[0, r, c] + gravity[1] * q[1, r, c]
                          + gravity[2] * q[2, r, c])
    for s in range(0, rest.shape[0], 2):
        lo, hi = stencil_span(r, s, rows, cols)
        if hi <= lo:
            continue
        xp, yp, zp = row3(q, r, lo)
        xn, yn, zn = row3(q, r + STENCIL_DR[s], lo + STENCIL_DC[s])
        for i in range(hi - lo):
            e = spring_vector(xn, yn, zn, xp, yp, zp, i)[3] - rest[s]
            k = stiffness[s] if e >= 0.0 else stiffness[s] * contraction
            elastic += 0.5 * k * e * e
    return kinetic, potential, elastic


@numba.njit(**JIT)
def energy(q, qd, mass, rest, stiffness, contraction, gravity):
    """Kinetic, gravitational (zero at the origin) and elastic energy of a level (J)."""
    rows = mass.shape[0]
    kinetic = potential = elastic = 0.0
    for r in range(rows):
        k, p, e = _energy_row(q, qd, mass, rest, stiffness, contraction, gravity, r)
        kinetic, potential, elastic = kinetic + k, potential + p, elastic + e
    return kinetic, potential, elastic
