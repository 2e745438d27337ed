"""
Backward Euler's linear algebra (the converged reference solver).

Each Newton iteration of :class:`~hcloth_ros.core.solvers.ImplicitSolver` solves

    (M - h^2 J) dv = b

with ``J`` the spring force Jacobian (Baraff and Witkin 1998): each spring contributes
the block ``-B = -k (b I + (1 - b) u u^T)``, ``u`` its direction and
``b = max(0, 1 - L / |d|)``; clamping ``b`` at zero for compressed springs drops their
negative transverse stiffness, which keeps the matrix positive definite (Newton still
converges to the exact backward-Euler step: the residual is exact). Held points are
Dirichlet rows (identity). CG with the Jacobi preconditioner solves it matrix-free.
"""

import math

from hcloth_ros.core.kernels.jit import BORROW, JIT, serial_and_parallel
from hcloth_ros.core.kernels.layout import (chunk_count, interleaved_dot, row3,
                                            STENCIL_DC, STENCIL_DR,
                                            stencil_span)
from hcloth_ros.core.kernels.springs import force_row, spring_vector
import numba
from numba import prange


@numba.njit(**JIT)
def spring_forces(q, rest, stiffness, contraction, force):
    """Spring forces on every point (N), no damping: ``force`` ``(3, rows, cols)``."""
    for r in range(q.shape[1]):
        force_row(q, q, r, rest, stiffness, contraction, 0.0, False, force[0, r],
                  force[1, r], force[2, r])


@numba.njit(**JIT)
def stiffness_block(dx, dy, dz, length, rest, stiffness, contraction):
    """
    ``(k, b, u)`` of the spring block ``B = k (b I + (1 - b) u u^T)`` (see the module).

    ``k`` is the contraction-scaled stiffness of a compressed spring; a spring of zero
    length has ``b = 1`` (isotropic) and no direction.
    """
    k = stiffness if length >= rest else stiffness * contraction
    if length <= 0.0:
        return k, 1.0, 0.0, 0.0, 0.0
    return k, max(0.0, 1.0 - rest / length), dx / length, dy / length, dz / length


@numba.njit(**BORROW)
def _system_row(q, rest, stiffness, contraction, mass, free, h, p, r, diagonal, out):
    """
    Write row r of ``(M - h^2 J) p`` into ``out`` (identity on held points).

    With ``diagonal``, the row's diagonal entries instead (``p`` unused; 1 on held points).
    """
    rows, cols = mass.shape
    h2 = h * h
    ox, oy, oz = row3(out, r, 0)
    px, py, pz = row3(p, r, 0)
    for c in range(cols):
        m = mass[r, c]
        ox[c] = m if diagonal else m * px[c]
        oy[c] = m if diagonal else m * py[c]
        oz[c] = m if diagonal else m * pz[c]
    for s in range(stiffness.shape[0]):
        lo, hi = stencil_span(r, s, rows, cols)
        if hi <= lo:
            continue
        rn, cn = r + STENCIL_DR[s], lo + STENCIL_DC[s]
        xp, yp, zp = row3(q, r, lo)
        xn, yn, zn = row3(q, rn, cn)
        ap, bp, cp = row3(p, r, lo)
        an, bn, cn_ = row3(p, rn, cn)
        free_n = free[rn, cn:]
        tx, ty, tz = ox[lo:], oy[lo:], oz[lo:]
        for i in range(hi - lo):
            dx, dy, dz, length = spring_vector(xn, yn, zn, xp, yp, zp, i)
            k, b, ux, uy, uz = stiffness_block(dx, dy, dz, length, rest[s], stiffness[s],
                                               contraction)
            if diagonal:
                tx[i] += h2 * k * (b + (1.0 - b) * ux * ux)
                ty[i] += h2 * k * (b + (1.0 - b) * uy * uy)
                tz[i] += h2 * k * (b + (1.0 - b) * uz * uz)
            else:
                f = free_n[i]
                ex, ey, ez = ap[i] - f * an[i], bp[i] - f * bn[i], cp[i] - f * cn_[i]
                proj = (1.0 - b) * (ux * ex + uy * ey + uz * ez)
                tx[i] += h2 * k * (b * ex + proj * ux)
                ty[i] += h2 * k * (b * ey + proj * uy)
                tz[i] += h2 * k * (b * ez + proj * uz)
    held = free[r]
    for c in range(cols):
        if held[c] == 0.0:
            ox[c] = 1.0 if diagonal else px[c]
            oy[c] = 1.0 if diagonal else py[c]
            oz[c] = 1.0 if diagonal else pz[c]


def system_apply(q, rest, stiffness, contraction, mass, free, h, p, out):
    """``out = (M - h^2 J) p`` on free points (``free`` 1.0), ``p`` on held ones (0.0)."""
    rows, cols = mass.shape
    chunks = chunk_count(rows, cols)
    for ch in prange(chunks):
        for r in range(ch * rows // chunks, (ch + 1) * rows // chunks):
            _system_row(q, rest, stiffness, contraction, mass, free, h, p, r, False, out)


system_apply, system_apply_parallel = serial_and_parallel(system_apply)


@numba.njit(**JIT)
def system_diagonal(q, rest, stiffness, contraction, mass, free, h, diagonal):
    """Diagonal of the system of :func:`system_apply` (the Jacobi preconditioner)."""
    for r in range(mass.shape[0]):
        _system_row(q, rest, stiffness, contraction, mass, free, h, diagonal, r, True,
                    diagonal)


@numba.njit(**JIT)
def _dot(a, b):
    """Dot product of two C-contiguous arrays (as flat vectors)."""
    return interleaved_dot(a.reshape(a.size), b.reshape(b.size), a.size)


def conjugate_gradient(q, rest, stiffness, contraction, mass, free, h, b, x, diagonal, rtol,
                       max_iter, r, z, p, ap):
    """
    Solve ``(M - h^2 J) x = b`` from ``x = 0`` by Jacobi-preconditioned CG.

    Stops at ``|r| <= rtol |b|`` or after ``max_iter`` iterations; returns
    ``(iterations, |r| / |b|)``. ``r, z, p, ap``: C-contiguous work arrays.
    """
    # vectors as flat views, updated by loops: array expressions would cost seconds of
    # compilation and temporaries
    n = x.size
    xf, rf, zf, pf = x.reshape(n), r.reshape(n), z.reshape(n), p.reshape(n)
    af, bf, df = ap.reshape(n), b.reshape(n), diagonal.reshape(n)
    for i in range(n):
        xf[i] = 0.0
        rf[i] = bf[i]
        zf[i] = rf[i] / df[i]
        pf[i] = zf[i]
    bnorm = math.sqrt(_dot(b, b))
    if bnorm == 0.0:
        return 0, 0.0
    rz = _dot(r, z)
    rel = 1.0
    for it in range(1, max_iter + 1):
        system_apply(q, rest, stiffness, contraction, mass, free, h, p, ap)
        alpha = rz / _dot(p, ap)
        for i in range(n):
            xf[i] += alpha * pf[i]
            rf[i] -= alpha * af[i]
        rel = math.sqrt(_dot(r, r)) / bnorm
        if rel <= rtol:
            return it, rel
        for i in range(n):
            zf[i] = rf[i] / df[i]
        rz_new = _dot(r, z)
        beta = rz_new / rz
        for i in range(n):
            pf[i] = zf[i] + beta * pf[i]
        rz = rz_new
    return max_iter, rel


conjugate_gradient, conjugate_gradient_parallel = serial_and_parallel(
    conjugate_gradient, parfor=False, system_apply=system_apply_parallel)
