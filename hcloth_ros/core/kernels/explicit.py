"""Symplectic Euler on one level: the baseline, stable only below ``2 / w_max``."""

from hcloth_ros.core.kernels.jit import JIT
from hcloth_ros.core.kernels.layout import advance_row, FREE
from hcloth_ros.core.kernels.springs import force_row
import numba
import numpy as np


@numba.njit(**JIT)
def explicit_step(
        # inputs: the level at the start of the step
        q, qd, mass, rest, stiffness, contraction, hold_kind, prescribed_dv,
        # inputs: the step
        h, gravity,
        # outputs: the level after the step and its velocity change
        q_out, qd_out, dv_out):
    """``dv = h (f / m + g)`` on free points (held: prescribed), ``v += dv``, ``x += h v``."""
    rows, cols = mass.shape
    fx, fy, fz = np.empty(cols), np.empty(cols), np.empty(cols)
    for r in range(rows):
        force_row(q, qd, r, rest, stiffness, contraction, h, False, fx, fy, fz)
        kinds, m = hold_kind[r], mass[r]
        for d in range(q.shape[0]):
            force, fixed, dv, g = (fx if d == 0 else (fy if d == 1 else fz),
                                   prescribed_dv[d, r], dv_out[d, r], gravity[d])
            for i in range(cols):
                dv[i] = fixed[i] if kinds[i] != FREE else h * (force[i] * (1.0 / m[i]) + g)
            advance_row(q[d, r], qd[d, r], dv, h, q_out[d, r], qd_out[d, r])
