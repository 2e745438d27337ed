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

FREE = 0
PINNED = 1
DRIVEN = 2


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


@numba.njit(**PJIT)
def prescribe(q, qd, kind, drive_index, drive_target, h, presc):
    """Velocity change that makes held points do what they must this step.

    Pinned: velocity becomes zero, so ``x + h * v`` is ``x`` bit for bit. Driven: the
    velocity that reaches the target at the end of the step.
    """
    rows, cols = kind.shape
    for r in prange(rows):
        for c in range(cols):
            if kind[r, c] == PINNED:
                for d in range(3):
                    presc[d, r, c] = -qd[d, r, c]
    for m in range(drive_index.shape[0]):
        g = drive_index[m]
        r = g // cols
        c = g % cols
        for d in range(3):
            presc[d, r, c] = (drive_target[d, m] - q[d, r, c]) / h - qd[d, r, c]


@numba.njit(**PJIT)
def eq6_first_sweep(q, qd, mass, rest, stiff, contraction, dinv, kind, presc, h,
                    gravity, literal, ft, a):
    """First Jacobi sweep of eq. 6: ``ft = h f~`` and ``a = h f~ / (m + h^2 K)``.

    ``literal``: gravity goes through the filter (the paper as written); otherwise ``a``
    holds only the spring part and held points carry their velocity change less the
    exact external part ``h g``.
    """
    rows, cols = mass.shape
    for r in prange(rows):
        for c in range(cols):
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


@numba.njit(**PJIT)
def eq6_second_sweep(q, qd, stiff, dinv, kind, presc, ft, a, h, gravity, literal,
                     q_out, qd_out, dv_out):
    """Second sweep of eq. 6, then ``v += dv`` and ``x += h v`` (semi-implicit order)."""
    rows, cols = dinv.shape
    h2 = h * h
    for r in prange(rows):
        for c in range(cols):
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


@numba.njit(**PJIT)
def prolong(coarse, fine):
    """Fill a level-k array from level k-1 with the hierarchy's parent rule.

    Inherited points copy their coarse value; inserted points take the mean of the two
    ends of the edge they were inserted on (the "\\" diagonal for face centres). Used for
    eq. 7's ``dv_app`` and to start a newly simulated level from the coarser state.
    """
    rows, cols = fine.shape[1], fine.shape[2]
    for r in prange(rows):
        r0 = r // 2
        r1 = (r + 1) // 2
        for c in range(cols):
            c0 = c // 2
            c1 = (c + 1) // 2
            for d in range(fine.shape[0]):
                fine[d, r, c] = 0.5 * (coarse[d, r0, c0] + coarse[d, r1, c1])


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
    h2 = h * h
    ext = 0.0 if literal else h
    gx = ext * gravity[0]
    gy = ext * gravity[1]
    gz = ext * gravity[2]
    for r in prange(rows):
        for c in range(cols):
            if r % 2 == 0 and c % 2 == 0:
                rc = r // 2
                cc2 = c // 2
                for d in range(3):
                    q_out[d, r, c] = q_coarse[d, rc, cc2]
                    qd_out[d, r, c] = qd_coarse[d, rc, cc2]
                    dv_out[d, r, c] = dv_coarse[d, rc, cc2]
                continue
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


@numba.njit(**PJIT)
def explicit_step(q, qd, mass, rest, stiff, contraction, kind, presc, h, gravity,
                  q_out, qd_out, dv_out):
    """Symplectic Euler: ``v += h (f / m + g)``, then ``x += h v``."""
    rows, cols = mass.shape
    for r in prange(rows):
        for c in range(cols):
            if kind[r, c] != FREE:
                for d in range(3):
                    dv_out[d, r, c] = presc[d, r, c]
            else:
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
                inv_m = 1.0 / mass[r, c]
                dv_out[0, r, c] = h * (fx * inv_m + gravity[0])
                dv_out[1, r, c] = h * (fy * inv_m + gravity[1])
                dv_out[2, r, c] = h * (fz * inv_m + gravity[2])
            for d in range(3):
                v = qd[d, r, c] + dv_out[d, r, c]
                qd_out[d, r, c] = v
                q_out[d, r, c] = q[d, r, c] + h * v


@numba.njit(**JIT)
def _movable(kind, r, c, inherited_fixed):
    if kind[r, c] != FREE:
        return False
    return not (inherited_fixed and r % 2 == 0 and c % 2 == 0)


@numba.njit(**PJIT)
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
    """
    rows, cols = kind.shape
    row_excess = np.zeros(rows)
    for it in range(max_iterations):
        for r in prange(rows):
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
        for r in prange(rows):
            for c in range(cols):
                for d in range(3):
                    x = corr[d, r, c]
                    if x != 0.0:
                        q[d, r, c] += x
                        qd[d, r, c] += x / h
                        dv[d, r, c] += x / h
    return max_iterations


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


@numba.njit(**PJIT)
def strain_stats(q, qd, rest):
    """Largest relative stretch of structural and shear springs, and whether every
    position and velocity is finite. Returns ``(max_strain, mean_strain, finite)``."""
    rows, cols = q.shape[1], q.shape[2]
    row_max = np.zeros(rows)
    row_sum = np.zeros(rows)
    row_cnt = np.zeros(rows)
    row_bad = np.zeros(rows)
    for r in prange(rows):
        mx = 0.0
        sm = 0.0
        cnt = 0.0
        bad = 0.0
        for c in range(cols):
            for d in range(3):
                if not (math.isfinite(q[d, r, c]) and math.isfinite(qd[d, r, c])):
                    bad = 1.0
            # each spring once: the stencil entries pointing right, down and down-right,
            # down-left
            for s in (0, 2, 4, 6):
                rr = r + DR[s]
                cc = c + DC[s]
                if rr < 0 or rr >= rows or cc < 0 or cc >= cols:
                    continue
                dx = q[0, rr, cc] - q[0, r, c]
                dy = q[1, rr, cc] - q[1, r, c]
                dz = q[2, rr, cc] - q[2, r, c]
                e = math.sqrt(dx * dx + dy * dy + dz * dz) / rest[s] - 1.0
                if not math.isfinite(e):
                    bad = 1.0
                    continue
                if e > mx:
                    mx = e
                sm += abs(e)
                cnt += 1.0
        row_max[r] = mx
        row_sum[r] = sm
        row_cnt[r] = cnt
        row_bad[r] = bad
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


@numba.njit(**PJIT)
def system_apply(q, rest, stiff, contraction, mass, free, h, p, out):
    """``out = (M - h^2 J) p`` on free points; identity on held ones (filtered system)."""
    rows, cols = mass.shape
    h2 = h * h
    for r in prange(rows):
        for c in range(cols):
            if free[r, c] == 0.0:
                for d in range(3):
                    out[d, r, c] = p[d, r, c]
                continue
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
    preconditioned CG to ``|r| <= rtol |b|``. Returns ``(iterations, |r| / |b|)``."""
    x[:] = 0.0
    r[:] = b
    bnorm = math.sqrt(_dot(b, b))
    if bnorm == 0.0:
        return 0, 0.0
    z[:] = r / diag
    p[:] = z
    rz = _dot(r, z)
    rel = 1.0
    for it in range(1, max_iter + 1):
        system_apply(q, rest, stiff, contraction, mass, free, h, p, ap)
        alpha = rz / _dot(p, ap)
        x += alpha * p
        r -= alpha * ap
        rel = math.sqrt(_dot(r, r)) / bnorm
        if rel <= rtol:
            return it, rel
        z[:] = r / diag
        rz_new = _dot(r, z)
        p[:] = z + (rz_new / rz) * p
        rz = rz_new
    return max_iter, rel
