"""
The paper's Table 1 on a refinement level: prolongation, constraint C and eq. 7.

Level k inserts a point on every edge of level k-1. After level k-1 has stepped:

* constraint C: inherited points (even row and column) take level k-1's new state;
* eq. 7 on inserted points, from this level's state at the start of the step, with the
  coarse velocity change prolonged (:func:`prolong`) standing in for the unknown changes
  of the neighbours:

      dv_i = (h f~_i + h^2 sum_j k_ij dv_app_j) / (m_i + h^2 K_i)

  A held neighbour's own prescribed change replaces its estimate. With exact gravity the
  estimate carries the external part once: ``h g`` is taken out of every neighbour's
  change and added back to the result.
"""

from hcloth_ros.core.kernels.jit import BORROW, JIT, serial_and_parallel
from hcloth_ros.core.kernels.layout import advance_row, chunk_count, FREE
from hcloth_ros.core.kernels.springs import (forward_terms_row, paired_force_row,
                                             stencil_sum_row)
import numba
from numba import prange
import numpy as np


@numba.njit(**BORROW)
def _prolong_row(coarse, r, out):
    """Row r of a level-k array from level k-1 (see :func:`prolong`) into ``out[d, col]``."""
    cols, coarse_cols = out.shape[1], coarse.shape[2]
    ra, rb = r // 2, (r + 1) // 2
    for d in range(out.shape[0]):
        a, b, f = coarse[d, ra], coarse[d, rb], out[d]
        for j in range(coarse_cols - 1):
            f[2 * j] = 0.5 * (a[j] + b[j])
            f[2 * j + 1] = 0.5 * (a[j] + b[j + 1])
        f[cols - 1] = 0.5 * (a[coarse_cols - 1] + b[coarse_cols - 1])


@numba.njit(**JIT)
def prolong(coarse, fine):
    r"""
    Fill a level-k array ``(d, rows, cols)`` from level k-1 by the parent rule.

    Point (r, c) is the mean of coarse points ``(r // 2, c // 2)`` and
    ``((r + 1) // 2, (c + 1) // 2)``: inherited points copy their coarse value, inserted
    points take the mean of the two ends of the edge they were inserted on (the "\"
    diagonal for face centres). Used for eq. 7's estimate and to start a level that is
    simulated again from the coarser state.
    """
    rows, cols = fine.shape[1], fine.shape[2]
    if cols != 2 * coarse.shape[2] - 1 or rows != 2 * coarse.shape[1] - 1:
        raise ValueError('prolong: the fine grid must have 2 n - 1 rows and columns')
    for r in range(rows):
        _prolong_row(coarse, r, fine[:, r])


@numba.njit(**BORROW)
def _add_drift_row(coarse_q_new, coarse_q_old, coarse_qd_new, h, hold_kind, q, r):
    """
    Move row r's free inserted points by the prolonged drift of level k-1 (in place).

    The drift of a coarse point is what it moved beyond ``h`` times its new velocity,
    ``(x_new - x_old) - h v_new`` (not zero when level k-1 steps by BDF2); an inserted
    point takes the mean drift of its edge's two ends (the rule of :func:`prolong`).
    Inherited and held points stay.
    """
    cols = hold_kind.shape[1]
    ra, rb = r // 2, (r + 1) // 2
    for c in range(1 - r % 2, cols, 2 - r % 2):     # inserted: not both even
        if hold_kind[r, c] != FREE:
            continue
        ca, cb = c // 2, (c + 1) // 2
        for d in range(3):
            a = (coarse_q_new[d, ra, ca] - coarse_q_old[d, ra, ca]) \
                - h * coarse_qd_new[d, ra, ca]
            b = (coarse_q_new[d, rb, cb] - coarse_q_old[d, rb, cb]) \
                - h * coarse_qd_new[d, rb, cb]
            q[d, r, c] += 0.5 * (a + b)


# rows of eq. 7's estimate a row needs: its own and two on either side (the stencil)
ESTIMATE_RING = 5


@numba.njit(**BORROW)
def _estimate_row(coarse_dv, hold_kind, prescribed_dv, r, ring):
    """
    Eq. 7's estimate of row r into its slot of ``ring`` (``(3, ESTIMATE_RING, cols)``).

    Level k-1's velocity change prolonged; a held point's estimate is its own prescribed
    change. Made a row at a time where eq. 7 reads it: a whole level's estimate made first
    was a pass over memory of its own, and read back (0.2 ms at 257 x 257).
    """
    out = ring[:, r % ring.shape[1]]
    _prolong_row(coarse_dv, r, out)
    kinds = hold_kind[r]
    for c in range(kinds.shape[0]):
        if kinds[c] != FREE:
            for d in range(3):
                out[d, c] = prescribed_dv[d, r, c]


@numba.njit(**BORROW)
def _inherit_row(coarse_q, coarse_qd, coarse_dv, r, q_out, qd_out, dv_out):
    """Constraint C on an even row: its even columns take level k-1's new state."""
    for d in range(3):
        for c in range(0, q_out.shape[2], 2):
            q_out[d, r, c] = coarse_q[d, r // 2, c // 2]
            qd_out[d, r, c] = coarse_qd[d, r // 2, c // 2]
            dv_out[d, r, c] = coarse_dv[d, r // 2, c // 2]


@numba.njit(**JIT)
def _eq7_rows(q, qd, mass, rest, stiffness, contraction, inv_diagonal, hold_kind,
              prescribed_dv, h, gravity, literal, coarse_q, coarse_qd, coarse_dv,
              coarse_q_start, drift, q_out, qd_out, dv_out, r0, r1):
    rows, cols = mass.shape
    fx, fy, fz = np.empty(cols), np.empty(cols), np.empty(cols)
    # forward spring terms of rows r-2 .. r (row t in slot t % 3): each spring once
    terms = np.empty((3, stiffness.shape[0] // 2, 3, cols))
    for t in range(max(r0 - 2, 0), r0):
        forward_terms_row(q, qd, t, rest, stiffness, contraction, h, terms[t % 3])
    # the estimate of rows r-2 .. r+2
    ring = np.empty((3, ESTIMATE_RING, cols))
    for t in range(max(r0 - 2, 0), min(r0 + 2, rows)):
        _estimate_row(coarse_dv, hold_kind, prescribed_dv, t, ring)
    sx, sy, sz = np.empty(cols), np.empty(cols), np.empty(cols)
    h2 = h * h
    exact = 0.0 if literal else h
    shift = (exact * gravity[0], exact * gravity[1], exact * gravity[2])
    for r in range(r0, r1):
        # every column, inherited ones included (overwritten below): a contiguous loop
        # vectorises, a stride-2 one over the inserted points would not
        forward_terms_row(q, qd, r, rest, stiffness, contraction, h, terms[r % 3])
        paired_force_row(terms, r, rows, fx, fy, fz)
        if r + 2 < rows:
            _estimate_row(coarse_dv, hold_kind, prescribed_dv, r + 2, ring)
        stencil_sum_row(ring, r, rows, stiffness, shift, sx, sy, sz)
        kinds, m, w = hold_kind[r], mass[r], inv_diagonal[r]
        for d in range(q.shape[0]):
            force = fx if d == 0 else (fy if d == 1 else fz)
            neighbours = sx if d == 0 else (sy if d == 1 else sz)
            fixed, dv, g, g_exact = prescribed_dv[d, r], dv_out[d, r], gravity[d], shift[d]
            for i in range(cols):
                f = force[i] + m[i] * g if literal else force[i]
                dv[i] = (fixed[i] if kinds[i] != FREE
                         else (h * f + h2 * neighbours[i]) * w[i] + g_exact)
            advance_row(q[d, r], qd[d, r], dv, h, q_out[d, r], qd_out[d, r])
        if r % 2 == 0:
            _inherit_row(coarse_q, coarse_qd, coarse_dv, r, q_out, qd_out, dv_out)
        if drift:   # while the row is in cache: a pass of its own cost 0.46 ms at 257 x 257
            _add_drift_row(coarse_q, coarse_q_start, coarse_qd, h, hold_kind, q_out, r)


def eq7_level(
        # inputs: this level at the start of the step
        q, qd, mass, rest, stiffness, contraction, inv_diagonal, hold_kind, prescribed_dv,
        # inputs: the step
        h, gravity, literal,
        # inputs: level k-1 after the step (its velocity change, prolonged, is the estimate)
        coarse_q, coarse_qd, coarse_dv,
        # inputs: level k-1 at the start of the step, and whether its drift is added
        coarse_q_start, drift,
        # outputs: this level after the step and its velocity change
        q_out, qd_out, dv_out):
    """
    One refinement level of Table 1: constraint C, then eq. 7 on inserted points.

    With ``drift``, the free inserted points then move by level k-1's prolonged drift
    beyond ``h v+`` (see :func:`_add_drift_row`; the multigrid solver's BDF2 level).
    """
    for j in range(0, stiffness.shape[0], 2):
        if rest[j] != rest[j + 1] or stiffness[j] != stiffness[j + 1]:
            raise ValueError('eq7_level: opposite stencil entries must be one spring')
    rows, cols = mass.shape
    chunks = chunk_count(rows, cols)
    for ch in prange(chunks):
        _eq7_rows(q, qd, mass, rest, stiffness, contraction, inv_diagonal, hold_kind,
                  prescribed_dv, h, gravity, literal, coarse_q, coarse_qd, coarse_dv,
                  coarse_q_start, drift, q_out, qd_out, dv_out,
                  ch * rows // chunks,
                  (ch + 1) * rows // chunks)


eq7_level, eq7_level_parallel = serial_and_parallel(eq7_level)
