"""Every numba kernel of the engine, in one module so the JIT cache sees them together.

Layout: each level is a regular grid; arrays are float64 ``(3, rows, cols)`` (x, y, z
planes: structure of arrays) or ``(rows, cols)``. Springs are the 12-direction stencil of
:mod:`hcloth_ros.core.model`, passed in as ``rest`` and ``stiff`` of shape ``(12,)``.
Every kernel gathers: a point reads its neighbours and writes only its own entries, so the
``prange`` over rows needs no atomics and results are bit-identical run after run.

Flags: ``cache=True``, ``error_model='numpy'`` and no ``fastmath`` (fast math lets LLVM
delete the NaN checks the blow-up detector relies on).

Hold kinds (see :mod:`hcloth_ros.core.control`): 0 free, 1 pinned, 2 driven. ``presc``
holds the prescribed velocity change of held points for the current step.

Speed. The per-step kernels have two paths that compute the same numbers:

* an interior fast path over whole rows: rows and columns at least two (the stencil's
  reach) from the border, written as loops over 1-D row views indexed ``i + offset`` with
  ``i`` counting from 0, so that LLVM can prove every index non-negative, drop numba's
  wrap-around handling and vectorise the loop (SIMD ``sqrt`` and division over columns).
  One stencil direction per loop, accumulating into row buffers in stencil order: a loop
  over all twelve reads too many distinct arrays for LLVM's run-time overlap checks and
  stays scalar;
* the generic per-point code (bounds-checked stencil, hold kinds) for the border band,
  for rows near held points where a kernel looks at the neighbours' hold kinds, and for
  inputs the fast path does not cover.

Both evaluate the same expressions in the same order, so results agree bit for bit (up
to the sign of a zero where the fast path adds a ``0.0`` the generic one skips; the one
exception is ``strain_stats``' mean, a reordered sum). Strain limiting, which runs up to
``max_iterations`` sweeps per level and step and dominates the step, evaluates each
spring once for both of its ends and corrects rows in the same streaming pass
(:func:`strain_limit`). Sweeps, square roots and divisions are what is left: most of a
step is the hardware divider.

Each kernel runs one ``prange`` over row chunks (:func:`_nchunks`): a single chunk, so
one thread does the work, on levels below ``PAR_MIN_POINTS`` points (splitting costs
more than it saves there), a few chunks on larger ones. One call site per row function
keeps the compiled code, and the cold-start compile time, smaller than a separate serial
branch would.
"""

import math

import numba
import numpy as np
from numba import prange

from hcloth_ros.core.model import STENCIL_DC, STENCIL_DR

JIT = dict(cache=True, error_model='numpy', nogil=True)
PJIT = dict(JIT, parallel=True)

DR = STENCIL_DR
DC = STENCIL_DC
NSTENCIL = 12
# Stencil entries of structural and shear springs (strain limiting, strain metrics).
NSTRETCH = 8
# Levels with fewer points run in one chunk (one thread).
PAR_MIN_POINTS = 2048
# Strain limiting on levels with fewer points sweeps the level as a whole (flat loops).
FLAT_MAX_POINTS = 2048
# Most row chunks a parallel kernel splits a level into.
MAX_CHUNKS = 8

FREE = 0
PINNED = 1
DRIVEN = 2


# --- helpers -----------------------------------------------------------------------------

@numba.njit(**JIT)
def _nchunks(rows, cols):
    """Row chunks of a level: 1 (one thread) for small levels, else about 32 rows a chunk,
    2 to ``MAX_CHUNKS`` of them (``prange`` hands each thread a contiguous run of
    chunks). Not ``numba.get_num_threads()``: a kernel calling it cannot be cached."""
    if rows * cols < PAR_MIN_POINTS:
        return 1
    return max(2, min(MAX_CHUNKS, rows // 32))


@numba.njit(**JIT)
def _v3(a, r, c):
    """The x, y and z row views of ``a[:, r, c:]`` (1-D, contiguous)."""
    return a[0, r, c:], a[1, r, c:], a[2, r, c:]


@numba.njit(**JIT)
def _rows_free(kind, r0, r1):
    """True when rows ``r0 .. r1-1`` (clipped to the grid) hold only free points."""
    rows, cols = kind.shape
    held = 0
    for r in range(max(r0, 0), min(r1, rows)):
        kr = kind[r]
        for c in range(cols):
            held += kr[c] != FREE
    return held == 0


@numba.njit(**JIT)
def _spring(q, r, c, rr, cc, rest, stiff, contraction):
    """Force on (r, c) from the spring to (rr, cc) and the spring vector (N, m)."""
    dx = q[0, rr, cc] - q[0, r, c]
    dy = q[1, rr, cc] - q[1, r, c]
    dz = q[2, rr, cc] - q[2, r, c]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    stretch = length - rest
    k = stiff if stretch >= 0.0 else stiff * contraction
    coef = k * stretch / length if length > 0.0 else 0.0
    return coef * dx, coef * dy, coef * dz


@numba.njit(**JIT)
def _filtered_force(q, qd, r, c, rest, stiff, contraction, h):
    """Spring force plus the viscous term of the paper's eq. 4 on one point (N)."""
    rows, cols = q.shape[1], q.shape[2]
    fx = 0.0
    fy = 0.0
    fz = 0.0
    vx = qd[0, r, c]
    vy = qd[1, r, c]
    vz = qd[2, r, c]
    for s in range(NSTENCIL):
        rr = r + DR[s]
        cc = c + DC[s]
        if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
            continue
        sx, sy, sz = _spring(q, r, c, rr, cc, rest[s], stiff[s], contraction)
        hk = h * stiff[s]
        fx += sx + hk * (qd[0, rr, cc] - vx)
        fy += sy + hk * (qd[1, rr, cc] - vy)
        fz += sz + hk * (qd[2, rr, cc] - vz)
    return fx, fy, fz


@numba.njit(**JIT)
def _spring_force(q, r, c, rest, stiff, contraction):
    """Spring force alone on one point (N), bounds-checked."""
    rows, cols = q.shape[1], q.shape[2]
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for s in range(NSTENCIL):
        rr = r + DR[s]
        cc = c + DC[s]
        if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
            continue
        sx, sy, sz = _spring(q, r, c, rr, cc, rest[s], stiff[s], contraction)
        fx += sx
        fy += sy
        fz += sz
    return fx, fy, fz


@numba.njit(**JIT)
def _force_dir(q, qd, r, c0, n, dr, dc, rest, stiff, contraction, h, viscous, fx, fy, fz):
    """Add one stencil entry's term to ``f*[i]`` for points ``(r, c0 + i)``, ``i < n``:
    the spring force (plus eq. 4's viscous term if ``viscous``) from the neighbour at
    ``(r + dr, c0 + i + dc)``. The body of ``_spring`` / ``_filtered_force``.

    One direction per loop keeps the loop's distinct arrays few enough for LLVM to
    check them for overlap at run time and vectorise (twelve directions in one loop are
    too many). Needs ``c0 + dc >= 0`` and ``c0 >= 0``."""
    xp, yp, zp = _v3(q, r, c0)
    up, vp, wp = _v3(qd, r, c0)
    xn, yn, zn = _v3(q, r + dr, c0 + dc)
    un, vn, wn = _v3(qd, r + dr, c0 + dc)
    hk = h * stiff
    for i in range(n):
        dx = xn[i] - xp[i]
        dy = yn[i] - yp[i]
        dz = zn[i] - zp[i]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        stretch = length - rest
        k = stiff if stretch >= 0.0 else stiff * contraction
        coef = k * stretch / length if length > 0.0 else 0.0
        if viscous:
            fx[i] += coef * dx + hk * (un[i] - up[i])
            fy[i] += coef * dy + hk * (vn[i] - vp[i])
            fz[i] += coef * dz + hk * (wn[i] - wp[i])
        else:
            fx[i] += coef * dx
            fy[i] += coef * dy
            fz[i] += coef * dz


@numba.njit(**JIT)
def _force_row(q, qd, r, c0, n, rest, stiff, contraction, h, viscous, fx, fy, fz):
    """Interior fast path of ``_filtered_force`` (``viscous``) or ``_spring_force`` for
    points ``(r, c0 + i)``, ``i < n``, into ``f*[i]``: needs ``2 <= r < rows - 2``,
    ``c0 >= 2`` and ``c0 + n <= cols - 2``. Each point's sum starts at 0.0 and adds the
    stencil entries in order 0 .. 11, as the per-point form does."""
    for i in range(n):
        fx[i] = 0.0
        fy[i] = 0.0
        fz[i] = 0.0
    for s in range(NSTENCIL):
        _force_dir(q, qd, r, c0, n, DR[s], DC[s], rest[s], stiff[s], contraction, h,
                   viscous, fx, fy, fz)


@numba.njit(**JIT)
def _stencil_sum_row(a, r, c0, n, stiff, shift, sx_out, sy_out, sz_out):
    """Interior fast path of ``sum_s stiff[s] * (a[:, nbr_s] - shift)`` in stencil order
    for points ``(r, c0 + i)``, ``i < n`` (same bounds as :func:`_force_row`)."""
    o = c0 - 2
    xa, ya, za = _v3(a, r - 2, o)
    xb, yb, zb = _v3(a, r - 1, o)
    xc, yc, zc = _v3(a, r, o)
    xd, yd, zd = _v3(a, r + 1, o)
    xe, ye, ze = _v3(a, r + 2, o)
    k0, k1, k2, k3, k4, k5 = stiff[0], stiff[1], stiff[2], stiff[3], stiff[4], stiff[5]
    k6, k7, k8, k9, k10, k11 = stiff[6], stiff[7], stiff[8], stiff[9], stiff[10], stiff[11]
    gx, gy, gz = shift
    for i in range(n):
        j = i + 2
        sx = 0.0
        sy = 0.0
        sz = 0.0
        sx += k0 * (xc[j + 1] - gx)
        sy += k0 * (yc[j + 1] - gy)
        sz += k0 * (zc[j + 1] - gz)
        sx += k1 * (xc[j - 1] - gx)
        sy += k1 * (yc[j - 1] - gy)
        sz += k1 * (zc[j - 1] - gz)
        sx += k2 * (xd[j] - gx)
        sy += k2 * (yd[j] - gy)
        sz += k2 * (zd[j] - gz)
        sx += k3 * (xb[j] - gx)
        sy += k3 * (yb[j] - gy)
        sz += k3 * (zb[j] - gz)
        sx += k4 * (xd[j + 1] - gx)
        sy += k4 * (yd[j + 1] - gy)
        sz += k4 * (zd[j + 1] - gz)
        sx += k5 * (xb[j - 1] - gx)
        sy += k5 * (yb[j - 1] - gy)
        sz += k5 * (zb[j - 1] - gz)
        sx += k6 * (xd[j - 1] - gx)
        sy += k6 * (yd[j - 1] - gy)
        sz += k6 * (zd[j - 1] - gz)
        sx += k7 * (xb[j + 1] - gx)
        sy += k7 * (yb[j + 1] - gy)
        sz += k7 * (zb[j + 1] - gz)
        sx += k8 * (xc[j + 2] - gx)
        sy += k8 * (yc[j + 2] - gy)
        sz += k8 * (zc[j + 2] - gz)
        sx += k9 * (xc[j - 2] - gx)
        sy += k9 * (yc[j - 2] - gy)
        sz += k9 * (zc[j - 2] - gz)
        sx += k10 * (xe[j] - gx)
        sy += k10 * (ye[j] - gy)
        sz += k10 * (ze[j] - gz)
        sx += k11 * (xa[j] - gx)
        sy += k11 * (ya[j] - gy)
        sz += k11 * (za[j] - gz)
        sx_out[i] = sx
        sy_out[i] = sy
        sz_out[i] = sz


# --- per-step kernels --------------------------------------------------------------------

@numba.njit(**JIT)
def prescribe(q, qd, kind, drive_index, drive_target, h, presc):
    """Velocity change that makes held points do what they must this step.

    Pinned: velocity becomes zero, so ``x + h * v`` is ``x`` bit for bit. Driven: the
    velocity that reaches the target at the end of the step. Entries of other points are
    left as they are.
    """
    rows, cols = kind.shape
    for r in range(rows):
        kr = kind[r]
        pinned = 0
        for c in range(cols):
            pinned += kr[c] == PINNED
        if pinned == 0:
            continue
        for c in range(cols):
            if kr[c] == PINNED:
                for d in range(3):
                    presc[d, r, c] = -qd[d, r, c]
    for m in range(drive_index.shape[0]):
        g = drive_index[m]
        r = g // cols
        c = g % cols
        for d in range(3):
            presc[d, r, c] = (drive_target[d, m] - q[d, r, c]) / h - qd[d, r, c]


@numba.njit(**JIT)
def _eq6_first_point(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h, gravity,
                     literal, ft, a, r, c):
    fx, fy, fz = _filtered_force(q, qd, r, c, rest, stiff, contraction, h)
    if literal:
        m = mass[r, c]
        fx += m * gravity[0]
        fy += m * gravity[1]
        fz += m * gravity[2]
    ft[0, r, c] = h * fx
    ft[1, r, c] = h * fy
    ft[2, r, c] = h * fz
    if kind[r, c] != FREE:
        for d in range(3):
            a[d, r, c] = presc[d, r, c] - (0.0 if literal else h * gravity[d])
    else:
        w = dinv[r, c]
        a[0, r, c] = h * fx * w
        a[1, r, c] = h * fy * w
        a[2, r, c] = h * fz * w


@numba.njit(**JIT)
def _eq6_first_rows(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h, gravity,
                    literal, ft, a, r0, r1):
    rows, cols = mass.shape
    n = cols - 4
    fxb = np.empty(max(n, 1))
    fyb = np.empty(max(n, 1))
    fzb = np.empty(max(n, 1))
    g0, g1, g2 = gravity[0], gravity[1], gravity[2]
    e0 = 0.0 if literal else h * g0
    e1 = 0.0 if literal else h * g1
    e2 = 0.0 if literal else h * g2
    for r in range(r0, r1):
        if not (2 <= r < rows - 2 and n > 0):
            for c in range(cols):
                _eq6_first_point(q, qd, mass, rest, stiff, contraction, dinv, kind, presc,
                                 h, gravity, literal, ft, a, r, c)
            continue
        for c in (0, 1, cols - 2, cols - 1):
            _eq6_first_point(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h,
                             gravity, literal, ft, a, r, c)
        _force_row(q, qd, r, 2, n, rest, stiff, contraction, h, True, fxb, fyb, fzb)
        mr = mass[r, 2:]
        wr = dinv[r, 2:]
        kr = kind[r, 2:]
        # one component per loop (few arrays per loop: LLVM vectorises it)
        _eq6_first_update(fxb, mr, wr, kr, presc[0, r, 2:], ft[0, r, 2:], a[0, r, 2:], n,
                          h, literal, g0, e0)
        _eq6_first_update(fyb, mr, wr, kr, presc[1, r, 2:], ft[1, r, 2:], a[1, r, 2:], n,
                          h, literal, g1, e1)
        _eq6_first_update(fzb, mr, wr, kr, presc[2, r, 2:], ft[2, r, 2:], a[2, r, 2:], n,
                          h, literal, g2, e2)


@numba.njit(**JIT)
def _eq6_first_update(fb, mr, wr, kr, pr, tr, ar, n, h, literal, g, e):
    """One component of the first sweep's outputs from the force ``fb`` (interior)."""
    for i in range(n):
        f = fb[i]
        if literal:
            f += mr[i] * g
        tr[i] = h * f
        ar[i] = pr[i] - e if kr[i] != FREE else h * f * wr[i]


@numba.njit(**PJIT)
def eq6_first_sweep(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h,
                    gravity, literal, ft, a):
    """First Jacobi sweep of eq. 6: ``ft = h f~`` and ``a = h f~ / (m + h^2 K)``.

    ``literal``: gravity goes through the filter (the paper as written); otherwise ``a``
    holds only the spring part and held points carry their velocity change less the
    exact external part ``h g``.
    """
    rows, cols = mass.shape
    nch = _nchunks(rows, cols)
    for ch in prange(nch):
        _eq6_first_rows(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h,
                        gravity, literal, ft, a, ch * rows // nch,
                        (ch + 1) * rows // nch)


@numba.njit(**JIT)
def _eq6_second_point(q, qd, stiff, dinv, kind, presc, ft, a, h, gravity, literal,
                      q_out, qd_out, dv_out, r, c):
    rows, cols = dinv.shape
    h2 = h * h
    if kind[r, c] != FREE:
        for d in range(3):
            dv_out[d, r, c] = presc[d, r, c]
    else:
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for s in range(NSTENCIL):
            rr = r + DR[s]
            cc = c + DC[s]
            if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                continue
            k = stiff[s]
            sx += k * a[0, rr, cc]
            sy += k * a[1, rr, cc]
            sz += k * a[2, rr, cc]
        w = dinv[r, c]
        ext = 0.0 if literal else h
        dv_out[0, r, c] = (ft[0, r, c] + h2 * sx) * w + ext * gravity[0]
        dv_out[1, r, c] = (ft[1, r, c] + h2 * sy) * w + ext * gravity[1]
        dv_out[2, r, c] = (ft[2, r, c] + h2 * sz) * w + ext * gravity[2]
    for d in range(3):
        v = qd[d, r, c] + dv_out[d, r, c]
        qd_out[d, r, c] = v
        q_out[d, r, c] = q[d, r, c] + h * v


@numba.njit(**JIT)
def _eq6_second_rows(q, qd, stiff, dinv, kind, presc, ft, a, h, gravity, literal, q_out,
                     qd_out, dv_out, r0, r1):
    rows, cols = dinv.shape
    n = cols - 4
    sxb = np.empty(max(n, 1))
    syb = np.empty(max(n, 1))
    szb = np.empty(max(n, 1))
    h2 = h * h
    ext = 0.0 if literal else h
    g0 = ext * gravity[0]
    g1 = ext * gravity[1]
    g2 = ext * gravity[2]
    for r in range(r0, r1):
        if not (2 <= r < rows - 2 and n > 0):
            for c in range(cols):
                _eq6_second_point(q, qd, stiff, dinv, kind, presc, ft, a, h, gravity,
                                  literal, q_out, qd_out, dv_out, r, c)
            continue
        for c in (0, 1, cols - 2, cols - 1):
            _eq6_second_point(q, qd, stiff, dinv, kind, presc, ft, a, h, gravity, literal,
                              q_out, qd_out, dv_out, r, c)
        _stencil_sum_row(a, r, 2, n, stiff, (0.0, 0.0, 0.0), sxb, syb, szb)
        wr = dinv[r, 2:]
        kr = kind[r, 2:]
        for d in range(3):
            sb = sxb if d == 0 else (syb if d == 1 else szb)
            _eq6_second_update(sb, wr, kr, presc[d, r, 2:], ft[d, r, 2:], q[d, r, 2:],
                               qd[d, r, 2:], q_out[d, r, 2:], qd_out[d, r, 2:],
                               dv_out[d, r, 2:], n, h, h2, g0 if d == 0 else
                               (g1 if d == 1 else g2))


@numba.njit(**JIT)
def _eq6_second_update(sb, wr, kr, pr, tr, xr, ur, xo, uo, do, n, h, h2, g):
    """One component of the second sweep and the update ``v += dv``, ``x += h v``."""
    for i in range(n):
        dd = pr[i] if kr[i] != FREE else (tr[i] + h2 * sb[i]) * wr[i] + g
        do[i] = dd
        v = ur[i] + dd
        uo[i] = v
        xo[i] = xr[i] + h * v


@numba.njit(**PJIT)
def eq6_second_sweep(q, qd, stiff, dinv, kind, presc, ft, a, h, gravity, literal,
                     q_out, qd_out, dv_out):
    """Second sweep of eq. 6, then ``v += dv`` and ``x += h v`` (semi-implicit order)."""
    rows, cols = dinv.shape
    nch = _nchunks(rows, cols)
    for ch in prange(nch):
        _eq6_second_rows(q, qd, stiff, dinv, kind, presc, ft, a, h, gravity, literal,
                         q_out, qd_out, dv_out, ch * rows // nch,
                         (ch + 1) * rows // nch)


@numba.njit(**JIT)
def _prolong_rows(coarse, fine, r0, r1):
    rows, cols = fine.shape[1], fine.shape[2]
    ccols = coarse.shape[2]
    regular = cols == 2 * ccols - 1 and rows == 2 * coarse.shape[1] - 1
    for r in range(r0, r1):
        ra = r // 2
        rb = (r + 1) // 2
        for d in range(fine.shape[0]):
            if regular:
                ca = coarse[d, ra]
                cb = coarse[d, rb]
                f = fine[d, r]
                for j in range(ccols - 1):
                    f[2 * j] = 0.5 * (ca[j] + cb[j])
                    f[2 * j + 1] = 0.5 * (ca[j] + cb[j + 1])
                f[cols - 1] = 0.5 * (ca[ccols - 1] + cb[ccols - 1])
            else:
                for c in range(cols):
                    c0 = c // 2
                    c1 = (c + 1) // 2
                    fine[d, r, c] = 0.5 * (coarse[d, ra, c0] + coarse[d, rb, c1])


@numba.njit(**PJIT)
def prolong(coarse, fine):
    """Fill a level-k array from level k-1 with the hierarchy's parent rule.

    Inherited points copy their coarse value; inserted points take the mean of the two
    ends of the edge they were inserted on (the "\\" diagonal for face centres). Used for
    eq. 7's ``dv_app`` and to start a newly simulated level from the coarser state.
    """
    rows, cols = fine.shape[1], fine.shape[2]
    nch = _nchunks(rows, cols)
    for ch in prange(nch):
        _prolong_rows(coarse, fine, ch * rows // nch, (ch + 1) * rows // nch)


@numba.njit(**JIT)
def _eq7_point(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h, gravity,
               literal, q_coarse, qd_coarse, dv_coarse, dv_app, q_out, qd_out, dv_out, r, c):
    rows, cols = dinv.shape
    h2 = h * h
    ext = 0.0 if literal else h
    gx = ext * gravity[0]
    gy = ext * gravity[1]
    gz = ext * gravity[2]
    if r % 2 == 0 and c % 2 == 0:
        rc = r // 2
        cc2 = c // 2
        for d in range(3):
            q_out[d, r, c] = q_coarse[d, rc, cc2]
            qd_out[d, r, c] = qd_coarse[d, rc, cc2]
            dv_out[d, r, c] = dv_coarse[d, rc, cc2]
        return
    if kind[r, c] != FREE:
        for d in range(3):
            dv_out[d, r, c] = presc[d, r, c]
    else:
        fx, fy, fz = _filtered_force(q, qd, r, c, rest, stiff, contraction, h)
        if literal:
            m = mass[r, c]
            fx += m * gravity[0]
            fy += m * gravity[1]
            fz += m * gravity[2]
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for s in range(NSTENCIL):
            rr = r + DR[s]
            cc = c + DC[s]
            if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                continue
            k = stiff[s]
            src = presc if kind[rr, cc] != FREE else dv_app
            sx += k * (src[0, rr, cc] - gx)
            sy += k * (src[1, rr, cc] - gy)
            sz += k * (src[2, rr, cc] - gz)
        w = dinv[r, c]
        dv_out[0, r, c] = (h * fx + h2 * sx) * w + gx
        dv_out[1, r, c] = (h * fy + h2 * sy) * w + gy
        dv_out[2, r, c] = (h * fz + h2 * sz) * w + gz
    for d in range(3):
        v = qd[d, r, c] + dv_out[d, r, c]
        qd_out[d, r, c] = v
        q_out[d, r, c] = q[d, r, c] + h * v


@numba.njit(**JIT)
def _eq7_rows(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h, gravity,
              literal, q_coarse, qd_coarse, dv_coarse, dv_app, q_out, qd_out, dv_out, r0, r1):
    rows, cols = dinv.shape
    n = cols - 4
    fxb = np.empty(max(n, 1))
    fyb = np.empty(max(n, 1))
    fzb = np.empty(max(n, 1))
    sxb = np.empty(max(n, 1))
    syb = np.empty(max(n, 1))
    szb = np.empty(max(n, 1))
    h2 = h * h
    ext = 0.0 if literal else h
    gx = ext * gravity[0]
    gy = ext * gravity[1]
    gz = ext * gravity[2]
    g0, g1, g2 = gravity[0], gravity[1], gravity[2]
    near = np.zeros(cols, dtype=np.bool_)
    for r in range(r0, r1):
        if not (2 <= r < rows - 2 and n > 0):
            for c in range(cols):
                _eq7_point(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h,
                           gravity, literal, q_coarse, qd_coarse, dv_coarse, dv_app, q_out,
                           qd_out, dv_out, r, c)
            continue
        for c in (0, 1, cols - 2, cols - 1):
            _eq7_point(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h,
                       gravity, literal, q_coarse, qd_coarse, dv_coarse, dv_app, q_out,
                       qd_out, dv_out, r, c)
        # every interior column, inherited ones included (overwritten below): a
        # contiguous loop vectorises; a stride-2 one over the new points would not.
        # Held points and their neighbours are redone below.
        _force_row(q, qd, r, 2, n, rest, stiff, contraction, h, True, fxb, fyb, fzb)
        _stencil_sum_row(dv_app, r, 2, n, stiff, (gx, gy, gz), sxb, syb, szb)
        mr = mass[r, 2:]
        wr = dinv[r, 2:]
        for d in range(3):
            fb = fxb if d == 0 else (fyb if d == 1 else fzb)
            sb = sxb if d == 0 else (syb if d == 1 else szb)
            _eq7_update(fb, sb, mr, wr, q[d, r, 2:], qd[d, r, 2:], q_out[d, r, 2:],
                        qd_out[d, r, 2:], dv_out[d, r, 2:], n, h, h2, literal,
                        g0 if d == 0 else (g1 if d == 1 else g2),
                        gx if d == 0 else (gy if d == 1 else gz))
        if r % 2 == 0:
            rc = r // 2
            for c in range(2, cols - 2, 2):
                cc2 = c // 2
                for d in range(3):
                    q_out[d, r, c] = q_coarse[d, rc, cc2]
                    qd_out[d, r, c] = qd_coarse[d, rc, cc2]
                    dv_out[d, r, c] = dv_coarse[d, rc, cc2]
        # the fast path took every point and neighbour as free: redo the points with a
        # held point within the stencil's reach (a 5 x 5 window) by the generic code
        if not _rows_free(kind, r - 2, r + 3):
            near[:] = False
            for rr in range(r - 2, r + 3):
                for cc in range(cols):
                    if kind[rr, cc] != FREE:
                        for c in range(max(cc - 2, 2), min(cc + 3, cols - 2)):
                            near[c] = True
            for c in range(2, cols - 2):
                if near[c]:
                    _eq7_point(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h,
                               gravity, literal, q_coarse, qd_coarse, dv_coarse, dv_app,
                               q_out, qd_out, dv_out, r, c)


@numba.njit(**JIT)
def _eq7_update(fb, sb, mr, wr, xr, ur, xo, uo, do, n, h, h2, literal, g, gext):
    """One component of eq. 7 on free points and the update ``v += dv``, ``x += h v``."""
    for i in range(n):
        f = fb[i]
        if literal:
            f += mr[i] * g
        dd = (h * f + h2 * sb[i]) * wr[i] + gext
        do[i] = dd
        v = ur[i] + dd
        uo[i] = v
        xo[i] = xr[i] + h * v


@numba.njit(**PJIT)
def eq7_level(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h, gravity,
              literal, q_coarse, qd_coarse, dv_coarse, dv_app, q_out, qd_out, dv_out):
    """One refinement level of Table 1: constraint C, then S' (eq. 7) on new points.

    Inherited points (even row and column) take level k-1's new state. Inserted points
    integrate eq. 7 from this level's state at the start of the step, with ``dv_app``
    (level k-1's velocity change, prolonged) for their neighbours; a held neighbour's own
    prescribed change replaces the estimate. With exact gravity the estimate carries the
    external part once: ``h g`` is taken out of every neighbour's change and added back
    to the result.
    """
    rows, cols = dinv.shape
    nch = _nchunks(rows, cols)
    for ch in prange(nch):
        _eq7_rows(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h, gravity,
                  literal, q_coarse, qd_coarse, dv_coarse, dv_app, q_out, qd_out,
                  dv_out, ch * rows // nch, (ch + 1) * rows // nch)


@numba.njit(**JIT)
def _explicit_point(q, qd, mass, rest, stiff, contraction, kind, presc, h, gravity,
                    q_out, qd_out, dv_out, r, c):
    if kind[r, c] != FREE:
        for d in range(3):
            dv_out[d, r, c] = presc[d, r, c]
    else:
        fx, fy, fz = _spring_force(q, r, c, rest, stiff, contraction)
        inv_m = 1.0 / mass[r, c]
        dv_out[0, r, c] = h * (fx * inv_m + gravity[0])
        dv_out[1, r, c] = h * (fy * inv_m + gravity[1])
        dv_out[2, r, c] = h * (fz * inv_m + gravity[2])
    for d in range(3):
        v = qd[d, r, c] + dv_out[d, r, c]
        qd_out[d, r, c] = v
        q_out[d, r, c] = q[d, r, c] + h * v


@numba.njit(**JIT)
def _explicit_rows(q, qd, mass, rest, stiff, contraction, kind, presc, h, gravity,
                   q_out, qd_out, dv_out, r0, r1):
    rows, cols = mass.shape
    n = cols - 4
    fxb = np.empty(max(n, 1))
    fyb = np.empty(max(n, 1))
    fzb = np.empty(max(n, 1))
    g0, g1, g2 = gravity[0], gravity[1], gravity[2]
    for r in range(r0, r1):
        if not (2 <= r < rows - 2 and n > 0):
            for c in range(cols):
                _explicit_point(q, qd, mass, rest, stiff, contraction, kind, presc, h,
                                gravity, q_out, qd_out, dv_out, r, c)
            continue
        for c in (0, 1, cols - 2, cols - 1):
            _explicit_point(q, qd, mass, rest, stiff, contraction, kind, presc, h, gravity,
                            q_out, qd_out, dv_out, r, c)
        _force_row(q, qd, r, 2, n, rest, stiff, contraction, h, False, fxb, fyb, fzb)
        mr = mass[r, 2:]
        kr = kind[r, 2:]
        for d in range(3):
            fb = fxb if d == 0 else (fyb if d == 1 else fzb)
            _explicit_update(fb, mr, kr, presc[d, r, 2:], q[d, r, 2:], qd[d, r, 2:],
                             q_out[d, r, 2:], qd_out[d, r, 2:], dv_out[d, r, 2:], n, h,
                             g0 if d == 0 else (g1 if d == 1 else g2))


@numba.njit(**JIT)
def _explicit_update(fb, mr, kr, pr, xr, ur, xo, uo, do, n, h, g):
    """One component of ``dv = h (f / m + g)`` on free points and the update."""
    for i in range(n):
        dd = pr[i] if kr[i] != FREE else h * (fb[i] * (1.0 / mr[i]) + g)
        do[i] = dd
        v = ur[i] + dd
        uo[i] = v
        xo[i] = xr[i] + h * v


@numba.njit(**PJIT)
def explicit_step(q, qd, mass, rest, stiff, contraction, kind, presc, h, gravity,
                  q_out, qd_out, dv_out):
    """Symplectic Euler: ``v += h (f / m + g)``, then ``x += h v``."""
    rows, cols = mass.shape
    nch = _nchunks(rows, cols)
    for ch in prange(nch):
        _explicit_rows(q, qd, mass, rest, stiff, contraction, kind, presc, h, gravity,
                       q_out, qd_out, dv_out, ch * rows // nch, (ch + 1) * rows // nch)


@numba.njit(**JIT)
def _movable(kind, r, c, inherited_fixed):
    if kind[r, c] != FREE:
        return False
    return not (inherited_fixed and r % 2 == 0 and c % 2 == 0)


@numba.njit(**JIT)
def _strain_limit_generic(q, qd, dv, rest, kind, inherited_fixed, max_stretch,
                          max_iterations, tolerance, h, corr):
    """The per-point form of :func:`strain_limit` (any ``rest``, any tolerance); serial:
    a fallback the model's levels never take."""
    rows, cols = kind.shape
    row_excess = np.zeros(rows)
    for it in range(max_iterations):
        for r in range(rows):
            worst = 0.0
            for c in range(cols):
                corr[0, r, c] = 0.0
                corr[1, r, c] = 0.0
                corr[2, r, c] = 0.0
                if not _movable(kind, r, c, inherited_fixed):
                    continue
                n = 0
                cx = 0.0
                cy = 0.0
                cz = 0.0
                for s in range(NSTRETCH):
                    rr = r + DR[s]
                    cc = c + DC[s]
                    if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                        continue
                    dx = q[0, rr, cc] - q[0, r, c]
                    dy = q[1, rr, cc] - q[1, r, c]
                    dz = q[2, rr, cc] - q[2, r, c]
                    length = math.sqrt(dx * dx + dy * dy + dz * dz)
                    limit = (1.0 + max_stretch) * rest[s]
                    if length <= limit:
                        continue
                    worst = max(worst, length / limit - 1.0)
                    share = 0.5 if _movable(kind, rr, cc, inherited_fixed) else 1.0
                    f = share * (length - limit) / length
                    cx += f * dx
                    cy += f * dy
                    cz += f * dz
                    n += 1
                if n > 0:
                    corr[0, r, c] = cx / n
                    corr[1, r, c] = cy / n
                    corr[2, r, c] = cz / n
            row_excess[r] = worst
        if row_excess.max() <= tolerance:
            return it
        for r in range(rows):
            for c in range(cols):
                for d in range(3):
                    x = corr[d, r, c]
                    if x != 0.0:
                        q[d, r, c] += x
                        qd[d, r, c] += x / h
                        dv[d, r, c] += x / h
    return max_iterations


@numba.njit(**JIT)
def _excess_threshold(limit, tolerance):
    """Smallest float64 ``x`` with ``x / limit - 1.0 > tolerance`` (evaluated in floating
    point). Both operations are monotone, so for a spring longer than ``limit`` the test
    ``length >= threshold`` equals ``length / limit - 1.0 > tolerance`` exactly, with no
    division. Needs ``0 < limit < inf`` and ``0 <= tolerance < inf``."""
    buf = np.empty(1)
    bits = buf.view(np.int64)
    buf[0] = limit
    lo = bits[0]            # excess 0 <= tolerance
    buf[0] = np.inf
    hi = bits[0]            # excess inf > tolerance
    while hi - lo > 1:      # bit patterns of positive floats are ordered like the floats
        mid = lo + (hi - lo) // 2
        bits[0] = mid
        if buf[0] / limit - 1.0 > tolerance:
            hi = mid
        else:
            lo = mid
    bits[0] = hi
    return buf[0]


@numba.njit(**JIT)
def _sl_spring(xp, yp, zp, mp, ip, xn, yn, zn, mn, jn, limit, threshold, fx, fy, fz, fe,
               o):
    """One structural or shear spring from p to n, evaluated once for both ends.

    Stores at index ``o`` the correction term p gets from it, ``f * (x_n - x_p)`` (n gets
    its exact negation), and 1.0 if it is longer than ``limit`` (else 0.0 and a zero
    term). ``share`` is 0.5 when both ends move, else 1.0 (only a movable end reads the
    term). Returns 1 when the spring has a movable end and its excess is above the
    tolerance (``length >= threshold``), else 0."""
    dx = xn[jn] - xp[ip]
    dy = yn[jn] - yp[ip]
    dz = zn[jn] - zp[ip]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    exceed = not (length <= limit)
    a = mp[ip]
    b = mn[jn]
    share = 1.0 - 0.5 * (a * b)
    f = share * (length - limit) / length
    fx[o] = f * dx if exceed else 0.0
    fy[o] = f * dy if exceed else 0.0
    fz[o] = f * dz if exceed else 0.0
    fe[o] = 1.0 if exceed else 0.0
    return 1 if (exceed and a + b > 0.0 and length >= threshold) else 0


@numba.njit(**JIT)
def _sl_forward(xp, yp, zp, mp, xn, yn, zn, mn, has_next, limit, threshold, fw):
    """The springs from one row (positions ``x/y/zp``, movable flags ``mp``) forward,
    into ``fw`` ``(16, cols + 2)``; ``x/y/zn``, ``mn``: the next row (if ``has_next``).
    Entry ``4 * d + (0, 1, 2 | 3)`` holds the x, y, z terms | exceed flag of direction
    d = (0, 1), (1, 0), (1, 1), (1, -1) seen from column c at index ``c + 1``; springs
    that do not exist are zeros, as are the pads at 0 and ``cols + 1``. Returns how many
    springs exceed the tolerance."""
    cols = xp.shape[0]
    count = 0
    # direction (0, 1), columns 0 .. cols-2
    for i in range(cols - 1):
        count += _sl_spring(xp, yp, zp, mp, i, xp, yp, zp, mp, i + 1, limit[0],
                            threshold[0], fw[0], fw[1], fw[2], fw[3], i + 1)
    for e in range(4):
        fw[e, cols] = 0.0
    if not has_next:
        for e in range(4, 16):
            for c in range(cols + 2):
                fw[e, c] = 0.0
        return count
    # (1, 0), columns 0 .. cols-1
    for i in range(cols):
        count += _sl_spring(xp, yp, zp, mp, i, xn, yn, zn, mn, i, limit[1], threshold[1],
                            fw[4], fw[5], fw[6], fw[7], i + 1)
    # (1, 1), columns 0 .. cols-2
    for i in range(cols - 1):
        count += _sl_spring(xp, yp, zp, mp, i, xn, yn, zn, mn, i + 1, limit[2],
                            threshold[2], fw[8], fw[9], fw[10], fw[11], i + 1)
    for e in range(8, 12):
        fw[e, cols] = 0.0
    # (1, -1), columns 1 .. cols-1
    for i in range(cols - 1):
        count += _sl_spring(xp, yp, zp, mp, i + 1, xn, yn, zn, mn, i, limit[3],
                            threshold[3], fw[12], fw[13], fw[14], fw[15], i + 2)
    for e in range(12, 16):
        fw[e, 1] = 0.0
    return count


@numba.njit(**JIT)
def _sl_gather(mov, corr, cur, prev, r):
    """Corrections of row r from its springs (stencil order 0..7, as the per-point form):
    ``cur`` holds row r's forward springs, ``prev`` row r-1's."""
    cols = mov.shape[1]
    m = mov[r]
    ox, oy, oz = _v3(corr, r, 0)
    a0x, a0y, a0z, a0e = cur[0], cur[1], cur[2], cur[3]
    a1x, a1y, a1z, a1e = cur[4], cur[5], cur[6], cur[7]
    a2x, a2y, a2z, a2e = cur[8], cur[9], cur[10], cur[11]
    a3x, a3y, a3z, a3e = cur[12], cur[13], cur[14], cur[15]
    b1x, b1y, b1z, b1e = prev[4], prev[5], prev[6], prev[7]
    b2x, b2y, b2z, b2e = prev[8], prev[9], prev[10], prev[11]
    b3x, b3y, b3z, b3e = prev[12], prev[13], prev[14], prev[15]
    for c in range(cols):
        # s: 0 (0,1) 1 (0,-1) 2 (1,0) 3 (-1,0) 4 (1,1) 5 (-1,-1) 6 (1,-1) 7 (-1,1)
        cx = 0.0
        cy = 0.0
        cz = 0.0
        cx += a0x[c + 1]
        cy += a0y[c + 1]
        cz += a0z[c + 1]
        cx -= a0x[c]
        cy -= a0y[c]
        cz -= a0z[c]
        cx += a1x[c + 1]
        cy += a1y[c + 1]
        cz += a1z[c + 1]
        cx -= b1x[c + 1]
        cy -= b1y[c + 1]
        cz -= b1z[c + 1]
        cx += a2x[c + 1]
        cy += a2y[c + 1]
        cz += a2z[c + 1]
        cx -= b2x[c]
        cy -= b2y[c]
        cz -= b2z[c]
        cx += a3x[c + 1]
        cy += a3y[c + 1]
        cz += a3z[c + 1]
        cx -= b3x[c + 2]
        cy -= b3y[c + 2]
        cz -= b3z[c + 2]
        n = (a0e[c + 1] + a0e[c] + a1e[c + 1] + b1e[c + 1] + a2e[c + 1] + b2e[c]
             + a3e[c + 1] + b3e[c + 2])
        if m[c] > 0.0 and n > 0.0:
            ox[c] = cx / n
            oy[c] = cy / n
            oz[c] = cz / n
        else:
            ox[c] = 0.0
            oy[c] = 0.0
            oz[c] = 0.0


@numba.njit(**JIT)
def _sl_apply_row(q, qd, dv, corr, h, r):
    """``q += corr``, ``qd += corr / h``, ``dv += corr / h`` on row r (adding 0.0 changes
    nothing)."""
    for d in range(3):
        x = q[d, r]
        u = qd[d, r]
        w = dv[d, r]
        k = corr[d, r]
        for c in range(x.shape[0]):
            e = k[c]
            x[c] += e
            eh = e / h
            u[c] += eh
            w[c] += eh


@numba.njit(**JIT)
def _sl_chunk(q, qd, dv, mov, corr, h, limit, threshold, fw, snap, r0, r1):
    """One sweep on rows ``r0 .. r1-1`` in one streaming pass; returns how many springs
    whose first end lies in these rows exceed the tolerance.

    Row r's corrections need rows r-1 .. r+1 as they were before the sweep; once row r is
    gathered, no later row of the sweep reads it, so it can be corrected at once. That is
    only allowed once the sweep is known to be applied, i.e. once a spring over the
    tolerance has been seen: rows before that stay pending (their corrections in
    ``corr``) and the caller applies them if another chunk saw one. ``snap[0]`` and
    ``snap[1]``: rows ``r0 - 1`` and ``r1`` before the sweep (the neighbouring chunks may
    already have corrected them)."""
    rows, cols = mov.shape
    if r0 == 0:
        fw[1, :, :] = 0.0   # "row -1" has no springs
    count = 0
    done = r0               # rows r0 .. done-1 are corrected
    # row r0 - 1 (from the snapshot) only supplies its forward springs; one call site
    # of _sl_forward keeps the compiled code (and compile time) small
    for r in range(max(r0 - 1, 0), r1):
        if r < r0:
            xp, yp, zp = snap[0, 0], snap[0, 1], snap[0, 2]
        else:
            xp, yp, zp = _v3(q, r, 0)
        has_next = r + 1 < rows
        if r + 1 == r1 and has_next:
            xn, yn, zn = snap[1, 0], snap[1, 1], snap[1, 2]
        else:
            xn, yn, zn = _v3(q, min(r + 1, rows - 1), 0)
        cnt = _sl_forward(xp, yp, zp, mov[r], xn, yn, zn, mov[min(r + 1, rows - 1)],
                          has_next, limit, threshold, fw[r % 2])
        if r < r0:
            continue
        _sl_gather(mov, corr, fw[r % 2], fw[(r + 1) % 2], r)
        count += cnt
        if count > 0:
            for j in range(done, r + 1):
                _sl_apply_row(q, qd, dv, corr, h, j)
            done = r + 1
    return count


@numba.njit(**JIT)
def _flat3(a):
    """The x, y and z planes of a ``(3, rows, cols)`` array as flat views."""
    n = a.shape[1] * a.shape[2]
    return a[0].reshape(n), a[1].reshape(n), a[2].reshape(n)


@numba.njit(**JIT)
def _sl_spring_valid(xp, yp, zp, mp, xn, yn, zn, mn, k, valid, limit, threshold, fx, fy,
                     fz, fe):
    """:func:`_sl_spring` from ``p[k]`` to ``n[k]`` (``n``: views of the same planes
    shifted by the neighbour's offset), stored at ``k``; counted as absent where
    ``valid[k]`` is 0 (a neighbour that wrapped around a row end)."""
    dx = xn[k] - xp[k]
    dy = yn[k] - yp[k]
    dz = zn[k] - zp[k]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    exceed = valid[k] > 0.0 and not (length <= limit)
    a = mp[k]
    b = mn[k]
    share = 1.0 - 0.5 * (a * b)
    f = share * (length - limit) / length
    # a select, not a product with 0: a wrapped neighbour may be NaN
    fx[k] = f * dx if exceed else 0.0
    fy[k] = f * dy if exceed else 0.0
    fz[k] = f * dz if exceed else 0.0
    fe[k] = 1.0 if exceed else 0.0
    return 1 if (exceed and a + b > 0.0 and length >= threshold) else 0


@numba.njit(**JIT)
def _sl_flat_dir(x, y, z, m, lo, hi, off, valid, limit, threshold, fw, e0, pad):
    """Springs of one direction (flat neighbour offset ``off``) from points ``lo .. hi-1``
    into ``fw[e0 .. e0+3]``."""
    xp, yp, zp, mp, vp = x[lo:], y[lo:], z[lo:], m[lo:], valid[lo:]
    xn, yn, zn, mn = x[lo + off:], y[lo + off:], z[lo + off:], m[lo + off:]
    fx, fy, fz, fe = fw[e0, pad + lo:], fw[e0 + 1, pad + lo:], fw[e0 + 2, pad + lo:], \
        fw[e0 + 3, pad + lo:]
    cnt = 0
    for k in range(hi - lo):
        cnt += _sl_spring_valid(xp, yp, zp, mp, xn, yn, zn, mn, k, vp, limit, threshold,
                                fx, fy, fz, fe)
    return cnt


@numba.njit(**JIT)
def _sl_flat_sweep(q, mov, corr, limit, threshold, fw, valid_r, valid_l, ones):
    """One sweep's corrections on a small level as a whole: flat loops over all points
    instead of short loops per row (same springs, same order as :func:`_sl_forward` and
    :func:`_sl_gather`). ``fw``: ``(16, n + 2 * (cols + 1))``, point k's forward springs
    at ``k + cols + 1``, zero elsewhere; ``valid_r`` / ``valid_l``: 1.0 where a point has
    a right / left neighbour. Returns how many springs exceed the tolerance."""
    rows, cols = mov.shape
    n = rows * cols
    pad = cols + 1
    x, y, z = _flat3(q)
    m = mov.reshape(n)
    count = 0
    count += _sl_flat_dir(x, y, z, m, 0, n - 1, 1, valid_r, limit[0], threshold[0], fw, 0,
                          pad)
    count += _sl_flat_dir(x, y, z, m, 0, n - cols, cols, ones, limit[1], threshold[1], fw,
                          4, pad)
    count += _sl_flat_dir(x, y, z, m, 0, n - cols - 1, cols + 1, valid_r, limit[2],
                          threshold[2], fw, 8, pad)
    count += _sl_flat_dir(x, y, z, m, 1, n - cols, cols - 1, valid_l, limit[3],
                          threshold[3], fw, 12, pad)
    ox, oy, oz = _flat3(corr)
    # s: 0 (0,1) 1 (0,-1) 2 (1,0) 3 (-1,0) 4 (1,1) 5 (-1,-1) 6 (1,-1) 7 (-1,1)
    a0x, a0y, a0z, a0e = fw[0, pad:], fw[1, pad:], fw[2, pad:], fw[3, pad:]
    b0x, b0y, b0z, b0e = fw[0, cols:], fw[1, cols:], fw[2, cols:], fw[3, cols:]
    a1x, a1y, a1z, a1e = fw[4, pad:], fw[5, pad:], fw[6, pad:], fw[7, pad:]
    b1x, b1y, b1z, b1e = fw[4, 1:], fw[5, 1:], fw[6, 1:], fw[7, 1:]
    a2x, a2y, a2z, a2e = fw[8, pad:], fw[9, pad:], fw[10, pad:], fw[11, pad:]
    b2x, b2y, b2z, b2e = fw[8], fw[9], fw[10], fw[11]
    a3x, a3y, a3z, a3e = fw[12, pad:], fw[13, pad:], fw[14, pad:], fw[15, pad:]
    b3x, b3y, b3z, b3e = fw[12, 2:], fw[13, 2:], fw[14, 2:], fw[15, 2:]
    for k in range(n):
        cx = 0.0
        cy = 0.0
        cz = 0.0
        cx += a0x[k]
        cy += a0y[k]
        cz += a0z[k]
        cx -= b0x[k]
        cy -= b0y[k]
        cz -= b0z[k]
        cx += a1x[k]
        cy += a1y[k]
        cz += a1z[k]
        cx -= b1x[k]
        cy -= b1y[k]
        cz -= b1z[k]
        cx += a2x[k]
        cy += a2y[k]
        cz += a2z[k]
        cx -= b2x[k]
        cy -= b2y[k]
        cz -= b2z[k]
        cx += a3x[k]
        cy += a3y[k]
        cz += a3z[k]
        cx -= b3x[k]
        cy -= b3y[k]
        cz -= b3z[k]
        e = a0e[k] + b0e[k] + a1e[k] + b1e[k] + a2e[k] + b2e[k] + a3e[k] + b3e[k]
        if m[k] > 0.0 and e > 0.0:
            ox[k] = cx / e
            oy[k] = cy / e
            oz[k] = cz / e
        else:
            ox[k] = 0.0
            oy[k] = 0.0
            oz[k] = 0.0
    return count


@numba.njit(**JIT)
def _sl_flat_apply(q, qd, dv, corr, h):
    """:func:`_sl_apply_row` over a whole level at once."""
    for d in range(3):
        n = q.shape[1] * q.shape[2]
        x = q[d].reshape(n)
        u = qd[d].reshape(n)
        w = dv[d].reshape(n)
        k = corr[d].reshape(n)
        for c in range(n):
            e = k[c]
            x[c] += e
            eh = e / h
            u[c] += eh
            w[c] += eh


@numba.njit(**JIT)
def _sl_flat(q, qd, dv, mov, corr, h, limit, threshold, max_iterations):
    """The fast path's sweeps on a small level (see :func:`_sl_flat_sweep`)."""
    rows, cols = mov.shape
    n = rows * cols
    fwf = np.zeros((16, n + 2 * (cols + 1)))
    valid_r = np.ones(n)
    valid_l = np.ones(n)
    for r in range(rows):
        valid_r[r * cols + cols - 1] = 0.0
        valid_l[r * cols] = 0.0
    ones = np.ones(n)
    for it in range(max_iterations):
        if _sl_flat_sweep(q, mov, corr, limit, threshold, fwf, valid_r, valid_l,
                          ones) == 0:
            return it
        _sl_flat_apply(q, qd, dv, corr, h)
    return max_iterations


@numba.njit(**PJIT)
def _sl_chunked(q, qd, dv, mov, corr, h, limit, threshold, max_iterations):
    """The fast path's sweeps on a large level: row chunks in parallel, one streaming
    pass per sweep each (see :func:`_sl_chunk`)."""
    rows, cols = mov.shape
    nch = max(2, _nchunks(rows, cols))
    fw = np.zeros((nch, 2, 16, cols + 2))
    snap = np.zeros((nch, 2, 3, cols))
    counts = np.zeros(nch, dtype=np.int64)
    for it in range(max_iterations):
        for ch in range(nch):
            r0 = ch * rows // nch
            r1 = (ch + 1) * rows // nch
            for d in range(3):
                if r0 > 0:
                    snap[ch, 0, d] = q[d, r0 - 1]
                if r1 < rows:
                    snap[ch, 1, d] = q[d, r1]
        for ch in prange(nch):
            counts[ch] = _sl_chunk(q, qd, dv, mov, corr, h, limit, threshold, fw[ch],
                                   snap[ch], ch * rows // nch, (ch + 1) * rows // nch)
        if counts.sum() == 0:
            return it       # nothing was corrected: every chunk's rows are pending
        for ch in range(nch):
            if counts[ch] == 0:     # saw no spring over the tolerance itself: pending
                for r in range(ch * rows // nch, (ch + 1) * rows // nch):
                    _sl_apply_row(q, qd, dv, corr, h, r)
    return max_iterations


@numba.njit(**JIT)
def strain_limit(q, qd, dv, rest, kind, inherited_fixed, max_stretch, max_iterations,
                 tolerance, h, corr):
    """Provot-style strain limiting by Jacobi sweeps over structural and shear springs.

    A spring longer than ``(1 + max_stretch) * rest`` pulls its movable ends back towards
    each other (all of the excess onto a movable end whose partner is fixed, half each
    when both move); each point applies the mean of its corrections. Velocities take the
    same change divided by ``h`` so that motion stays consistent with positions.
    Sweeps stop once no spring exceeds its limit by more than ``tolerance`` (relative) or
    after ``max_iterations``; returns the sweeps applied. ``inherited_fixed``: on a
    refinement level, inherited points belong to the coarser level and do not move here.

    Fast path (symmetric rest lengths, the model's case): each spring is evaluated once
    per sweep for both of its ends (the second end's term is the exact negation), rows
    stream through a two-row buffer of spring terms and are corrected in the same pass
    (:func:`_sl_chunk`), one parallel region per sweep, and the stopping test compares
    lengths with a precomputed threshold instead of dividing. Same numbers as
    :func:`_strain_limit_generic`.
    """
    rows, cols = kind.shape
    limit = np.empty(4)
    threshold = np.empty(4)
    fast = tolerance >= 0.0 and tolerance < np.inf and q.shape[1] == rows \
        and q.shape[2] == cols
    for d in range(4):
        s = 2 * d
        limit[d] = (1.0 + max_stretch) * rest[s]
        if not (rest[s] == rest[s + 1] and limit[d] > 0.0 and limit[d] < np.inf):
            fast = False
    if not fast:
        return _strain_limit_generic(q, qd, dv, rest, kind, inherited_fixed, max_stretch,
                                     max_iterations, tolerance, h, corr)
    for d in range(4):
        threshold[d] = _excess_threshold(limit[d], tolerance)
    mov = np.empty((rows, cols))
    for r in range(rows):
        kr = kind[r]
        mr = mov[r]
        even_row = inherited_fixed and r % 2 == 0
        for c in range(cols):      # _movable, in a form that vectorises
            fixed = kr[c] != FREE or (even_row and c % 2 == 0)
            mr[c] = 0.0 if fixed else 1.0
    if rows * cols < FLAT_MAX_POINTS:
        return _sl_flat(q, qd, dv, mov, corr, h, limit, threshold, max_iterations)
    return _sl_chunked(q, qd, dv, mov, corr, h, limit, threshold, max_iterations)


@numba.njit(**JIT)
def _resolve_contact(q, qd, dv, r, c, nx, ny, nz, depth, friction):
    """Move a point ``depth`` along unit normal n, stop its inward normal velocity and
    slow its tangential velocity by Coulomb friction (never reversing it)."""
    q[0, r, c] += depth * nx
    q[1, r, c] += depth * ny
    q[2, r, c] += depth * nz
    vx = qd[0, r, c]
    vy = qd[1, r, c]
    vz = qd[2, r, c]
    vn = vx * nx + vy * ny + vz * nz
    if vn >= 0.0:
        return
    tx = vx - vn * nx
    ty = vy - vn * ny
    tz = vz - vn * nz
    vt = math.sqrt(tx * tx + ty * ty + tz * tz)
    scale = 0.0
    if vt > 0.0:
        scale = max(0.0, 1.0 - friction * (-vn) / vt)
    nvx = tx * scale
    nvy = ty * scale
    nvz = tz * scale
    dv[0, r, c] += nvx - vx
    dv[1, r, c] += nvy - vy
    dv[2, r, c] += nvz - vz
    qd[0, r, c] = nvx
    qd[1, r, c] = nvy
    qd[2, r, c] = nvz


@numba.njit(**PJIT)
def contact(q, qd, dv, q_prev, kind, inherited_fixed, planes, boxes, spheres, friction, margin):
    """Push movable points out of static obstacles (see :mod:`hcloth_ros.core.scene`).

    ``q_prev``: positions at the start of the step (to tell which face a point entered
    a box by)."""
    rows, cols = kind.shape
    for r in prange(rows):
        for c in range(cols):
            if not _movable(kind, r, c, inherited_fixed):
                continue
            for p in range(planes.shape[0]):
                nx, ny, nz, off = planes[p, 0], planes[p, 1], planes[p, 2], planes[p, 3]
                dist = q[0, r, c] * nx + q[1, r, c] * ny + q[2, r, c] * nz - off - margin
                if dist < 0.0:
                    _resolve_contact(q, qd, dv, r, c, nx, ny, nz, -dist, friction)
            for b in range(boxes.shape[0]):
                # Leave through the face the point entered by: the axis on which its
                # start-of-step position was furthest outside (nearest face if it was
                # already inside). Nearest-face alone pushes points that fall onto a
                # table top near its edge out sideways, tearing the cloth there.
                best = 1e300
                axis = -1
                entry = -1e300
                inside = True
                for d in range(3):
                    rel = q[d, r, c] - boxes[b, d]
                    pen = boxes[b, 3 + d] + margin - abs(rel)
                    if pen <= 0.0:
                        inside = False
                        break
                    outside_before = abs(q_prev[d, r, c] - boxes[b, d]) - boxes[b, 3 + d] \
                        - margin
                    if outside_before > entry:
                        entry = outside_before
                        axis = d
                    if entry <= 0.0 and pen < best:
                        best = pen
                if not inside:
                    continue
                if entry <= 0.0:
                    axis = 0
                    best = 1e300
                    for d in range(3):
                        pen = boxes[b, 3 + d] + margin - abs(q[d, r, c] - boxes[b, d])
                        if pen < best:
                            best = pen
                            axis = d
                rel = q[axis, r, c] - boxes[b, axis]
                sign = 1.0 if (q_prev[axis, r, c] - boxes[b, axis]) >= 0.0 else -1.0
                depth = boxes[b, 3 + axis] + margin - sign * rel
                _resolve_contact(q, qd, dv, r, c, sign if axis == 0 else 0.0,
                                 sign if axis == 1 else 0.0, sign if axis == 2 else 0.0,
                                 depth, friction)
            for s in range(spheres.shape[0]):
                dx = q[0, r, c] - spheres[s, 0]
                dy = q[1, r, c] - spheres[s, 1]
                dz = q[2, r, c] - spheres[s, 2]
                dist = math.sqrt(dx * dx + dy * dy + dz * dz)
                pen = spheres[s, 3] + margin - dist
                if pen > 0.0:
                    if dist > 0.0:
                        _resolve_contact(q, qd, dv, r, c, dx / dist, dy / dist, dz / dist,
                                         pen, friction)
                    else:
                        _resolve_contact(q, qd, dv, r, c, 0.0, 0.0, 1.0, pen, friction)



@numba.njit(**JIT)
def _stats_rows(q, qd, rest, r0, r1, row_max, row_sum, row_cnt, row_bad):
    rows, cols = q.shape[1], q.shape[2]
    pbuf = np.empty(cols)       # |strain| of finite strains, else 0
    mbuf = np.empty(cols)       # strain where finite and > 0, else 0
    mbits = mbuf.view(np.int64)
    for r in range(r0, r1):
        bad = 0
        for d in range(3):
            x = q[d, r]
            v = qd[d, r]
            for c in range(cols):
                bad += not (math.isfinite(x[c]) and math.isfinite(v[c]))
        top = 0                 # bit pattern of the largest strain (>= 0.0) so far
        cnt = 0
        sm = 0.0
        # each spring once: the stencil entries pointing right, down, down-right and
        # down-left
        for s in (0, 2, 4, 6):
            dr = DR[s]
            dc = DC[s]
            if r + dr >= rows:
                continue
            c0 = 1 if dc < 0 else 0
            c1 = cols - 1 if dc > 0 else cols
            m = c1 - c0
            if m <= 0:
                continue
            xb, yb, zb = _v3(q, r + dr, c0 + dc)
            xs, ys, zs = _v3(q, r, c0)
            rs = rest[s]
            fin = 0
            for i in range(m):
                dx = xb[i] - xs[i]
                dy = yb[i] - ys[i]
                dz = zb[i] - zs[i]
                e = math.sqrt(dx * dx + dy * dy + dz * dz) / rs - 1.0
                ok = math.isfinite(e)
                fin += ok
                pbuf[i] = abs(e) if ok else 0.0
                mbuf[i] = e if (ok and e > 0.0) else 0.0
            cnt += fin
            bad += m - fin
            # the largest: bit patterns of non-negative floats order like the floats,
            # and an integer max reduction vectorises (exact in any order)
            for i in range(m):
                b = mbits[i]
                if b > top:
                    top = b
            # the sum of |e| in eight interleaved partial sums: a reordered sum of
            # non-negative terms, relative difference at most ~m * 1.1e-16 from the
            # sequential one
            p0 = p1 = p2 = p3 = p4 = p5 = p6 = p7 = 0.0
            m8 = m - m % 8
            for i in range(0, m8, 8):
                p0 += pbuf[i]
                p1 += pbuf[i + 1]
                p2 += pbuf[i + 2]
                p3 += pbuf[i + 3]
                p4 += pbuf[i + 4]
                p5 += pbuf[i + 5]
                p6 += pbuf[i + 6]
                p7 += pbuf[i + 7]
            for i in range(m8, m):
                p0 += pbuf[i]
            sm += ((p0 + p1) + (p2 + p3)) + ((p4 + p5) + (p6 + p7))
        mbits[0] = top
        row_max[r] = mbuf[0]
        row_sum[r] = sm
        row_cnt[r] = cnt
        row_bad[r] = 1.0 if bad > 0 else 0.0


@numba.njit(**PJIT)
def strain_stats(q, qd, rest):
    """Largest relative stretch of structural and shear springs, and whether every
    position and velocity is finite. Returns ``(max_strain, mean_strain, finite)``.

    A non-finite spring strain also counts as not finite and is left out of the max and
    the mean. The mean's sum is taken in a different order than one point after another
    (difference at rounding level, ~1e-16 relative)."""
    rows, cols = q.shape[1], q.shape[2]
    row_max = np.zeros(rows)
    row_sum = np.zeros(rows)
    row_cnt = np.zeros(rows)
    row_bad = np.zeros(rows)
    nch = _nchunks(rows, cols)
    for ch in prange(nch):
        _stats_rows(q, qd, rest, ch * rows // nch, (ch + 1) * rows // nch, row_max,
                    row_sum, row_cnt, row_bad)
    return row_max.max(), row_sum.sum() / max(row_cnt.sum(), 1.0), row_bad.max() == 0.0


@numba.njit(**PJIT)
def energy(q, qd, mass, rest, stiff, contraction, gravity):
    """Kinetic, gravitational (zero at the origin) and elastic energy of a level (J)."""
    rows, cols = mass.shape
    kin = np.zeros(rows)
    pot = np.zeros(rows)
    ela = np.zeros(rows)
    for r in prange(rows):
        ke = 0.0
        pe = 0.0
        ee = 0.0
        for c in range(cols):
            m = mass[r, c]
            v2 = 0.0
            for d in range(3):
                v2 += qd[d, r, c] * qd[d, r, c]
                pe -= m * gravity[d] * q[d, r, c]
            ke += 0.5 * m * v2
            for s in range(0, NSTENCIL, 2):   # every spring once: even stencil entries
                rr = r + DR[s]
                cc = c + DC[s]
                if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                    continue
                dx = q[0, rr, cc] - q[0, r, c]
                dy = q[1, rr, cc] - q[1, r, c]
                dz = q[2, rr, cc] - q[2, r, c]
                e = math.sqrt(dx * dx + dy * dy + dz * dz) - rest[s]
                k = stiff[s] if e >= 0.0 else stiff[s] * contraction
                ee += 0.5 * k * e * e
        kin[r] = ke
        pot[r] = pe
        ela[r] = ee
    return kin.sum(), pot.sum(), ela.sum()


# --- backward Euler (the converged reference) --------------------------------------------

@numba.njit(**PJIT)
def spring_forces(q, rest, stiff, contraction, f):
    """Spring forces on every point (N), no damping."""
    rows, cols = q.shape[1], q.shape[2]
    for r in prange(rows):
        for c in range(cols):
            fx = 0.0
            fy = 0.0
            fz = 0.0
            for s in range(NSTENCIL):
                rr = r + DR[s]
                cc = c + DC[s]
                if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                    continue
                sx, sy, sz = _spring(q, r, c, rr, cc, rest[s], stiff[s], contraction)
                fx += sx
                fy += sy
                fz += sz
            f[0, r, c] = fx
            f[1, r, c] = fy
            f[2, r, c] = fz


@numba.njit(**JIT)
def _stiffness_block(q, r, c, rr, cc, rest, stiff, contraction):
    """Coefficients of the spring's stiffness block ``B = k (b I + (1-b) u u^T)``.

    ``-B`` is the force Jacobian of the spring (Baraff and Witkin 1998) with the
    transverse term clamped at zero for compressed springs, which keeps the Newton matrix
    positive definite; Newton still converges to the exact backward-Euler solution because
    the residual is exact.
    """
    dx = q[0, rr, cc] - q[0, r, c]
    dy = q[1, rr, cc] - q[1, r, c]
    dz = q[2, rr, cc] - q[2, r, c]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    k = stiff if length >= rest else stiff * contraction
    if length <= 0.0:
        return k, 1.0, 0.0, 0.0, 0.0
    b = max(0.0, 1.0 - rest / length)
    return k, b, dx / length, dy / length, dz / length


@numba.njit(**JIT)
def _system_apply_point(q, rest, stiff, contraction, mass, free, h, p, out, r, c):
    rows, cols = mass.shape
    h2 = h * h
    if free[r, c] == 0.0:
        for d in range(3):
            out[d, r, c] = p[d, r, c]
        return
    m = mass[r, c]
    ox = m * p[0, r, c]
    oy = m * p[1, r, c]
    oz = m * p[2, r, c]
    for s in range(NSTENCIL):
        rr = r + DR[s]
        cc = c + DC[s]
        if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
            continue
        k, b, ux, uy, uz = _stiffness_block(q, r, c, rr, cc, rest[s], stiff[s],
                                            contraction)
        px = p[0, r, c] - free[rr, cc] * p[0, rr, cc]
        py = p[1, r, c] - free[rr, cc] * p[1, rr, cc]
        pz = p[2, r, c] - free[rr, cc] * p[2, rr, cc]
        proj = (1.0 - b) * (ux * px + uy * py + uz * pz)
        ox += h2 * k * (b * px + proj * ux)
        oy += h2 * k * (b * py + proj * uy)
        oz += h2 * k * (b * pz + proj * uz)
    out[0, r, c] = ox
    out[1, r, c] = oy
    out[2, r, c] = oz


@numba.njit(**JIT)
def _system_apply_dir(q, free, p, r, c0, n, dr, dc, rest, stiff, contraction, h2, ox, oy,
                      oz):
    """Add one stencil entry's term of :func:`system_apply` to ``o*[i]`` for points
    ``(r, c0 + i)`` (interior fast path; the body of ``_stiffness_block`` and of the
    per-point loop)."""
    xp, yp, zp = _v3(q, r, c0)
    xn, yn, zn = _v3(q, r + dr, c0 + dc)
    ap, bp, cp = _v3(p, r, c0)
    an, bn, cn = _v3(p, r + dr, c0 + dc)
    fn = free[r + dr, c0 + dc:]
    for i in range(n):
        dx = xn[i] - xp[i]
        dy = yn[i] - yp[i]
        dz = zn[i] - zp[i]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        k = stiff if length >= rest else stiff * contraction
        if length <= 0.0:
            b = 1.0
            ux = 0.0
            uy = 0.0
            uz = 0.0
        else:
            b = max(0.0, 1.0 - rest / length)
            ux = dx / length
            uy = dy / length
            uz = dz / length
        f = fn[i]
        px = ap[i] - f * an[i]
        py = bp[i] - f * bn[i]
        pz = cp[i] - f * cn[i]
        proj = (1.0 - b) * (ux * px + uy * py + uz * pz)
        ox[i] += h2 * k * (b * px + proj * ux)
        oy[i] += h2 * k * (b * py + proj * uy)
        oz[i] += h2 * k * (b * pz + proj * uz)


@numba.njit(**JIT)
def _system_apply_rows(q, rest, stiff, contraction, mass, free, h, p, out, r0, r1):
    rows, cols = mass.shape
    n = cols - 4
    oxb = np.empty(max(n, 1))
    oyb = np.empty(max(n, 1))
    ozb = np.empty(max(n, 1))
    h2 = h * h
    for r in range(r0, r1):
        if not (2 <= r < rows - 2 and n > 0):
            for c in range(cols):
                _system_apply_point(q, rest, stiff, contraction, mass, free, h, p, out, r, c)
            continue
        for c in (0, 1, cols - 2, cols - 1):
            _system_apply_point(q, rest, stiff, contraction, mass, free, h, p, out, r, c)
        mr = mass[r, 2:]
        fr = free[r, 2:]
        ax, ay, az = _v3(p, r, 2)
        for i in range(n):
            m = mr[i]
            oxb[i] = m * ax[i]
            oyb[i] = m * ay[i]
            ozb[i] = m * az[i]
        for s in range(NSTENCIL):
            _system_apply_dir(q, free, p, r, 2, n, DR[s], DC[s], rest[s], stiff[s],
                              contraction, h2, oxb, oyb, ozb)
        tx, ty, tz = _v3(out, r, 2)
        for i in range(n):
            held = fr[i] == 0.0
            tx[i] = ax[i] if held else oxb[i]
            ty[i] = ay[i] if held else oyb[i]
            tz[i] = az[i] if held else ozb[i]


@numba.njit(**PJIT)
def system_apply(q, rest, stiff, contraction, mass, free, h, p, out):
    """``out = (M - h^2 J) p`` on free points; identity on held ones (filtered system)."""
    rows, cols = mass.shape
    nch = _nchunks(rows, cols)
    for ch in prange(nch):
        _system_apply_rows(q, rest, stiff, contraction, mass, free, h, p, out,
                           ch * rows // nch, (ch + 1) * rows // nch)


@numba.njit(**PJIT)
def system_diagonal(q, rest, stiff, contraction, mass, free, h, diag):
    """Diagonal of the filtered system matrix (the Jacobi preconditioner)."""
    rows, cols = mass.shape
    h2 = h * h
    for r in prange(rows):
        for c in range(cols):
            if free[r, c] == 0.0:
                for d in range(3):
                    diag[d, r, c] = 1.0
                continue
            dx = mass[r, c]
            dy = dx
            dz = dx
            for s in range(NSTENCIL):
                rr = r + DR[s]
                cc = c + DC[s]
                if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                    continue
                k, b, ux, uy, uz = _stiffness_block(q, r, c, rr, cc, rest[s], stiff[s],
                                                    contraction)
                dx += h2 * k * (b + (1.0 - b) * ux * ux)
                dy += h2 * k * (b + (1.0 - b) * uy * uy)
                dz += h2 * k * (b + (1.0 - b) * uz * uz)
            diag[0, r, c] = dx
            diag[1, r, c] = dy
            diag[2, r, c] = dz


@numba.njit(**PJIT)
def _dot(a, b):
    rows = a.shape[1]
    total = np.zeros(rows)
    for r in prange(rows):
        s = 0.0
        for d in range(3):
            for c in range(a.shape[2]):
                s += a[d, r, c] * b[d, r, c]
        total[r] = s
    return total.sum()


@numba.njit(**JIT)
def conjugate_gradient(q, rest, stiff, contraction, mass, free, h, b, x, diag, rtol,
                       max_iter, r, z, p, ap):
    """Solve the filtered system ``(M - h^2 J) x = b`` from ``x = 0`` by Jacobi-
    preconditioned CG to ``|r| <= rtol |b|``. Returns ``(iterations, |r| / |b|)``.
    The work arrays must be C-contiguous (the solver's are)."""
    x[:] = 0.0
    r[:] = b
    bnorm = math.sqrt(_dot(b, b))
    if bnorm == 0.0:
        return 0, 0.0
    z[:] = r / diag
    p[:] = z
    rz = _dot(r, z)
    rel = 1.0
    # the vector updates as loops over flat views: the same element-wise operations as
    # the array expressions, without their temporaries
    n = x.size
    xf = x.reshape(n)
    rf = r.reshape(n)
    zf = z.reshape(n)
    pf = p.reshape(n)
    af = ap.reshape(n)
    df = diag.reshape(n)
    for it in range(1, max_iter + 1):
        system_apply(q, rest, stiff, contraction, mass, free, h, p, ap)
        alpha = rz / _dot(p, ap)
        for i in range(n):
            xf[i] += alpha * pf[i]
        for i in range(n):
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
