r"""
The nonlinear equations of an implicit step: BDF2, and backward Euler as its first step.

Both write the new state as

    x+ = x^ + beta v+,    M (v+ - v^) = beta F(x+, v+)

BDF2 (second order, A-stable): ``x^ = (4 x_n - x_{n-1}) / 3``, ``v^ = (4 v_n - v_{n-1}) / 3``,
``beta = 2 h / 3``. Backward Euler (first order; BDF2's first step): ``x^ = x_n``,
``v^ = v_n``, ``beta = h``. ``F`` is the spring force, spring damping
``d ((v_j - v_i) . u) u`` along each spring, gravity ``m g`` and air drag
``-drag_i v_i`` (``drag_i`` = drag per unit area times the point's share of the area).

Newton's method on ``v+`` solves ``A dv = -R(v+)`` with the residual
``R = M (v+ - v^) - beta F(x^ + beta v+, v+)`` and ``A`` of :mod:`.multigrid`.
Held points are not unknowns: their new position is their target and ``v+`` the
velocity that reaches it, ``(target - x^) / beta``.
"""

from hcloth_ros.core.kernels.jit import BORROW, JIT
from hcloth_ros.core.kernels.layout import FREE, PINNED, row3, STENCIL_DC, STENCIL_DR, stencil_span
from hcloth_ros.core.kernels.springs import force_row, spring_vector
import numba
import numpy as np


@numba.njit(**JIT)
def new_positions(x_hat, v, target, hold_kind, beta, x_new):
    """``x+ = x^ + beta v+`` on free points, the target on held ones (bit for bit)."""
    rows, cols = hold_kind.shape
    for d in range(3):
        for r in range(rows):
            kinds = hold_kind[r]
            xh, vv, tg, out = x_hat[d, r], v[d, r], target[d, r], x_new[d, r]
            for c in range(cols):
                out[c] = xh[c] + beta * vv[c] if kinds[c] == FREE else tg[c]


@numba.njit(**JIT)
def anchor(q, qd, q_previous, qd_previous, history, hold_kind, x_hat, v_hat):
    """
    Compute the step's anchor ``x^, v^``: BDF2's with a ``history``, else backward Euler's.

    A pinned point's ``x^`` is its position, bit for bit (``(4 x - x) / 3`` need not be),
    so that ``x^ + beta * 0`` keeps it where it is.
    """
    rows, cols = hold_kind.shape
    third = 1.0 / 3.0
    for d in range(3):
        for r in range(rows):
            kinds = hold_kind[r]
            x, v, xp, vp = q[d, r], qd[d, r], q_previous[d, r], qd_previous[d, r]
            xh, vh = x_hat[d, r], v_hat[d, r]
            for c in range(cols):
                if history and kinds[c] != PINNED:
                    xh[c] = (4.0 * x[c] - xp[c]) * third
                    vh[c] = (4.0 * v[c] - vp[c]) * third
                else:
                    xh[c] = x[c]
                    vh[c] = v[c]


@numba.njit(**JIT)
def start_velocity(qd, h, gravity, v_hat, prescribed_dv, hold_kind, v):
    """
    Newton's first guess of ``v+``: ``v_n + h g`` on free points, exact on held ones.

    Held: ``v^ + prescribed change`` (:func:`.holds.prescribe` run on the anchor with step
    beta). Not the extrapolation ``2 v_n - v_{n-1}``: it overshoots where the cloth turns
    and three Newton iterations do not recover (0.12 m against 0.035 m on the 33 x 33
    swing).
    """
    rows, cols = hold_kind.shape
    for d in range(3):
        g = h * gravity[d]
        for r in range(rows):
            kinds = hold_kind[r]
            for c in range(cols):
                v[d, r, c] = (qd[d, r, c] + g if kinds[c] == FREE
                              else v_hat[d, r, c] + prescribed_dv[d, r, c])


@numba.njit(**BORROW)
def _damping_row(x, v, r, springs, damping, fx, fy, fz):
    """
    Add spring damping ``d ((v_j - v_i) . u) u`` of row r's springs (N).

    ``springs``: the stencil entries to loop over (12), passed in so the loop count is
    not a compile-time constant (see :mod:`.layout`). A pass of its own, not a term in
    :func:`.springs.force_row`: a damping branch in that loop stopped it vectorising and
    slowed eq. 7 on 257 x 257 from 5.0-5.4 ms to 6.1-6.2 ms (one thread).
    """
    rows, cols = x.shape[1], x.shape[2]
    for s in range(springs):
        lo, hi = stencil_span(r, s, rows, cols)
        if hi <= lo:
            continue
        dr, dc = STENCIL_DR[s], STENCIL_DC[s]
        xp, yp, zp = row3(x, r, lo)
        xn, yn, zn = row3(x, r + dr, lo + dc)
        up, vp, wp = row3(v, r, lo)
        un, vn, wn = row3(v, r + dr, lo + dc)
        ox, oy, oz = fx[lo:], fy[lo:], fz[lo:]
        for i in range(hi - lo):
            dx, dy, dz, length = spring_vector(xn, yn, zn, xp, yp, zp, i)
            if length > 0.0:
                rate = damping * ((un[i] - up[i]) * dx + (vn[i] - vp[i]) * dy
                                  + (wn[i] - wp[i]) * dz) / (length * length)
                ox[i] += rate * dx
                oy[i] += rate * dy
                oz[i] += rate * dz


@numba.njit(**JIT)
def newton_residual(
        # inputs: the step's anchor (x^, v^, beta), the guess v+ and the held targets
        x_hat, v_hat, v, target, hold_kind, beta,
        # inputs: the level's material and gravity
        mass, air_drag, rest, stiffness, contraction, damping, gravity,
        # outputs: positions at the guess and the right-hand side -R (0 on held points)
        x_new, rhs):
    """
    ``rhs = beta F(x+, v+) - M (v+ - v^)`` on free points, 0 on held ones (N s).

    ``x_new`` gets ``x+`` of the guess (:func:`new_positions`).
    """
    rows, cols = hold_kind.shape
    new_positions(x_hat, v, target, hold_kind, beta, x_new)
    fx, fy, fz = np.empty(cols), np.empty(cols), np.empty(cols)
    for r in range(rows):
        force_row(x_new, x_new, r, rest, stiffness, contraction, 0.0, False, fx, fy, fz)
        if damping > 0.0:
            _damping_row(x_new, v, r, stiffness.shape[0], damping, fx, fy, fz)
        kinds, m, drag = hold_kind[r], mass[r], air_drag[r]
        for d in range(3):
            force = fx if d == 0 else (fy if d == 1 else fz)
            vv, vh, out, g = v[d, r], v_hat[d, r], rhs[d, r], gravity[d]
            for c in range(cols):
                total = force[c] + m[c] * g - drag[c] * vv[c]
                out[c] = beta * total - m[c] * (vv[c] - vh[c]) if kinds[c] == FREE else 0.0
