r"""
An implicit step's Newton system, solved by CG preconditioned with a V-cycle over the levels.

The system of one Newton iteration of an implicit step (backward Euler or BDF2, see
:mod:`.bdf2`) on a level is

    A dv = b,    A = M + beta D_air + beta^2 K + beta C

with ``M`` the lumped masses, ``D_air`` the air drag per point, ``K`` the clamped spring
stiffness and ``C`` the spring damping; ``beta`` is ``h`` for backward Euler and
``2 h / 3`` for BDF2. Every spring (i, j) adds the 3 x 3 block

    B = a u u^T + c I,   a = beta^2 k (1 - b) + beta d,   c = beta^2 k b,
    b = max(0, 1 - L / |x_j - x_i|)

(``u`` the spring's direction, ``k`` its stiffness, times the contraction resistance when
compressed, ``d`` its damping coefficient) to the diagonal blocks of i and j and ``-B``
to the two off-diagonal ones (Baraff and Witkin 1998). Clamping ``b`` at zero for
compressed springs drops their negative transverse stiffness: ``A`` stays symmetric
positive definite, so CG applies. Held points are Dirichlet rows (their correction is 0)
on every level.

Storage, per level: each spring's ``a``, ``c`` and ``u`` once, at the end point it leaves
in an even stencil direction (``2 j``); a point reads a spring of an odd direction
``2 j + 1`` at the neighbour it points to, whose direction ``2 j`` is the same spring.
So the products gather (no atomics) and the blocks are computed once per spring.

Preconditioner: one V-cycle over the model's own levels, coarse to fine as the hierarchy
nests them (a level-k-1 point is the level-k point at twice its row and column):

* smoothing: damped 3 x 3 block Jacobi, ``x += omega D_i^-1 (b - A x)_i`` with ``D_i`` the
  point's diagonal block (point Jacobi misses the ``k u u^T`` coupling inside a block and
  diverges);
* transfer: the hierarchy's own prolongation (an inserted point takes the mean of the two
  ends of the edge it was inserted on: linear interpolation on the triangles) and its
  transpose as restriction;
* coarse operators: each coarser level's own springs evaluated at the fine positions
  injected (re-discretised, not Galerkin ``P^T A P``: as cheap as one fine assembly, and a
  good enough preconditioner even though it is a poor solver on its own);
* the coarsest grid: solved exactly (dense Cholesky, :func:`coarse_cholesky`) when it has
  at most ``DENSE_MAX_POINTS`` points, else ``coarse_sweeps`` block-Jacobi sweeps.

The same number of sweeps before and after the coarse correction and a Jacobi smoother
make the V-cycle a symmetric linear operator, as CG needs.

All levels of a hierarchy live in flat buffers, each level at its point offset
(``offsets[l]``): one call runs a whole V-cycle or a whole PCG solve, with no Python
between the levels.
"""

import math

from hcloth_ros.core.kernels.jit import JIT
from hcloth_ros.core.kernels.layout import interleaved_dot, row3, STENCIL_DC, STENCIL_DR, \
    stencil_span
from hcloth_ros.core.kernels.springs import spring_vector
import numba
import numpy as np

# Largest coarsest grid solved by dense Cholesky (75 unknowns: about 0.1 M operations).
DENSE_MAX_POINTS = 25


@numba.njit(**JIT)
def level_field(buffer, offsets, level, entries, rows, cols):
    """Level ``level``'s ``(entries, rows, cols)`` view of a flat buffer of all levels."""
    start = entries * offsets[level]
    return buffer[start:start + entries * rows * cols].reshape(entries, rows, cols)


@numba.njit(**JIT)
def level_directions(buffer, offsets, level, rows, cols):
    """Level ``level``'s spring directions ``(6, 3, rows, cols)`` from a flat buffer."""
    start = 18 * offsets[level]
    return buffer[start:start + 18 * rows * cols].reshape(6, 3, rows, cols)


@numba.njit(**JIT)
def assemble_level(
        # inputs: positions to linearise at, the level's springs, the step's factor
        x, rest, stiffness, contraction, damping, beta,
        # outputs: each spring's a, c (N/m * s^2 / ... as in the module docstring) and u
        coef_uu, coef_iso, directions):
    """Store every spring's block ``a u u^T + c I`` of ``A`` (see the module docstring)."""
    rows, cols = x.shape[1], x.shape[2]
    b2 = beta * beta
    flat_a, flat_c = coef_uu.reshape(coef_uu.size), coef_iso.reshape(coef_iso.size)
    for i in range(flat_a.size):    # springs that do not exist stay 0 (see apply_level)
        flat_a[i] = 0.0
        flat_c[i] = 0.0
    for j in range(coef_uu.shape[0]):
        s = 2 * j
        dr, dc = STENCIL_DR[s], STENCIL_DC[s]
        length0, k0 = rest[s], stiffness[s]
        for r in range(rows):
            lo, hi = stencil_span(r, s, rows, cols)
            if hi <= lo:
                continue
            xp, yp, zp = row3(x, r, lo)
            xn, yn, zn = row3(x, r + dr, lo + dc)
            a_out, c_out = coef_uu[j, r, lo:], coef_iso[j, r, lo:]
            ux, uy, uz = directions[j, 0, r, lo:], directions[j, 1, r, lo:], \
                directions[j, 2, r, lo:]
            for i in range(hi - lo):
                dx, dy, dz, length = spring_vector(xn, yn, zn, xp, yp, zp, i)
                k = k0 if length >= length0 else k0 * contraction
                b = max(0.0, 1.0 - length0 / length) if length > 0.0 else 1.0
                inv = 1.0 / length if length > 0.0 else 0.0
                a_out[i] = b2 * k * (1.0 - b) + beta * damping
                c_out[i] = b2 * k * b
                ux[i] = dx * inv
                uy[i] = dy * inv
                uz[i] = dz * inv


@numba.njit(**JIT)
def _direction_span(s, rows, cols):
    """
    Flat index range ``lo .. hi-1`` of points whose neighbour in direction s is in range.

    Returns ``(lo, hi, offset, source)``: the neighbour of flat index i is ``i + offset``
    and the direction's spring is stored at ``i + source``. Points whose neighbour lies
    past the end of a row wrap onto the next row: their spring does not exist, and its
    stored coefficients are 0, so it adds nothing.
    """
    offset = STENCIL_DR[s] * cols + STENCIL_DC[s]
    n = rows * cols
    if s % 2 == 0:          # even directions point forwards: offset > 0
        return 0, max(0, n - offset), offset, 0
    return min(n, -offset), n, offset, offset


@numba.njit(**JIT)
def _springs_of(coef_uu, coef_iso, directions, s, start, stop):
    """Flat views ``a, c, ux, uy, uz`` of direction s's springs, entries start .. stop-1."""
    j, n = s // 2, coef_uu.shape[1] * coef_uu.shape[2]
    return (coef_uu[j].reshape(n)[start:stop], coef_iso[j].reshape(n)[start:stop],
            directions[j, 0].reshape(n)[start:stop], directions[j, 1].reshape(n)[start:stop],
            directions[j, 2].reshape(n)[start:stop])


@numba.njit(**JIT)
def diagonal_inverse(mass, free, coef_uu, coef_iso, directions, block_inverse):
    """
    Each free point's inverse diagonal block ``D_i^-1`` (identity on held points).

    ``D_i = mass_i I + sum over its springs of (a u u^T + c I)``; ``mass`` already holds
    ``m + beta * air drag``. ``block_inverse`` is ``(6, rows, cols)``: xx, yy, zz, xy,
    xz, yz of the symmetric inverse.
    """
    rows, cols = mass.shape
    n = rows * cols
    m, fr = mass.reshape(n), free.reshape(n)
    inv = block_inverse.reshape(6, n)
    for i in range(n):
        for e in range(3):
            inv[e, i] = m[i]
            inv[e + 3, i] = 0.0
    for s in range(2 * coef_uu.shape[0]):
        lo, hi, _, src = _direction_span(s, rows, cols)
        a, c_iso, ux, uy, uz = _springs_of(coef_uu, coef_iso, directions, s, lo + src,
                                           hi + src)
        dxx, dyy, dzz = inv[0, lo:hi], inv[1, lo:hi], inv[2, lo:hi]
        dxy, dxz, dyz = inv[3, lo:hi], inv[4, lo:hi], inv[5, lo:hi]
        for i in range(hi - lo):
            dxx[i] += a[i] * ux[i] * ux[i] + c_iso[i]
            dyy[i] += a[i] * uy[i] * uy[i] + c_iso[i]
            dzz[i] += a[i] * uz[i] * uz[i] + c_iso[i]
            dxy[i] += a[i] * ux[i] * uy[i]
            dxz[i] += a[i] * ux[i] * uz[i]
            dyz[i] += a[i] * uy[i] * uz[i]
    for i in range(n):
        if fr[i] == 0.0:
            for e in range(3):
                inv[e, i] = 1.0
                inv[e + 3, i] = 0.0
            continue
        xx, yy, zz = inv[0, i], inv[1, i], inv[2, i]
        xy, xz, yz = inv[3, i], inv[4, i], inv[5, i]
        # cofactors of a symmetric 3 x 3 matrix
        cxx, cyy, czz = yy * zz - yz * yz, xx * zz - xz * xz, xx * yy - xy * xy
        cxy, cxz, cyz = xz * yz - xy * zz, xy * yz - xz * yy, xy * xz - xx * yz
        inv_det = 1.0 / (xx * cxx + xy * cxy + xz * cxz)
        inv[0, i] = cxx * inv_det
        inv[1, i] = cyy * inv_det
        inv[2, i] = czz * inv_det
        inv[3, i] = cxy * inv_det
        inv[4, i] = cxz * inv_det
        inv[5, i] = cyz * inv_det


@numba.njit(**JIT)
def apply_level(mass, free, coef_uu, coef_iso, directions, p, out):
    """
    ``out = A p`` on free points, 0 on held ones.

    ``(A p)_i = mass_i p_i + sum over springs (a u (u . w) + c w)``, ``w = p_i - p_j``.
    ``p`` must be 0 at held points (every vector of the PCG and the V-cycle is): a held
    neighbour's column is then eliminated with no test. One loop per stencil direction
    over the whole level as a flat array (:func:`_direction_span`): long loops that
    vectorise, with no per-row overhead, which dominated on small levels.
    """
    rows, cols = mass.shape
    n = rows * cols
    m, fr = mass.reshape(n), free.reshape(n)
    px, py, pz = p[0].reshape(n), p[1].reshape(n), p[2].reshape(n)
    ox, oy, oz = out[0].reshape(n), out[1].reshape(n), out[2].reshape(n)
    for i in range(n):
        ox[i] = m[i] * px[i]
        oy[i] = m[i] * py[i]
        oz[i] = m[i] * pz[i]
    for s in range(2 * coef_uu.shape[0]):
        lo, hi, off, src = _direction_span(s, rows, cols)
        a, c_iso, ux, uy, uz = _springs_of(coef_uu, coef_iso, directions, s, lo + src,
                                           hi + src)
        ax, ay, az = px[lo:hi], py[lo:hi], pz[lo:hi]
        nx, ny, nz = px[lo + off:hi + off], py[lo + off:hi + off], pz[lo + off:hi + off]
        tx, ty, tz = ox[lo:hi], oy[lo:hi], oz[lo:hi]
        for i in range(hi - lo):
            wx, wy, wz = ax[i] - nx[i], ay[i] - ny[i], az[i] - nz[i]
            proj = a[i] * (ux[i] * wx + uy[i] * wy + uz[i] * wz)
            tx[i] += proj * ux[i] + c_iso[i] * wx
            ty[i] += proj * uy[i] + c_iso[i] * wy
            tz[i] += proj * uz[i] + c_iso[i] * wz
    for i in range(n):
        ox[i] *= fr[i]
        oy[i] *= fr[i]
        oz[i] *= fr[i]


@numba.njit(**JIT)
def jacobi_update(block_inverse, free, b, ax, omega, zero_start, x):
    """
    One damped block-Jacobi sweep: ``x += omega D^-1 (b - A x)`` on free points.

    ``ax`` holds ``A x``; with ``zero_start`` x is taken as 0 (``x = omega D^-1 b``) and
    ``ax`` is not read. Held points stay 0.
    """
    rows, cols = free.shape
    keep = 0.0 if zero_start else 1.0
    for r in range(rows):
        for c in range(cols):
            if free[r, c] == 0.0:
                x[0, r, c] = x[1, r, c] = x[2, r, c] = 0.0
                continue
            rx = b[0, r, c] - keep * ax[0, r, c]
            ry = b[1, r, c] - keep * ax[1, r, c]
            rz = b[2, r, c] - keep * ax[2, r, c]
            xx, yy, zz = block_inverse[0, r, c], block_inverse[1, r, c], block_inverse[2, r, c]
            xy, xz, yz = block_inverse[3, r, c], block_inverse[4, r, c], block_inverse[5, r, c]
            x[0, r, c] = keep * x[0, r, c] + omega * (xx * rx + xy * ry + xz * rz)
            x[1, r, c] = keep * x[1, r, c] + omega * (xy * rx + yy * ry + yz * rz)
            x[2, r, c] = keep * x[2, r, c] + omega * (xz * rx + yz * ry + zz * rz)


@numba.njit(**JIT)
def restrict(fine, coarse_free, coarse):
    r"""
    ``coarse = P^T fine``: the transpose of the hierarchy's prolongation.

    A coarse point gathers its own fine point with weight 1 and the six fine points
    inserted on its edges (along rows, columns and the "\" diagonal) with weight 1/2;
    held coarse points get 0.
    """
    rows, cols = coarse.shape[1], coarse.shape[2]
    frows, fcols = fine.shape[1], fine.shape[2]
    for d in range(3):
        f, o = fine[d], coarse[d]
        for r in range(rows):
            fr = 2 * r
            for c in range(cols):
                if coarse_free[r, c] == 0.0:
                    o[r, c] = 0.0
                    continue
                fc = 2 * c
                total = 2.0 * f[fr, fc]
                if fc + 1 < fcols:
                    total += f[fr, fc + 1]
                if fc >= 1:
                    total += f[fr, fc - 1]
                if fr + 1 < frows:
                    total += f[fr + 1, fc]
                    if fc + 1 < fcols:
                        total += f[fr + 1, fc + 1]
                if fr >= 1:
                    total += f[fr - 1, fc]
                    if fc >= 1:
                        total += f[fr - 1, fc - 1]
                o[r, c] = 0.5 * total


@numba.njit(**JIT)
def prolong_add(coarse, fine_free, fine):
    r"""``fine += P coarse`` on free fine points (the parent rule of :func:`.eq7.prolong`)."""
    rows, cols = fine.shape[1], fine.shape[2]
    for d in range(3):
        a, f = coarse[d], fine[d]
        for r in range(rows):
            ra, rb = r // 2, (r + 1) // 2
            keep = fine_free[r]
            for c in range(cols):
                f[r, c] += keep[c] * 0.5 * (a[ra, c // 2] + a[rb, (c + 1) // 2])


@numba.njit(**JIT)
def _copy(source, target):
    """Copy one C-contiguous array into another of the same size (no slice assignment)."""
    flat_s, flat_t = source.reshape(source.size), target.reshape(target.size)
    for i in range(flat_s.size):
        flat_t[i] = flat_s[i]


@numba.njit(**JIT)
def inject(fine, coarse):
    """Coarse positions are the fine level's even rows and columns (the same points)."""
    for d in range(3):
        for r in range(coarse.shape[1]):
            for c in range(coarse.shape[2]):
                coarse[d, r, c] = fine[d, 2 * r, 2 * c]


@numba.njit(**JIT)
def coarse_cholesky(mass, free, coef_uu, coef_iso, directions, factor):
    """
    Assemble the coarsest grid's ``A`` densely and factor it, ``A = L L^T``, in place.

    ``factor`` is ``(3 n, 3 n)``, unknown ``3 i + d`` for point i and component d; held
    points get identity rows and columns. Block-Jacobi sweeps cannot stand in for this
    solve: the coarsest grid's smallest eigenvalues belong to the cloth's translations
    (mass only, the springs do not resist them), which a sweep reduces by about 1 - m/D,
    about 2 % here, and the error left shows as momentum the springs did not make.
    """
    rows, cols = mass.shape
    n = rows * cols
    m, fr = mass.reshape(n), free.reshape(n)
    size = 3 * n
    for i in range(size):
        for j in range(size):
            factor[i, j] = 0.0
    for i in range(n):
        for d in range(3):
            factor[3 * i + d, 3 * i + d] = m[i]
    for s in range(2 * coef_uu.shape[0]):
        lo, hi, off, src = _direction_span(s, rows, cols)
        a, c_iso, ux, uy, uz = _springs_of(coef_uu, coef_iso, directions, s, lo + src,
                                           hi + src)
        for k in range(hi - lo):
            i, j = lo + k, lo + k + off
            u = (ux[k], uy[k], uz[k])
            for d in range(3):
                for e in range(3):
                    block = a[k] * u[d] * u[e] + (c_iso[k] if d == e else 0.0)
                    factor[3 * i + d, 3 * i + e] += block
                    factor[3 * i + d, 3 * j + e] -= block
    for i in range(n):
        if fr[i] == 0.0:
            for d in range(3):
                for j in range(size):
                    factor[3 * i + d, j] = 0.0
                    factor[j, 3 * i + d] = 0.0
                factor[3 * i + d, 3 * i + d] = 1.0
    for j in range(size):           # Cholesky, column by column
        total = factor[j, j]
        for k in range(j):
            total -= factor[j, k] * factor[j, k]
        factor[j, j] = math.sqrt(total)
        for i in range(j + 1, size):
            total = factor[i, j]
            for k in range(j):
                total -= factor[i, k] * factor[j, k]
            factor[i, j] = total / factor[j, j]


@numba.njit(**JIT)
def coarse_solve(factor, b, x):
    """Solve ``L L^T x = b`` on the coarsest grid (``b``, ``x``: ``(3, rows, cols)``)."""
    n = b.shape[1] * b.shape[2]
    size = 3 * n
    y = np.empty(size)
    for d in range(3):
        flat = b[d].reshape(n)
        for i in range(n):
            y[3 * i + d] = flat[i]
    for i in range(size):
        total = y[i]
        for k in range(i):
            total -= factor[i, k] * y[k]
        y[i] = total / factor[i, i]
    for i in range(size - 1, -1, -1):
        total = y[i]
        for k in range(i + 1, size):
            total -= factor[k, i] * y[k]
        y[i] = total / factor[i, i]
    for d in range(3):
        flat = x[d].reshape(n)
        for i in range(n):
            flat[i] = y[3 * i + d]


@numba.njit(**JIT)
def assemble_hierarchy(
        # inputs: the finest solved level's positions (x, rows, cols) and per-level data
        x_top, shapes, offsets, rest, stiffness, contraction, damping, beta, base_mass,
        air_drag,
        # outputs (flat buffers of every level): injected positions, the effective mass,
        # the spring blocks and the inverse diagonal blocks
        positions, mass, coef_uu, coef_iso, directions, block_inverse,
        # input on the finest level, output on the coarser ones: 1.0 at free points
        free,
        # output: the coarsest grid's Cholesky factor, or a (0, 0) array (no direct solve)
        factor):
    """
    Assemble ``A`` on every level, the coarser ones at the injected positions.

    A coarse point is held (Dirichlet) where the fine point at its place is: the coarse
    correction is prolonged only onto free fine points, so the coarse system needs no
    more.
    """
    top = shapes.shape[0] - 1
    for level in range(top, -1, -1):
        rows, cols = shapes[level, 0], shapes[level, 1]
        n0, n1 = offsets[level], offsets[level + 1]
        x = level_field(positions, offsets, level, 3, rows, cols)
        fr = free[n0:n1].reshape(rows, cols)
        if level == top:
            _copy(x_top, x)
        else:
            fine_rows, fine_cols = shapes[level + 1, 0], shapes[level + 1, 1]
            inject(level_field(positions, offsets, level + 1, 3, fine_rows, fine_cols), x)
            fine_free = free[n1:n1 + fine_rows * fine_cols].reshape(fine_rows, fine_cols)
            for r in range(rows):
                for c in range(cols):
                    fr[r, c] = fine_free[2 * r, 2 * c]
        for i in range(n0, n1):
            mass[i] = base_mass[i] + beta * air_drag[i]
        uu = level_field(coef_uu, offsets, level, 6, rows, cols)
        iso = level_field(coef_iso, offsets, level, 6, rows, cols)
        dirs = level_directions(directions, offsets, level, rows, cols)
        assemble_level(x, rest[level], stiffness[level], contraction[level], damping, beta,
                       uu, iso, dirs)
        diagonal_inverse(mass[n0:n1].reshape(rows, cols), fr, uu, iso, dirs,
                         level_field(block_inverse, offsets, level, 6, rows, cols))
        if level == 0 and factor.shape[0] > 0:
            coarse_cholesky(mass[n0:n1].reshape(rows, cols), fr, uu, iso, dirs, factor)


@numba.njit(**JIT)
def _level_apply(level, shapes, offsets, mass, free, coef_uu, coef_iso, directions, p, out):
    rows, cols = shapes[level, 0], shapes[level, 1]
    n0, n1 = offsets[level], offsets[level + 1]
    apply_level(mass[n0:n1].reshape(rows, cols), free[n0:n1].reshape(rows, cols),
                level_field(coef_uu, offsets, level, 6, rows, cols),
                level_field(coef_iso, offsets, level, 6, rows, cols),
                level_directions(directions, offsets, level, rows, cols), p, out)


@numba.njit(**JIT)
def _cycle_views(level, shapes, offsets, free, block_inverse, b_top, mg_x, mg_b, mg_t):
    """Return a level's free mask, inverse blocks, correction, right-hand side, work vector."""
    rows, cols = shapes[level, 0], shapes[level, 1]
    n0, n1 = offsets[level], offsets[level + 1]
    top = shapes.shape[0] - 1
    b = b_top if level == top else level_field(mg_b, offsets, level, 3, rows, cols)
    return (free[n0:n1].reshape(rows, cols),
            level_field(block_inverse, offsets, level, 6, rows, cols),
            level_field(mg_x, offsets, level, 3, rows, cols), b,
            level_field(mg_t, offsets, level, 3, rows, cols))


@numba.njit(**JIT)
def _smooth(level, shapes, offsets, mass, free, coef_uu, coef_iso, directions, block_inverse,
            level_free, b, t, omega, count, zero_start, x):
    """``count`` block-Jacobi sweeps on a level (the first from x = 0 if ``zero_start``)."""
    if zero_start:
        jacobi_update(block_inverse, level_free, b, t, omega, True, x)
    for _ in range(count - 1 if zero_start else count):
        _level_apply(level, shapes, offsets, mass, free, coef_uu, coef_iso, directions, x, t)
        jacobi_update(block_inverse, level_free, b, t, omega, False, x)


@numba.njit(**JIT)
def v_cycle(
        # inputs: the assembled hierarchy
        shapes, offsets, mass, free, coef_uu, coef_iso, directions, block_inverse, factor,
        # inputs: the right-hand side on the finest level and the cycle's settings
        b_top, sweeps, coarse_sweeps, omega,
        # work (flat, every level): corrections, right-hand sides, products
        mg_x, mg_b, mg_t,
        # output: the finest level's correction
        x_top):
    """
    One V(sweeps, sweeps) cycle for ``A x = b`` from x = 0 (the preconditioner).

    Down: smooth, restrict the residual; the coarsest level: solved with its Cholesky
    ``factor``, or ``coarse_sweeps`` sweeps without one; up: add the prolonged
    correction, smooth.
    """
    top = shapes.shape[0] - 1
    for level in range(top, -1, -1):
        fr, inv, x, b, t = _cycle_views(level, shapes, offsets, free, block_inverse, b_top,
                                        mg_x, mg_b, mg_t)
        if level == 0 and factor.shape[0] > 0:
            coarse_solve(factor, b, x)
            break
        _smooth(level, shapes, offsets, mass, free, coef_uu, coef_iso, directions, inv, fr,
                b, t, omega, coarse_sweeps if level == 0 else sweeps, True, x)
        if level == 0:
            break
        # the residual, restricted
        _level_apply(level, shapes, offsets, mass, free, coef_uu, coef_iso, directions, x, t)
        flat_t, flat_b = t.reshape(t.size), b.reshape(b.size)
        for i in range(t.size):
            flat_t[i] = flat_b[i] - flat_t[i]
        crows, ccols = shapes[level - 1, 0], shapes[level - 1, 1]
        c0, c1 = offsets[level - 1], offsets[level]
        restrict(t, free[c0:c1].reshape(crows, ccols),
                 level_field(mg_b, offsets, level - 1, 3, crows, ccols))
    for level in range(1, top + 1):
        fr, inv, x, b, t = _cycle_views(level, shapes, offsets, free, block_inverse, b_top,
                                        mg_x, mg_b, mg_t)
        prolong_add(level_field(mg_x, offsets, level - 1, 3, shapes[level - 1, 0],
                                shapes[level - 1, 1]), fr, x)
        _smooth(level, shapes, offsets, mass, free, coef_uu, coef_iso, directions, inv, fr,
                b, t, omega, sweeps, False, x)
    _copy(level_field(mg_x, offsets, top, 3, shapes[top, 0], shapes[top, 1]), x_top)


@numba.njit(**JIT)
def _dot(a, b):
    return interleaved_dot(a.reshape(a.size), b.reshape(b.size), a.size)


@numba.njit(**JIT)
def multigrid_cg(
        # inputs: the assembled hierarchy (see assemble_hierarchy)
        shapes, offsets, mass, free, coef_uu, coef_iso, directions, block_inverse, factor,
        # inputs: right-hand side on the finest level, stopping rule, V-cycle settings
        b, max_iter, rtol, sweeps, coarse_sweeps, omega,
        # work: the V-cycle's flat buffers, then finest-level vectors
        mg_x, mg_b, mg_t, r, z, p, ap,
        # output: the solution, from x = 0
        x):
    """
    Solve ``A x = b`` on the finest level by V-cycle-preconditioned CG.

    At most ``max_iter`` iterations, fewer once ``|r| <= rtol |b|``. Returns
    ``(iterations, |r| / |b|)``. A fixed iteration count gives a fixed cost per step.
    """
    top = shapes.shape[0] - 1
    n = x.size
    xf, rf, zf, pf, af = (x.reshape(n), r.reshape(n), z.reshape(n), p.reshape(n),
                          ap.reshape(n))
    bf = b.reshape(n)
    for i in range(n):
        xf[i] = 0.0
        rf[i] = bf[i]
    bnorm = math.sqrt(_dot(b, b))
    if bnorm == 0.0:
        return 0, 0.0
    v_cycle(shapes, offsets, mass, free, coef_uu, coef_iso, directions, block_inverse,
            factor, r, sweeps, coarse_sweeps, omega, mg_x, mg_b, mg_t, z)
    for i in range(n):
        pf[i] = zf[i]
    rz = _dot(r, z)
    rel = 1.0
    for it in range(1, max_iter + 1):
        _level_apply(top, shapes, offsets, mass, free, coef_uu, coef_iso, directions, p, ap)
        alpha = rz / _dot(p, ap)
        for i in range(n):
            xf[i] += alpha * pf[i]
            rf[i] -= alpha * af[i]
        rel = math.sqrt(_dot(r, r)) / bnorm
        if rel <= rtol or it == max_iter:
            return it, rel
        v_cycle(shapes, offsets, mass, free, coef_uu, coef_iso, directions, block_inverse,
                factor, r, sweeps, coarse_sweeps, omega, mg_x, mg_b, mg_t, z)
        rz_new = _dot(r, z)
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            pf[i] = zf[i] + beta * pf[i]
    return max_iter, rel
