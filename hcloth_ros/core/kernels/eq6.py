"""
The paper's eq. 6: two Jacobi sweeps of linearised backward Euler on one level.

With the paper's Jacobian approximation (``J_ij = k_ij I``, ``J_ii = -K_i I``,
``K_i = sum_j k_ij``) the system ``(M - h^2 J) dv = h f~`` of eq. 3 has the diagonal
``D_i = m_i + h^2 K_i``; the solver passes ``inv_diagonal = 1 / D``. Two sweeps from
``dv = 0``:

    first:   a_i  = h f~_i / D_i
    second:  dv_i = (h f~_i + h^2 sum_j k_ij a_j) / D_i

then ``v += dv`` and ``x += h v``. ``f~`` is eq. 4's filtered force
(:func:`~hcloth_ros.core.kernels.springs.force_row`). Held points are Dirichlet rows: their
``dv`` is the prescribed change. With ``literal`` gravity is part of ``f~`` (the paper as
written); otherwise it is applied exactly, outside the filter: ``a`` holds the spring
part only, a held point's ``a`` is its prescribed change less ``h g``, and ``h g`` is
added to every free point's ``dv``.
"""

from hcloth_ros.core.kernels.jit import BORROW, JIT
from hcloth_ros.core.kernels.layout import advance_row, FREE
from hcloth_ros.core.kernels.springs import force_row, stencil_sum_row
import numba
import numpy as np


@numba.njit(**BORROW)
def _first_sweep_component(force, mass, inv_diagonal, hold_kind, prescribed_dv, h, literal,
                           g, h_ftilde, dv_first):
    """One row and component of the first sweep, from the row's spring force."""
    held_shift = 0.0 if literal else h * g
    for i in range(force.shape[0]):
        f = force[i] + mass[i] * g if literal else force[i]
        h_ftilde[i] = h * f
        dv_first[i] = (prescribed_dv[i] - held_shift if hold_kind[i] != FREE
                       else h * f * inv_diagonal[i])


@numba.njit(**JIT)
def eq6_first_sweep(
        # inputs: the level at the start of the step
        q, qd, mass, rest, stiffness, contraction, inv_diagonal, hold_kind, prescribed_dv,
        # inputs: the step
        h, gravity, literal,
        # outputs: h f~ and the first sweep's velocity change a
        h_ftilde, dv_first):
    """First Jacobi sweep of eq. 6: ``h_ftilde = h f~``, ``dv_first = h f~ / D``."""
    rows, cols = mass.shape
    fx, fy, fz = np.empty(cols), np.empty(cols), np.empty(cols)
    for r in range(rows):
        force_row(q, qd, r, rest, stiffness, contraction, h, True, fx, fy, fz)
        for d in range(q.shape[0]):
            _first_sweep_component(fx if d == 0 else (fy if d == 1 else fz), mass[r],
                                   inv_diagonal[r], hold_kind[r], prescribed_dv[d, r], h,
                                   literal, gravity[d], h_ftilde[d, r], dv_first[d, r])


@numba.njit(**JIT)
def eq6_second_sweep(
        # inputs: the level at the start of the step
        q, qd, stiffness, inv_diagonal, hold_kind, prescribed_dv,
        # inputs: the first sweep's outputs
        h_ftilde, dv_first,
        # inputs: the step
        h, gravity, literal,
        # outputs: the level after the step and its velocity change
        q_out, qd_out, dv_out):
    """Second sweep of eq. 6, then ``v += dv``, ``x += h v`` (semi-implicit order)."""
    rows, cols = inv_diagonal.shape
    sx, sy, sz = np.empty(cols), np.empty(cols), np.empty(cols)
    h2 = h * h
    exact = 0.0 if literal else h
    for r in range(rows):
        stencil_sum_row(dv_first, r, dv_first.shape[1], stiffness, (0.0, 0.0, 0.0), sx, sy,
                        sz)
        kinds, w = hold_kind[r], inv_diagonal[r]
        for d in range(q.shape[0]):
            neighbours = sx if d == 0 else (sy if d == 1 else sz)
            fixed, ft, dv = prescribed_dv[d, r], h_ftilde[d, r], dv_out[d, r]
            g = exact * gravity[d]
            for i in range(cols):
                dv[i] = (fixed[i] if kinds[i] != FREE
                         else (ft[i] + h2 * neighbours[i]) * w[i] + g)
            advance_row(q[d, r], qd[d, r], dv, h, q_out[d, r], qd_out[d, r])
