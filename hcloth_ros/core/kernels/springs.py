"""
Spring forces and stencil sums along a grid row: the pieces every step is made of.

Every per-row function covers the whole row, border columns included: each stencil
direction is one loop over the span of columns whose neighbour exists
(:func:`~hcloth_ros.core.kernels.layout.stencil_span`). A point's sum adds the stencil
entries in order 0 .. 11, skipping missing neighbours, whatever its position, so border
and interior points follow one formula. One direction per loop keeps each loop's arrays
few enough for LLVM to check them for overlap at run time and vectorise (a loop over all
twelve reads too many distinct arrays and stays scalar).
"""

import math

from hcloth_ros.core.kernels.jit import JIT
from hcloth_ros.core.kernels.layout import (clear3, row3, STENCIL_DC, STENCIL_DR,
                                            stencil_span)
import numba


@numba.njit(**JIT)
def spring_vector(xn, yn, zn, xp, yp, zp, i):
    """Return the vector ``d`` (m) and the length of the spring from ``p[i]`` to ``n[i]``."""
    dx = xn[i] - xp[i]
    dy = yn[i] - yp[i]
    dz = zn[i] - zp[i]
    return dx, dy, dz, math.sqrt(dx * dx + dy * dy + dz * dz)


@numba.njit(**JIT)
def spring_coefficient(length, rest, stiffness, contraction):
    """
    Hooke's law as force per metre of spring vector: ``f = coef * d`` (N/m).

    ``coef = k (|d| - L) / |d|`` with ``k`` the stiffness when stretched and
    ``contraction * k`` when compressed (the paper's contraction resistance c); 0 for a
    spring of zero length (no direction).
    """
    stretch = length - rest
    k = stiffness if stretch >= 0.0 else stiffness * contraction
    return k * stretch / length if length > 0.0 else 0.0


@numba.njit(**JIT)
def force_row(q, qd, r, rest, stiffness, contraction, h, viscous, fx, fy, fz):
    """
    Spring force on every point of row r into ``fx, fy, fz`` (N), shape ``(cols,)``.

    ``f_i = sum_s coef_s d_s`` over the existing stencil neighbours (see
    :func:`spring_coefficient`); with ``viscous``, the paper's eq. 4 filtered force
    ``f~_i = f_i + h sum_s k_s (v_s - v_i)``, i.e. ``f + h J v`` with the diagonal
    Jacobian approximation ``J_ij = k_ij I``. ``qd`` is read only if ``viscous``.
    """
    rows, cols = q.shape[1], q.shape[2]
    clear3(fx, fy, fz)
    for s in range(stiffness.shape[0]):
        lo, hi = stencil_span(r, s, rows, cols)
        if hi <= lo:
            continue
        dr, dc = STENCIL_DR[s], STENCIL_DC[s]
        xp, yp, zp = row3(q, r, lo)
        xn, yn, zn = row3(q, r + dr, lo + dc)
        up, vp, wp = row3(qd, r, lo)
        un, vn, wn = row3(qd, r + dr, lo + dc)
        ox, oy, oz = fx[lo:], fy[lo:], fz[lo:]
        k, length0, hk = stiffness[s], rest[s], h * stiffness[s]
        for i in range(hi - lo):
            dx, dy, dz, length = spring_vector(xn, yn, zn, xp, yp, zp, i)
            coef = spring_coefficient(length, length0, k, contraction)
            if viscous:
                ox[i] += coef * dx + hk * (un[i] - up[i])
                oy[i] += coef * dy + hk * (vn[i] - vp[i])
                oz[i] += coef * dz + hk * (wn[i] - wp[i])
            else:
                ox[i] += coef * dx
                oy[i] += coef * dy
                oz[i] += coef * dz


@numba.njit(**JIT)
def forward_terms_row(q, qd, r, rest, stiffness, contraction, h, out):
    """
    Row r's share of :func:`force_row` (viscous) from the springs its points start.

    ``out[j, d, c]``: component d of the term of spring ``2 j`` (the even stencil entries:
    right, down, the two downward diagonals, two right, two down) on point ``(r, c)``,
    written over each direction's span of columns. The same spring seen from its other end
    (entry ``2 j + 1``) contributes exactly the negated term: the vector, the velocity
    difference and so the product change sign, the length and coefficient do not.
    """
    rows, cols = q.shape[1], q.shape[2]
    for j in range(out.shape[0]):
        s = 2 * j
        lo, hi = stencil_span(r, s, rows, cols)
        if hi <= lo:
            continue
        # views written out here, not returned by a helper: a helper's 12 views stopped
        # LLVM vectorising force_row's loop (Newton residual 0.42 -> 1.0 ms a call)
        dr, dc = STENCIL_DR[s], STENCIL_DC[s]
        xp, yp, zp = row3(q, r, lo)
        xn, yn, zn = row3(q, r + dr, lo + dc)
        up, vp, wp = row3(qd, r, lo)
        un, vn, wn = row3(qd, r + dr, lo + dc)
        tx, ty, tz = out[j, 0, lo:], out[j, 1, lo:], out[j, 2, lo:]
        k, length0, hk = stiffness[s], rest[s], h * stiffness[s]
        for i in range(hi - lo):
            dx, dy, dz, length = spring_vector(xn, yn, zn, xp, yp, zp, i)
            coef = spring_coefficient(length, length0, k, contraction)
            tx[i] = coef * dx + hk * (un[i] - up[i])
            ty[i] = coef * dy + hk * (vn[i] - vp[i])
            tz[i] = coef * dz + hk * (wn[i] - wp[i])


@numba.njit(**JIT)
def paired_force_row(terms, r, rows, fx, fy, fz):
    """
    :func:`force_row` (viscous) of row r from :func:`forward_terms_row`'s terms.

    ``terms[t]`` holds the forward terms of the rows ``t, t + 3, ...``; rows ``r - 2 .. r``
    must be there. The twelve entries are added in stencil order, a backward one as its
    forward twin's term subtracted, so the result is :func:`force_row`'s to the bit with
    each spring evaluated once instead of twice (paired entries share rest length and
    stiffness).
    """
    cols = fx.shape[0]
    clear3(fx, fy, fz)
    for s in range(2 * terms.shape[1]):
        lo, hi = stencil_span(r, s, rows, cols)
        if hi <= lo:
            continue
        ox, oy, oz = fx[lo:], fy[lo:], fz[lo:]
        if s % 2 == 0:
            t = terms[r % 3, s // 2]
            tx, ty, tz = t[0, lo:], t[1, lo:], t[2, lo:]
            for i in range(hi - lo):
                ox[i] += tx[i]
                oy[i] += ty[i]
                oz[i] += tz[i]
        else:
            # entry s from (r, c) is entry s - 1 from (r + dr, c + dc)
            t = terms[(r + STENCIL_DR[s]) % 3, s // 2]
            start = lo + STENCIL_DC[s]
            tx, ty, tz = t[0, start:], t[1, start:], t[2, start:]
            for i in range(hi - lo):
                ox[i] -= tx[i]
                oy[i] -= ty[i]
                oz[i] -= tz[i]


@numba.njit(**JIT)
def stencil_sum_row(a, r, rows, stiffness, shift, sx, sy, sz):
    """
    Sum ``k_s (a[:, neighbour_s] - shift)`` over s for every point of row r into ``s*``.

    The off-diagonal product of the paper's Jacobian approximation with a field (eq. 6's
    second sweep, eq. 7's neighbour term); ``shift`` (3 floats) is subtracted from every
    neighbour value. The level has ``rows`` rows; its row t is ``a[:, t % a.shape[1]]``:
    ``a`` is the whole level, or a ring of the rows around r.
    """
    cols = a.shape[2]
    period = a.shape[1]
    gx, gy, gz = shift
    clear3(sx, sy, sz)
    for s in range(stiffness.shape[0]):
        lo, hi = stencil_span(r, s, rows, cols)
        if hi <= lo:
            continue
        xn, yn, zn = row3(a, (r + STENCIL_DR[s]) % period, lo + STENCIL_DC[s])
        ox, oy, oz = sx[lo:], sy[lo:], sz[lo:]
        k = stiffness[s]
        for i in range(hi - lo):
            ox[i] += k * (xn[i] - gx)
            oy[i] += k * (yn[i] - gy)
            oz[i] += k * (zn[i] - gz)
