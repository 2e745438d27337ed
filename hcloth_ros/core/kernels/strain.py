"""
Strain limiting (Provot 1995) by Jacobi sweeps over structural and shear springs.

A spring longer than ``limit = (1 + max_stretch) L`` pulls its movable ends towards each
other: ``share (|d| - limit) / |d| d`` onto each end (``share`` 1 when the other end is
fixed, 1/2 when both move), and each point moves by the mean of its springs' terms.
Velocities (and the step's velocity change) take the same correction divided by ``h``, so
motion stays consistent with positions. A sweep is applied only while some spring with a
movable end exceeds its limit by more than ``tolerance`` (relative).

How a sweep runs. Each spring is evaluated once, from its first end (the point it leaves
rightwards or downwards: stencil entries 0, 2, 4, 6), and the two ends take its term with
opposite signs; those "forward" terms of a block of rows are computed over the block as
one flat array, neighbours found at fixed flat offsets (masks drop the row wrap-around),
which vectorises over the whole block. A level is split into row chunks (one per thread
on large levels) and each chunk streams through blocks of rows: a block's corrections
need its rows and the rows next to it as they were before the sweep, so a block is
corrected as soon as it is gathered. The spring terms of the row before each chunk
boundary are computed first (the neighbouring chunk may correct its rows at any time);
a chunk applies its corrections only once the sweep is known to happen, i.e. once any
spring over the tolerance has been seen, and the rest afterwards.

Sweeps after the first skip what cannot change. A point moves only through a spring over
its limit, so a spring can be over its limit in a sweep only if it was in the sweep before
or one of its ends moved then. Each sweep flags the rows whose springs (first ends) are
over with a movable end; the next sweep skips a block of rows ``b0 .. b1-1`` when no row
from ``b0 - 2`` to ``b1`` is flagged (a row's corrections read its own terms and the row
above's; a row's terms can change only if a row from one above it to one below it moved,
and a row moves only if it or the row above is flagged): all its terms and corrections
are zero, exactly as a full sweep would compute them, so they are neither written nor
applied (adding zeros to every skipped row's state was most of a later sweep's cost once
few rows stayed flagged). On a swinging cloth few rows stay flagged after the first sweep;
on a hanging one many do, and skipping saves less.

Sparse sweeps. Springs over their limit are usually few and scattered (the node's
257 x 257 cloth, 8 s into a swing: 333 of 263,000, in 188 of 257 rows, 208 points moved by
the first sweep), so a sweep may instead evaluate a list of springs: for the first sweep
every spring longer than ``1 - CLOSE`` of its limit (found by a pass of squared lengths,
no division, which gives up once the list is too long), for a later one every spring of
the points the sweep before corrected (listed only when a dense sweep moved few). The
points with a spring over its limit gather their listed terms in the dense sweep's order
(an unlisted spring's term is zero there), so both forms give the same bits; a sweep runs
dense when its list exceeds 1 / ``SPARSE_SHARE`` of the level's springs.
"""

import math

from hcloth_ros.core.kernels.jit import BORROW, JIT, serial_and_parallel
from hcloth_ros.core.kernels.layout import chunk_count, FREE
from hcloth_ros.core.kernels.springs import spring_vector
import numba
from numba import prange
import numpy as np


# Points a block of rows holds at most (its spring terms stay in the core's caches).
BLOCK_POINTS = 2048
# Spring terms per point: 4 forward directions x (x, y, z term, over-limit flag).
TERMS = 16
# A sweep runs in the sparse form (:func:`_sparse_sweep`) when the springs it must
# evaluate are at most 1 / SPARSE_SHARE of 4 per point (a little more than the level's
# springs), else dense (the table scene's contact rounds, 129 x 129, about a third of the
# points moving each sweep: 8 cost 2.2x the dense sweeps, 32 and 128 0.95x).
SPARSE_SHARE = 32
# The first sweep's candidates are the springs longer than (1 - CLOSE) times their limit:
# far more than rounding, so no spring over its limit is missed.
CLOSE = 1e-9
# Whether a build splits large levels into row chunks (only the parallel one does: in one
# thread, chunk boundaries only cost an extra row of springs each).
SPLIT_ROWS = False


@numba.njit(**JIT)
def excess_threshold(limit, tolerance):
    """
    Smallest float64 ``x`` with ``x / limit - 1.0 > tolerance`` (in floating point).

    Both operations are monotone, so for a spring longer than ``limit`` the test
    ``length >= threshold`` equals ``length / limit - 1.0 > tolerance`` exactly, without
    a division. Needs ``0 < limit < inf`` and ``0 <= tolerance < inf``.
    """
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


@numba.njit(**BORROW)
def _spring_term(dx, dy, dz, length, valid, limit, threshold, a, b):
    """
    One spring's share of a sweep, from its vector ``d`` (first end to second) and length.

    ``a``, ``b``: 1.0 where the first / second end may move. Returns the first end's term
    ``share (|d| - limit) / |d| d`` (zeros unless the spring is ``valid`` and longer than
    ``limit``), its flag (1.0: over the limit with a movable end) and whether it counts
    for the stopping test (such a spring at least ``threshold`` long). The dense and the
    sparse sweeps both call it, which is what keeps their bits equal.
    """
    # bitwise & on the flags, not `and`: a short circuit branches, and a loop with
    # branches does not vectorise (measured: 1.6x the sweep)
    over = valid & (not (length <= limit))
    f = (1.0 - 0.5 * (a * b)) * (length - limit) / length
    # a spring with no movable end counts nowhere: its ends' corrections are zero
    moves = over & (a + b > 0.0)
    # selects, not products with 0: a wrapped neighbour may be NaN
    return (f * dx if over else 0.0, f * dy if over else 0.0, f * dz if over else 0.0,
            1.0 if moves else 0.0, moves & (length >= threshold))


@numba.njit(**BORROW)
def _direction(q, movable, valid, lo, stop, end, offset, limit, threshold, terms, e0, base):
    """
    Springs from flat points ``lo .. stop-1`` to the point ``offset`` further.

    Writes the first end's term ``share (|d| - limit) / |d| d`` and the over-limit flag
    (1.0) into ``terms[e0 .. e0+3, k - base]`` for an existing spring (``valid``, indexed
    ``k - lo``) longer than ``limit``, zeros otherwise and for ``stop .. end-1`` (springs
    that leave the grid). Returns how many springs with a movable end exceed the
    tolerance (``length >= threshold``).
    """
    xp, yp, zp, mp = q[0, lo:], q[1, lo:], q[2, lo:], movable[lo:]
    xn, yn, zn, mn = q[0, lo + offset:], q[1, lo + offset:], q[2, lo + offset:], \
        movable[lo + offset:]
    tx, ty, tz, flag = terms[e0, lo - base:], terms[e0 + 1, lo - base:], \
        terms[e0 + 2, lo - base:], terms[e0 + 3, lo - base:]
    count = 0
    for i in range(stop - lo):
        dx, dy, dz, length = spring_vector(xn, yn, zn, xp, yp, zp, i)
        tx[i], ty[i], tz[i], flag[i], counts = _spring_term(
            dx, dy, dz, length, valid[i] > 0.0, limit, threshold, mp[i], mn[i])
        count += counts
    for i in range(max(stop - lo, 0), end - lo):
        tx[i] = 0.0
        ty[i] = 0.0
        tz[i] = 0.0
        flag[i] = 0.0
    return count


@numba.njit(**BORROW)
def _forward_terms(q, movable, masks, ra, rb, rows, cols, limit, threshold, terms, base):
    """
    Forward spring terms of rows ``ra .. rb-1`` into ``terms[:, k - base]``.

    Directions (0, 1), (1, 0), (1, 1) and (1, -1) in entry groups 0, 4, 8 and 12;
    ``masks[0]`` / ``masks[1]``: 1.0 where a point of a block has a right / left
    neighbour, ``masks[2]`` all ones. Returns the springs over the tolerance.
    """
    n = rows * cols
    lo, end = ra * cols, rb * cols
    offsets = (1, cols, cols + 1, cols - 1)
    stops = (n - 1, n - cols, n - cols - 1, n - cols)    # the partner leaves the grid
    mask = (0, 2, 0, 1)
    count = 0
    for j in range(limit.shape[0]):
        count += _direction(q, movable, masks[mask[j]], lo, min(end, stops[j]), end,
                            offsets[j], limit[j], threshold[j], terms, 4 * j, base)
    return count


@numba.njit(**BORROW)
def _term_views(terms, e, pad, cols):
    """
    Return the views of entry ``e``'s terms that a point's eight springs read.

    In stencil order, for point i at index i: (0, 1) forward, then backward (its left
    neighbour's term), (1, 0) and (-1, 0), (1, 1) and (-1, -1), (1, -1) and (-1, 1). Point
    i's forward terms sit at ``pad + i``; the row above ends at ``pad - 1``.
    """
    return (terms[e, pad:], terms[e, pad - 1:], terms[4 + e, pad:], terms[4 + e, pad - cols:],
            terms[8 + e, pad:], terms[8 + e, pad - cols - 1:], terms[12 + e, pad:],
            terms[12 + e, pad - cols + 1:])


@numba.njit(**BORROW)
def _gather(movable, terms, pad, cols, lo, hi, corr, active):
    """
    Write the corrections of flat points ``lo .. hi-1``: the mean of their springs' terms.

    One pass over the block, every term of a point at once: it vectorises, and a pass per
    component cost 1.2x the sweep. A backward term is the forward term negated.
    ``active``: 1.0 where a point takes a correction (movable, with a spring over its
    limit), else 0.0. Returns how many do.
    """
    x0, x1, x2, x3, x4, x5, x6, x7 = _term_views(terms, 0, pad, cols)
    y0, y1, y2, y3, y4, y5, y6, y7 = _term_views(terms, 1, pad, cols)
    z0, z1, z2, z3, z4, z5, z6, z7 = _term_views(terms, 2, pad, cols)
    c0, c1, c2, c3, c4, c5, c6, c7 = _term_views(terms, 3, pad, cols)
    m, ox, oy, oz = movable[lo:], corr[0, lo:], corr[1, lo:], corr[2, lo:]
    act = active[lo:]
    moved = 0
    for i in range(hi - lo):
        x = 0.0 + x0[i] - x1[i] + x2[i] - x3[i] + x4[i] - x5[i] + x6[i] - x7[i]
        y = 0.0 + y0[i] - y1[i] + y2[i] - y3[i] + y4[i] - y5[i] + y6[i] - y7[i]
        z = 0.0 + z0[i] - z1[i] + z2[i] - z3[i] + z4[i] - z5[i] + z6[i] - z7[i]
        n = c0[i] + c1[i] + c2[i] + c3[i] + c4[i] + c5[i] + c6[i] + c7[i]
        use = (m[i] > 0.0) & (n > 0.0)     # & not `and`: a branch stops vectorising
        ox[i] = x / n if use else 0.0
        oy[i] = y / n if use else 0.0
        oz[i] = z / n if use else 0.0
        act[i] = 1.0 if use else 0.0
        moved += use
    return moved


@numba.njit(**BORROW)
def _apply(q, qd, dv, corr, lo, hi, h):
    """``q += corr``, ``qd += corr / h``, ``dv += corr / h`` on flat points ``lo .. hi-1``."""
    for d in range(q.shape[0]):
        x, u, w, e = q[d, lo:hi], qd[d, lo:hi], dv[d, lo:hi], corr[d, lo:hi]
        for i in range(hi - lo):
            x[i] += e[i]
            u[i] += e[i] / h
            w[i] += e[i] / h


@numba.njit(**BORROW)
def _apply_rows(q, qd, dv, corr, gathered, r0, r1, cols, h):
    """
    :func:`_apply` on the rows of ``r0 .. r1-1`` whose corrections this sweep gathered.

    The other rows' corrections are zero (skipped blocks): they are neither written nor
    applied. Adding those zeros to ``q``, ``qd`` and ``dv`` of every row cost more than
    the springs once few rows stayed flagged (257 x 257 hanging: 0.65 ms a sweep).
    """
    r = r0
    while r < r1:
        if not gathered[r]:
            r += 1
            continue
        run = r
        while run < r1 and gathered[run]:
            run += 1
        _apply(q, qd, dv, corr, r * cols, run * cols, h)
        r = run


@numba.njit(**BORROW)
def _copy_terms(src, i, dst, j, n):
    """
    Copy ``src[:, i:i+n]`` to ``dst[:, j:j+n]``.

    A loop: numba's slice assignment costs seconds of compilation.
    """
    for e in range(src.shape[0]):
        a, b = src[e, i:i + n], dst[e, j:j + n]
        for k in range(n):
            b[k] = a[k]


@numba.njit(**BORROW)
def _any_flagged(row_flags, lo, hi):
    """Whether a row of ``lo .. hi-1`` (clipped to the grid) is flagged."""
    for r in range(max(lo, 0), min(hi, row_flags.size)):
        if row_flags[r]:
            return True
    return False


@numba.njit(**BORROW)
def _flag_rows(terms, pad, cols, b0, b1, row_flags):
    """Flag rows ``b0 .. b1-1`` with a spring over its limit and a movable end."""
    for r in range(b0, b1):
        start = pad + (r - b0) * cols
        total = 0.0
        for e in range(3, TERMS, 4):
            flags = terms[e, start:start + cols]
            for c in range(cols):
                total += flags[c]
        row_flags[r] = total > 0.0


@numba.njit(**BORROW)
def _zero_columns(array, start, n):
    """Set ``array[:, start:start+n]`` to zero (a loop, as in :func:`_copy_terms`)."""
    for e in range(array.shape[0]):
        row = array[e, start:start + n]
        for k in range(n):
            row[k] = 0.0


@numba.njit(**BORROW)
def _chunk_sweep(q, qd, dv, corr, movable, masks, rows, cols, r0, r1, block_rows, limit,
                 threshold, h, edge_before, edge_after, terms, applied, was_over, now_over,
                 gathered, active, moved):
    """
    One sweep over rows ``r0 .. r1-1`` (see the module docstring).

    ``edge_before`` / ``edge_after``: the forward terms of rows ``r0 - 1`` and ``r1 - 1``
    computed before the sweep (zeros for ``r0 = 0``; unused for ``r1 = rows``).
    ``applied``: the sweep is known to happen. ``was_over``: the rows the last sweep
    flagged (all for the first); ``now_over``: this sweep's flags of rows ``r0 .. r1-1``;
    ``gathered``: which of these rows had their corrections computed (the others' are zero
    and left unwritten); ``active``: per point of the gathered rows, whether it takes a
    correction (:func:`_gather`), ``moved[0]`` how many. Returns the springs over the
    tolerance counted here; rows stay uncorrected while none is seen and ``applied`` is
    False.
    """
    pad = cols + 1
    _copy_terms(edge_before, 0, terms, 1, cols)
    for e in range(terms.shape[0]):
        terms[e, 0] = 0.0                   # the row above's (non-existent) last diagonal
    count = 0
    moved[0] = 0
    done = r0                               # rows r0 .. done-1 are corrected
    for b0 in range(r0, r1, block_rows):
        b1 = min(b0 + block_rows, r1)
        if not _any_flagged(was_over, b0 - 2, b1 + 1):
            # no spring of these rows (nor of the row above) can be over its limit: zero
            # corrections (neither gathered nor applied), zero terms carried to the next
            # block
            for r in range(b0, b1):
                now_over[r] = False
                gathered[r] = False
            _zero_columns(terms, 1, cols)
            if applied or count > 0:
                _apply_rows(q, qd, dv, corr, gathered, done, b0, cols, h)
                done = b1
            continue
        base = b0 * cols - pad
        # the chunk's last row reaches into the next chunk: its terms were computed first
        own = b1 if (b1 < r1 or r1 == rows) else b1 - 1
        count += _forward_terms(q, movable, masks, b0, own, rows, cols, limit, threshold,
                                terms, base)
        if own < b1:
            _copy_terms(edge_after, 0, terms, pad + (own - b0) * cols, cols)
        _flag_rows(terms, pad, cols, b0, b1, now_over)
        moved[0] += _gather(movable, terms, pad, cols, b0 * cols, b1 * cols, corr, active)
        for r in range(b0, b1):
            gathered[r] = True
        if applied or count > 0:
            _apply_rows(q, qd, dv, corr, gathered, done, b1, cols, h)
            done = b1
        # carry the block's last row to the next block
        _copy_terms(terms, pad + (b1 - 1 - b0) * cols, terms, 1, cols)
    return count


@numba.njit(**JIT)
def _active_points(active, gathered, cols):
    """Flat indices of the points the last dense sweep corrected (gathered rows only)."""
    count = 0
    for r in range(gathered.size):
        if gathered[r]:
            for i in range(r * cols, (r + 1) * cols):
                count += active[i] > 0.0
    points = np.empty(count, dtype=np.int64)
    count = 0
    for r in range(gathered.size):
        if gathered[r]:
            for i in range(r * cols, (r + 1) * cols):
                if active[i] > 0.0:
                    points[count] = i
                    count += 1
    return points


@numba.njit(**BORROW)
def _spring_exists(j, i, rows, cols):
    """Whether forward spring ``j`` (directions of :func:`_forward_terms`) leaves point i."""
    if i < 0 or i >= rows * cols:
        return False
    r, c = i // cols, i % cols
    if j == 0:
        return c + 1 < cols
    if r + 1 >= rows:
        return False
    return (j == 1) | ((j == 2) & (c + 1 < cols)) | ((j == 3) & (c > 0))


@numba.njit(**BORROW)
def _in_set(slot, members, size, key):
    """Whether ``key`` is among ``members[:size]``, ``slot[key]`` its position if so."""
    t = slot[key]
    return 0 <= t < size and members[t] == key


@numba.njit(**JIT)
def _springs_of(points, rows, cols, offsets, spring_slot):
    """
    Every spring (key ``j n + i``: direction j from point i) of the given points, once.

    ``offsets``: the flat offsets of the four directions (int64 array);
    ``spring_slot``: int32 scratch of ``4 rows cols`` entries, any content (a sparse set:
    a key is in the list if its slot points at it).
    """
    n = rows * cols
    springs = np.empty(8 * points.size, dtype=np.int64)
    found = 0
    for a in range(points.size):
        p = points[a]
        for j in range(offsets.shape[0]):
            for first in (p, p - offsets[j]):
                key = j * n + first
                if _spring_exists(j, first, rows, cols) and \
                        not _in_set(spring_slot, springs, found, key):
                    spring_slot[key] = found
                    springs[found] = key
                    found += 1
    return springs[:found]


@numba.njit(**BORROW)
def _row_candidates(q, r, rows, cols, offsets, close2, keys, found):
    """
    Append to ``keys`` the springs leaving row r longer than ``sqrt(close2[j])``.

    NaN lengths included. Each direction's row is first counted in a loop that
    vectorises (views from the first column read: no negative-index handling); only rows
    with a candidate are walked again to list them. Returns the new length of the list.
    """
    n = rows * cols
    for j in range(offsets.shape[0]):
        if j > 0 and r + 1 >= rows:
            break
        c0 = r * cols + (1 if j == 3 else 0)
        c1 = r * cols + (cols - 1 if (j == 0) | (j == 2) else cols)
        xp, yp, zp = q[0, c0:], q[1, c0:], q[2, c0:]
        o = c0 + offsets[j]
        xn, yn, zn = q[0, o:], q[1, o:], q[2, o:]
        bound = close2[j]
        count = 0
        for i in range(c1 - c0):
            dx, dy, dz = xn[i] - xp[i], yn[i] - yp[i], zn[i] - zp[i]
            count += not (dx * dx + dy * dy + dz * dz <= bound)
        if count == 0:
            continue
        for i in range(c1 - c0):
            dx, dy, dz = xn[i] - xp[i], yn[i] - yp[i], zn[i] - zp[i]
            if not (dx * dx + dy * dy + dz * dz <= bound):
                keys[found] = j * n + c0 + i
                found += 1
    return found


def _candidates(q, rows, cols, offsets, close2, most):
    """
    Springs that may be over their limits: squared length above ``close2`` or NaN.

    ``close2[j]``: a bound a little under the square of direction j's limit (the exact
    test is the sweep's own). Returns ``(springs, True)``, or ``(empty, False)`` when more
    than ``most`` turn up (a chunk stops looking once it alone has found more; the sweep
    then runs dense). Row chunks in parallel in the parallel build.
    """
    chunks = chunk_count(rows, cols) if SPLIT_ROWS else 1
    keys = np.empty((chunks, most + 4 * cols), dtype=np.int64)    # a row adds <= 4 cols
    counts = np.zeros(chunks, dtype=np.int64)
    for ch in prange(chunks):
        found = 0
        for r in range(ch * rows // chunks, (ch + 1) * rows // chunks):
            found = _row_candidates(q, r, rows, cols, offsets, close2, keys[ch], found)
            if found > most:
                break
        counts[ch] = found
    total = counts.sum()
    if total > most:
        return np.empty(0, dtype=np.int64), False
    springs = np.empty(total, dtype=np.int64)
    at = 0
    for ch in range(chunks):
        for t in range(counts[ch]):     # a loop: slice assignment compiles for seconds
            springs[at + t] = keys[ch, t]
        at += counts[ch]
    return springs, True


_candidates, _candidates_parallel = serial_and_parallel(_candidates, SPLIT_ROWS=True)


@numba.njit(**JIT)
def _sparse_sweep(q, qd, dv, movable, rows, cols, offsets, limit, threshold, h, springs,
                  slots):
    """
    One sweep evaluating only ``springs`` (keys of :func:`_springs_of`).

    The list must hold every spring that can be over its limit: those of the last sweep's
    corrected points (see the module docstring), or the candidates of the first sweep.
    Each is evaluated as :func:`_direction` does, the points with a spring over its limit
    gather their terms in :func:`_gather`'s order, and the corrections are applied (if
    some spring is over the tolerance): the bits of a dense sweep. ``slots``: int32
    scratch of at least ``5 rows cols`` entries, any content. Returns the points corrected
    (empty when no spring was over the tolerance and nothing was applied).
    """
    n = rows * cols
    spring_slot, point_slot = slots[:4 * n], slots[4 * n:5 * n]
    found = springs.size
    for t in range(found):
        spring_slot[springs[t]] = t
    terms = np.empty((4, found))                # x, y, z term, moves flag
    points = np.empty(min(2 * found, n), dtype=np.int64)
    gathered, count = 0, 0
    for t in range(found):
        j = springs[t] // n
        i = springs[t] - j * n
        k = i + offsets[j]
        # spring_vector's arithmetic (a view per spring costs here), and _row_candidates'
        # squared length
        dx, dy, dz = q[0, k] - q[0, i], q[1, k] - q[1, i], q[2, k] - q[2, i]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        terms[0, t], terms[1, t], terms[2, t], terms[3, t], counts = _spring_term(
            dx, dy, dz, length, True, limit[j], threshold[j], movable[i], movable[k])
        count += counts
        if terms[3, t] > 0.0:       # over its limit with a movable end
            for end in (i, k):
                if movable[end] > 0.0 and not _in_set(point_slot, points, gathered, end):
                    point_slot[end] = gathered
                    points[gathered] = end
                    gathered += 1
    if count == 0:
        return points[:0]
    corr = np.empty((3, gathered))
    for g in range(gathered):
        p = points[g]
        x, y, z, m = 0.0, 0.0, 0.0, 0.0
        for j in range(offsets.shape[0]):   # stencil order: forward, backward, per direction
            for side in range(2):
                first = p - side * offsets[j]
                key = j * n + first     # a first end before point 0 would alias direction j-1
                if first >= 0 and _in_set(spring_slot, springs, found, key):
                    t = spring_slot[key]
                    sign = 1.0 - 2.0 * side
                    x += sign * terms[0, t]
                    y += sign * terms[1, t]
                    z += sign * terms[2, t]
                    m += terms[3, t]
        corr[0, g], corr[1, g], corr[2, g] = x / m, y / m, z / m
    for g in range(gathered):
        p = points[g]
        for d in range(q.shape[0]):
            e = corr[d, g]
            q[d, p] += e
            qd[d, p] += e / h
            dv[d, p] += e / h
    return points[:gathered]


@numba.njit(**JIT)
def _movable_flags(hold_kind, inherited_fixed):
    """
    Return 1.0 for each point strain limiting may move, else 0.0 (flat).

    Movable: free, and not inherited from the coarser level when ``inherited_fixed``.
    """
    rows, cols = hold_kind.shape
    movable = np.empty(rows * cols)
    for r in range(rows):
        kinds = hold_kind[r]
        m = movable[r * cols:(r + 1) * cols]
        even_row = inherited_fixed and r % 2 == 0
        for c in range(cols):      # a form that vectorises
            fixed = (kinds[c] != FREE) | (even_row & (c % 2 == 0))
            m[c] = 0.0 if fixed else 1.0
    return movable


@numba.njit(**JIT)
def _block_masks(block_rows, cols):
    """Per point of a block: has a right neighbour, has a left neighbour, always."""
    masks = np.ones((3, block_rows * cols))
    for r in range(block_rows):
        masks[0, r * cols + cols - 1] = 0.0
        masks[1, r * cols] = 0.0
    return masks


def strain_limit(q, qd, dv, rest, hold_kind, inherited_fixed, max_stretch, max_iterations,
                 tolerance, h, corr):
    """
    Limit the stretch of structural and shear springs to ``max_stretch`` (in place).

    ``q, qd, dv``: the level's positions, velocities and velocity change of the step, all
    corrected; ``rest``: per stencil entry (a spring has one rest length: entries 2 j and
    2 j + 1 must agree); ``inherited_fixed``: on a refinement level, inherited points
    belong to the coarser level and do not move here; ``corr``: scratch of ``q``'s shape.
    Sweeps stop once no spring exceeds its limit by more than ``tolerance`` (relative), or
    after ``max_iterations``. Returns the sweeps applied.
    """
    rows, cols = hold_kind.shape
    limit, threshold = np.empty(4), np.empty(4)
    for j in range(4):
        limit[j] = (1.0 + max_stretch) * rest[2 * j]
        if rest[2 * j + 1] != rest[2 * j]:
            raise ValueError('strain_limit: rest lengths of opposite stencil entries differ')
        if not (0.0 < limit[j] < np.inf and 0.0 <= tolerance < np.inf):
            raise ValueError('strain_limit: limits must be positive, the tolerance >= 0')
        threshold[j] = excess_threshold(limit[j], tolerance)
    n = rows * cols
    qf, qdf, dvf, cf = (q.reshape((3, n)), qd.reshape((3, n)), dv.reshape((3, n)),
                        corr.reshape((3, n)))
    movable = _movable_flags(hold_kind, inherited_fixed)
    chunks = chunk_count(rows, cols) if SPLIT_ROWS else 1
    block_rows = max(1, min(rows, BLOCK_POINTS // cols))
    masks = _block_masks(block_rows, cols)
    terms = np.empty((chunks, TERMS, cols + 1 + block_rows * cols))
    edges = np.zeros((chunks + 1, TERMS, cols))  # forward terms of the row before chunk ch
    counts = np.zeros(chunks, dtype=np.int64)
    moved = np.zeros(chunks, dtype=np.int64)        # points each chunk's sweep corrected
    # rows flagged by the last sweep and by this one, alternating (the first visits all)
    row_flags = np.ones((2, rows), dtype=np.bool_)
    gathered = np.zeros(rows, dtype=np.bool_)      # rows whose corrections a sweep computed
    active = np.empty(n)                            # points a sweep corrected (1.0)
    # the sparse sweeps' sets live in the corrections' scratch: a dense sweep applies its
    # corrections before a sparse one runs, and a sparse set tolerates any content
    slots = cf.reshape(3 * n).view(np.int32)
    close2 = np.empty(4)
    offsets = np.empty(4, dtype=np.int64)   # flat, per direction
    squares = True      # the limits' squares are normal floats: the candidates' bound holds
    for j in range(4):
        close2[j] = (limit[j] * (1.0 - CLOSE)) ** 2
        offsets[j] = (1, cols, cols + 1, cols - 1)[j]
        squares &= 1e-150 < limit[j] < 1e150
    springs, sparse = np.empty(0, dtype=np.int64), False
    if squares and max_iterations > 0:
        springs, sparse = _candidates(qf, rows, cols, offsets, close2, 4 * n // SPARSE_SHARE)
    for sweep in range(max_iterations):
        was_over, now_over = row_flags[sweep % 2], row_flags[(sweep + 1) % 2]
        if sparse:
            points = _sparse_sweep(qf, qdf, dvf, movable, rows, cols, offsets, limit,
                                   threshold, h, springs, slots)
            if points.size == 0:
                return sweep
            springs = _springs_of(points, rows, cols, offsets, slots)
            if springs.size * SPARSE_SHARE > 4 * n:
                sparse = False
                for r in range(rows):   # the first dense sweep visits every row
                    now_over[r] = True
            continue
        at_edges = 0
        for ch in range(1, chunks):
            r = ch * rows // chunks - 1
            at_edges += _forward_terms(qf, movable, masks, r, r + 1, rows, cols, limit,
                                       threshold, edges[ch], r * cols)
        for ch in prange(chunks):
            counts[ch] = _chunk_sweep(qf, qdf, dvf, cf, movable, masks, rows, cols,
                                      ch * rows // chunks, (ch + 1) * rows // chunks,
                                      block_rows, limit, threshold, h, edges[ch],
                                      edges[ch + 1], terms[ch], at_edges > 0, was_over,
                                      now_over, gathered, active, moved[ch:ch + 1])
        total = at_edges
        for ch in range(chunks):
            total += counts[ch]
        if total == 0:
            return sweep    # nothing was corrected: every chunk's rows are pending
        for ch in range(chunks):
            if at_edges == 0 and counts[ch] == 0:   # saw no spring over the tolerance
                _apply_rows(qf, qdf, dvf, cf, gathered, ch * rows // chunks,
                            (ch + 1) * rows // chunks, cols, h)
        if moved.sum() * SPARSE_SHARE <= 4 * n:    # few moved: maybe sparse from here
            springs = _springs_of(_active_points(active, gathered, cols), rows, cols,
                                  offsets, slots)
            sparse = springs.size * SPARSE_SHARE <= 4 * n
    return max_iterations


strain_limit, strain_limit_parallel = serial_and_parallel(
    strain_limit, SPLIT_ROWS=True, _candidates=_candidates_parallel)
