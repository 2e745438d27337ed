"""
Self-contact of one level: its points kept a thickness away from its own triangles.

Triangles: grid cell (r, c) splits along its (r, c)-(r+1, c+1) diagonal (the one
:func:`~hcloth_ros.core.kernels.eq7.prolong` uses for face centres) into triangle ``2 k``
= (r, c), (r, c+1), (r+1, c+1) and ``2 k + 1`` = (r, c), (r+1, c+1), (r+1, c), with
``k = r (cols - 1) + c``. A point is not tested against the triangles with a vertex
within ``RING`` rows and columns of it: the cloth's own surface, held apart by its
springs.

Detection (from the start positions ``x0`` to the end positions ``x1``, each point
moving linearly): the triangles are grouped in patches of ``PATCH`` x ``PATCH`` grid
cells, each with the box its vertices sweep (grown by the thickness) and the cone of its
normals. Patches whose boxes overlap are found by sweep and prune along x; a patch and
its neighbours are skipped when their normals stay within a cone of about 80 degrees (a
surface that cannot fold onto itself; neighbours corner to corner only with the two
patches between them inside the same cone), so on a sheet with nothing near it nothing
else runs. In the pairs of patches left, a point tests the blocks of ``SUB`` x
``SUB`` cells whose swept boxes its path comes near, then their triangles:

* crossing: its distance to the triangle's plane changes sign in one of ``S``
  sub-intervals (``S`` such that no point moves more than half the longest edge relative
  to the level's mean motion in one, at most ``MAX_SUBSTEPS``) and, at the time it is on
  the plane (the root of a cubic), it lies in the triangle or within ``ON_EDGE``
  thicknesses of its border (not past the cloth's free edges: a point past one went
  round it); the pair keeps the side it came from;
* near: at the end it is nearer than the thickness to the triangle's closest point
  (inside, on an edge or at a vertex); the pair keeps the side of the plane it is on.

In the pairs of patches along the grid's border the free edges (on the border) are also
tested against the other patch's edges (rows, columns and the cells' diagonals, outside
the ``RING``): crossed if the four ends become coplanar in a sub-interval while the two
segments pass within the thickness of each other at interior points of both, near if
they end so. A point passing through a triangle is what a surface's passing through
another's inside looks like; at the other's border it can pass with no point doing so (a
corner hooked round another layer's edge, both layers' edges lying over each other): the
edges are what cross there, and such tangles stretched the perturbed folded drops'
springs to 9 times their rest length (``tools/folded_seeds.py``). Away from the border
two layers can pass through each other in the same way only where both are creased: an
edge's ends stay a thickness clear of a layer it passes under only if that layer drops
by a thickness within half an edge of its crease, and they keep that clearance only at
the ends of a step. So the creases (edges between two triangles whose normals part by
more than ``2 asin(2 thickness / longest edge)`` or ``CREASE_ANGLE``, whichever is less:
:func:`_crease_cosine`) are tested against the other patch's edges in every pair of
patches for crossings, as the free edges are, but not kept a thickness away from them (a
cloth folded twice, its second fold across the first, tangled at their crossing without
it; the turns of a rolled-up border, kept apart, stretched its springs).

Response (at the end positions; rounds of detection, each followed by ``RESOLVE_PASSES``
Gauss-Seidel passes over its pairs, until a detection finds none, the last round moving
points alone): the point and the triangle's vertices (weighted by the closest point's
barycentric coordinates and inverse masses; held points do not move unless nothing else
of the pair can, as when a grasp presses a layer into one lying on an obstacle) move apart
until they are ``(1 + SLACK)`` thicknesses apart. A crossed pair moves along the triangle's
normal to the side the point came from; a near one along the normal if the closest point
is inside the triangle, else along the line from the closest point on the border to the
point (so a point sliding over another layer's free edge is not flipped between the two
sides). Velocities lose their approach along that direction (inelastic: a push turned
into velocity made the layers bounce and stretched the cloth); friction takes up to
``friction`` times the push off the point's sliding relative to the triangle over the
step, and that move divided by ``h`` off their velocities. A point above an obstacle
(its ``support``: the obstacle's outward normal and the room left to its margin, see
:func:`~hcloth_ros.core.self_contact.supports`) moves towards it by at most that room,
by a push or by friction; with no room left (``ROOM_TOLERANCE``) its weight is zero for a
push into it and for the velocity it takes, and the other side of the pair moves alone,
no vertex of it leaving faster than the resting side moves. A side pushed up off a
resting side comes to rest on it (no room left for the rest of the call): a stack of
layers on the ground is resolved from the bottom up, as shock propagation resolves stacks
of rigid bodies. An edge pair moves the two edges' closest points apart the same way
(weights ``1 - s, s`` and ``1 - t, t``, along the edges' common normal to the side they
came from, or the line between the closest points), without friction.

Layers lying on each other (:func:`carry`, before a step's detection): a point pushed up
off a triangle (its normal within 45 degrees of up) is noted as lying on it, followed
from step to step across the grid's triangles, and pushed back up off it to ``1 + SLACK``
thicknesses at the end of each step, friction included, as the detection would push
that pair, but without detecting it: a layer at rest on another sank into it every step
under gravity, every point of it a pair, and now lies still. A point noted as lying on a
layer with no room left to its obstacle has none left either (:func:`_rests`, asked
before the pushes of each pair it is in, of the positions at the call's first pushes): a
push from a layer above moves that layer alone, as on the ground, and does not press the
one below into the one under it.

A level restarted from the coarser one (:func:`settle`, once, before its first step) has
no motion to tell which side of a triangle a point came from: a pair found near takes the
side the point's own surface lies on, and is pushed apart as the detection's pairs are.
"""

import collections
import math

from hcloth_ros.core.kernels.jit import BORROW, BORROW_INLINE, JIT
from hcloth_ros.core.kernels.layout import FREE
import numba
import numpy as np


# What self_contact's ``reuse`` says of the patch cache: nothing (every patch's boxes are
# computed: a step's first call); the boxes of this step's last call, from the same start
# (``q_from``), stale only round the points moved since; the same but the paths now
# start where the last call left the level clean. Those boxes still hold every path: a
# patch none of whose points moved since its boxes were swept has its points where they
# ended, at the new start and at the end alike (with a new start, its boxes are cut down
# to where they ended and its motion to none, :func:`_still_sweeps`: the frame a pair's
# boxes are taken in moves by the patches' motion, and a swept box kept with its motion
# held the points' end, not their start). So do its creases' flags, made at a path's start
# and at its end where the patch first lists blocks near another's (a patch not stale kept
# them from an earlier call, its start's from the step's start or a later start it
# had not moved since: an edge creased at either is tested, more tests, none missed); the
# stale patches, and those whose first row's or column's edges border one, take their
# start's flags anew. The longest edge stays the step's start's (strain limiting keeps
# edges near it)
BOXES_NEW, BOXES_KEPT, BOXES_KEPT_NEW_START = 0, 1, 2

# Fewest and most sub-intervals of a step the crossing tests use (two: the distance to a
# turning triangle's plane is far from linear over a whole step).
MIN_SUBSTEPS = 2
MAX_SUBSTEPS = 8
# A point is not tested against triangles with a vertex within this many grid rows and
# columns of it: its own surface, held apart by its springs (two rows and columns of
# springs cannot fold within a thickness below the spacing without stretching 10 %).
RING = 2
# Grid cells a side of the patches detection culls by (64 cells, 128 triangles), and of
# the blocks inside them a point tests (a divisor of PATCH).
PATCH = 8
SUB = 2
# Patches whose triangles' normals all lie within this cosine of their mean normal (about
# 80 degrees) cannot touch themselves or their neighbour patches (see _pair_needed).
FLAT_COSINE = 0.17
FLAT_HALF_ANGLE = math.acos(FLAT_COSINE)
# Edges bent more than this (rad) are creases by default, whatever the thickness (see
# _crease_cosine).
CREASE_ANGLE = math.radians(10.0)
# Pairs are pushed this fraction beyond the thickness (see self_contact).
SLACK = 0.05
# Gauss-Seidel passes over the pairs of one detection.
RESOLVE_PASSES = 4
# Room to an obstacle (m) taken as none: the obstacle's pass leaves a point at its margin
# only within rounding (1.7e-18 m above the ground's on the folded drops), and a point
# with that room took its share of a push's velocity into the ground.
ROOM_TOLERANCE = 1e-9
# A side pushed along its obstacle's normal within this cosine (45 degrees) moves up,
# off what it lies on (see _come_to_rest).
UPWARD = math.sqrt(0.5)
# How far (in thicknesses) a point on a triangle's plane may lie outside it and still
# cross it (see _crossing for the figures behind it).
ON_EDGE = 0.3
# A point lying on a triangle of its own level, tracked from step to step (see carry):
# its projection may walk this many triangles a step, ends within INSIDE (barycentric) of
# the triangle, and lies at most REACH thicknesses above it; farther, it has left it.
WALKS = 3
INSIDE = 0.05
REACH = 2.0
# A projection past the grid's border this far (barycentric) out of the triangle there
# still lies on it (see _track): half a cell, about a thickness at the scenes' spacings.
BEYOND = 0.5
# Pairs a step may hold per point (beyond it the rest of the step's pairs are dropped and
# the count says so).
PAIRS_PER_POINT = 8
# Edge pairs a step may hold per free edge of the grid.
EDGE_PAIRS_PER_EDGE = 32
# The edges _edge_against takes from a cell (r, c): along its first row, down its first
# column, its diagonal, along its last row and down its last column; each as its first
# end's row and its last's (offsets from r), the same for columns (from c), and its
# direction in _edge's numbering from its first end
CELL_EDGES = np.array([(0, 0, 0, 1, 0), (0, 1, 0, 0, 1), (0, 1, 0, 1, 2), (1, 1, 0, 1, 0),
                       (0, 1, 1, 1, 1)], dtype=np.int64)
# Most edges a block lists (:func:`_block_edges`: three a cell, and a block in the grid's
# last row and column its cells' last row and column), and the flags it keeps of each
BLOCK_EDGES = 3 * SUB * SUB + 2 * SUB
EDGE_FRESH, EDGE_FREE, EDGE_CREASE = 1, 2, 4
# A block in a list of blocks: its row shifted by this many bits, or-ed with its column
# (read back without the integer divisions a row-major index takes: one a block listed
# per point and per edge tested)
BLOCK_BITS = 24


@numba.njit(**BORROW)
def _triangle(t, cols):
    """Flat indices of triangle t's three vertices on a grid of ``cols`` columns."""
    k = t // 2
    r, c = k // (cols - 1), k % (cols - 1)
    a = r * cols + c
    if t % 2 == 0:
        return a, a + 1, a + cols + 1
    return a, a + cols + 1, a + cols


@numba.njit(**BORROW)
def _point(x, i):
    """
    Point i of ``x`` (3, n) as a tuple.

    Not the column view ``x[:, i]``: each view passed to a function is an array object to
    build and reference-count (a call on the fold demo's resting layers took 29 ms with
    views, 18 ms with tuples).
    """
    return x[0, i], x[1, i], x[2, i]


@numba.njit(**BORROW)
def _at(x0, x1, i, tau, shift):
    """Point i at time ``tau`` of the step in the frame of the mean displacement."""
    return (x0[0, i] + tau * (x1[0, i] - x0[0, i] - shift[0]),
            x0[1, i] + tau * (x1[1, i] - x0[1, i] - shift[1]),
            x0[2, i] + tau * (x1[2, i] - x0[2, i] - shift[2]))


@numba.njit(**BORROW)
def _plane_distance(p, a, b, c):
    """Return p's signed distance to the plane of (a, b, c) and its unit normal (as _plane)."""
    ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    fx, fy, fz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
    area2 = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not area2 > 0.0:
        return 0.0, 0.0, 0.0, 0.0
    nx, ny, nz = nx / area2, ny / area2, nz / area2
    dx, dy, dz = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    return dx * nx + dy * ny + dz * nz, nx, ny, nz


@numba.njit(**BORROW)
def _plane(p, a, b, c):
    """
    Return p's signed distance to the plane of (a, b, c), its unit normal and weights.

    The weights are the barycentric coordinates of p's projection (0, 0, 0 for a
    degenerate triangle).
    """
    ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    fx, fy, fz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
    area2 = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not area2 > 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    nx, ny, nz = nx / area2, ny / area2, nz / area2
    dx, dy, dz = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    sd = dx * nx + dy * ny + dz * nz
    # barycentrics of the projection: sub-areas along the normal
    px, py, pz = dx - sd * nx, dy - sd * ny, dz - sd * nz
    wb = ((py * fz - pz * fy) * nx + (pz * fx - px * fz) * ny + (px * fy - py * fx) * nz) \
        / area2
    wc = ((ey * pz - ez * py) * nx + (ez * px - ex * pz) * ny + (ex * py - ey * px) * nz) \
        / area2
    return sd, nx, ny, nz, 1.0 - wb - wc, wb, wc


@numba.njit(**BORROW)
def _along(ab, ac, p, v):
    """Return the dot products of ``p - v`` with the edges ``ab`` and ``ac``."""
    dx, dy, dz = p[0] - v[0], p[1] - v[1], p[2] - v[2]
    return ab[0] * dx + ab[1] * dy + ab[2] * dz, ac[0] * dx + ac[1] * dy + ac[2] * dz


@numba.njit(**BORROW)
def _closest(p, a, b, c):
    """
    Barycentric weights of the point of triangle (a, b, c) closest to p.

    By the Voronoi region p projects into (a vertex, an edge or the inside; Ericson,
    Real-Time Collision Detection, 5.1.5). Near the triangle's border the plane's normal
    is the wrong direction to separate along: a point just past a free edge would be
    pushed along the other layer's normal, and flipped in and out of it from step to step.
    """
    ab = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
    ac = (c[0] - a[0], c[1] - a[1], c[2] - a[2])
    d1, d2 = _along(ab, ac, p, a)
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    d3, d4 = _along(ab, ac, p, b)
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        t = d1 / (d1 - d3)
        return 1.0 - t, t, 0.0
    d5, d6 = _along(ab, ac, p, c)
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6)
        return 1.0 - t, 0.0, t
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - t, t
    total = va + vb + vc
    if not total > 0.0:
        return 1.0, 0.0, 0.0        # degenerate: its first vertex
    return va / total, vb / total, vc / total


@numba.njit(**BORROW)
def _offset(x, p, i, j, k, u, v, w):
    """Vector from the point ``u x_i + v x_j + w x_k`` to point p, and its length."""
    ox = x[0, p] - u * x[0, i] - v * x[0, j] - w * x[0, k]
    oy = x[1, p] - u * x[1, i] - v * x[1, j] - w * x[1, k]
    oz = x[2, p] - u * x[2, i] - v * x[2, j] - w * x[2, k]
    return ox, oy, oz, math.sqrt(ox * ox + oy * oy + oz * oz)


@numba.njit(**BORROW)
def _plane_at(x0, x1, p, i, j, k, tau, shift):
    """Return p's signed distance to triangle (i, j, k)'s plane at ``tau``, and its normal."""
    sd, nx, ny, nz = _plane_distance(
        _at(x0, x1, p, tau, shift), _at(x0, x1, i, tau, shift), _at(x0, x1, j, tau, shift),
        _at(x0, x1, k, tau, shift))
    return sd, (nx, ny, nz)


@numba.njit(**BORROW)
def _crossing(x0, x1, p, i, j, k, ta, tb, sda, na, sdb, nb, shift, thickness, rows, cols,
              cubic):
    """
    Twice the side (+-2) p came from if it crossed triangle (i, j, k) between ``ta`` and ``tb``.

    ``sda``, ``na`` and ``sdb``, ``nb``: p's distance to the triangle's plane and its
    normal at ``ta`` and ``tb`` (:func:`_plane_at`; each sub-interval's end is the next
    one's start, computed once); ``cubic``: p's side of the plane as a cubic in time
    (:func:`_side_cubic`'s first four).

    0 if it did not cross. Crossing: its distance to the triangle's plane changes sign (or
    reaches zero at ``tb``: a point on the plane at a sub-interval's boundary was missed by
    both sub-intervals), and at the time it is on the plane (:func:`_root`) it lies inside
    the triangle or within ``ON_EDGE`` thicknesses of its border (a path exactly through
    an edge between two triangles must not slip between them), but not past a free edge
    of the cloth (the border of the grid of ``rows`` by ``cols``): with its closest point
    on one of those, an end included, it went round the cloth's edge, not through.
    (Inside at either end instead flagged triangles that turned over at a free corner, and
    pushed points 2.5 cm the wrong way. The time by linear interpolation of the distances
    at the sub-interval's ends put the point up to a centimetre from the plane of a
    turning triangle, beside it or inside it; a tolerance of a thickness round the
    triangle stood in for that error, and gave crossings with arbitrary sides to points
    falling onto or sliding just over a rumpled layer, through the extended planes of its
    tilted triangles. The perturbed folded drops of ``tools/folded_seeds.py`` at 1 mm,
    seeds 1-80, largest strain over 1: 7 with that; with the plane's own time 2 at a
    tolerance of a thickness (of 40), 1 at 1e-6 and 0.5 thickness, 0 at 0.3. Below 0.5,
    the contact bench's unperturbed 257 x 257 drop, whose layers' free edges lie exactly
    over each other, stretched its corners for a step or two: 0.63 at 1e-6, 0.30 at 0.3,
    against 0.20; doc/self_contact_log.md.)
    """
    if not (sda != 0.0 and sda * sdb <= 0.0):
        return 0.0      # (on the plane at ``tb``: this sub-interval's crossing)
    if not na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2] > 0.0:
        return 0.0      # the triangle turned over: its plane's sign says nothing
    # a point outside the box the triangle sweeps over the sub-interval is outside the
    # triangle (most planes crossed are a neighbour's, beside the point: the root and the
    # closest point are not needed)
    reach = ON_EDGE * thickness
    if _apart(x0, x1, p, i, j, k, ta, tb, shift, reach):
        return 0.0
    tc = _root(cubic, ta, tb, ta + (tb - ta) * sda / (sda - sdb))
    pc, a = _at(x0, x1, p, tc, shift), _at(x0, x1, i, tc, shift)
    b, c = _at(x0, x1, j, tc, shift), _at(x0, x1, k, tc, shift)
    # outside the triangle's box: outside the triangle (the closest point needs 3-4 times
    # the work)
    for d in range(3):
        if pc[d] > max(a[d], b[d], c[d]) + reach or pc[d] < min(a[d], b[d], c[d]) - reach:
            return 0.0
    u, v, w = _closest(pc, a, b, c)
    miss = 0.0
    for d in range(3):
        miss += (pc[d] - u * a[d] - v * b[d] - w * c[d]) ** 2
    if not miss < reach * reach:
        return 0.0
    if miss > 0.0:      # outside: beside a border; on an edge, one weight is 0
        for e0, e1, weight in ((i, j, w), (j, k, u), (i, k, v)):
            if weight == 0.0 and _on_border(e0, e1, rows, cols):
                return 0.0
    return 2.0 if sda > 0.0 else -2.0


@numba.njit(**BORROW)
def _apart(x0, x1, p, i, j, k, ta, tb, shift, reach):
    """Whether p's path and triangle (i, j, k)'s boxes between ``ta`` and ``tb`` stay apart."""
    pa, pb = _at(x0, x1, p, ta, shift), _at(x0, x1, p, tb, shift)
    ia, ib = _at(x0, x1, i, ta, shift), _at(x0, x1, i, tb, shift)
    ja, jb = _at(x0, x1, j, ta, shift), _at(x0, x1, j, tb, shift)
    ka, kb = _at(x0, x1, k, ta, shift), _at(x0, x1, k, tb, shift)
    for d in range(3):
        if min(pa[d], pb[d]) > max(max(ia[d], ib[d]), max(ja[d], jb[d]), max(ka[d], kb[d])) \
                + reach:
            return True
        if max(pa[d], pb[d]) < min(min(ia[d], ib[d]), min(ja[d], jb[d]), min(ka[d], kb[d])) \
                - reach:
            return True
    return False


@numba.njit(**BORROW)
def _root(cubic, ta, tb, guess):
    """
    Return the time in [ta, tb] where ``cubic`` (power coefficients) is zero.

    Newton's method from ``guess``, kept inside the bracket (a bisection where it would
    leave it), to 1e-14 of the step. ``guess`` where the cubic's values at the ends do not
    bracket a zero (their signs rounded the same way where the plane distances' did not).
    """
    c0, c1, c2, c3 = cubic
    fa = c0 + ta * (c1 + ta * (c2 + ta * c3))
    fb = c0 + tb * (c1 + tb * (c2 + tb * c3))
    if fa == 0.0:
        return ta
    if fb == 0.0:
        return tb
    if (fa > 0.0) == (fb > 0.0):
        return guess
    t = min(max(guess, ta), tb)
    for _ in range(100):
        f = c0 + t * (c1 + t * (c2 + t * c3))
        if f == 0.0:
            return t
        if (f > 0.0) == (fa > 0.0):
            ta, fa = t, f
        else:
            tb = t
        slope = c1 + t * (2.0 * c2 + 3.0 * t * c3)
        step = f / slope if slope != 0.0 else 0.0
        if slope != 0.0 and ta < t - step < tb:
            t -= step
            if abs(step) < 1e-14:
                return t
        else:
            t = 0.5 * (ta + tb)
            if not (ta < t < tb):
                return t        # the bracket is down to adjacent doubles
    return t


@numba.njit(**BORROW_INLINE)
def _near(x1, p, i, j, k, thickness):
    """
    Side (+-1) if p ends nearer than ``thickness`` to triangle (i, j, k), else 0.

    The distance is to the triangle's closest point (inside, on an edge or a vertex). The
    side is the one of the plane p is on at the end: a point that crossed the triangle
    during the step is found by :func:`_crossing` (with the side it came from); one that
    did not is on its own side. (The side of the plane at the start misled for points that
    came round the triangle's edge: it pushed them through, 1000 % strain within half a
    second.)
    """
    sd = _plane_distance(_point(x1, p), _point(x1, i), _point(x1, j), _point(x1, k))[0]
    if abs(sd) > thickness * (1.0 + 1e-9):
        return 0.0      # the closest point is no nearer than the plane (rounding aside)
    u, v, w = _closest(_point(x1, p), _point(x1, i), _point(x1, j), _point(x1, k))
    if not _offset(x1, p, i, j, k, u, v, w)[3] < thickness:
        return 0.0
    return 1.0 if sd >= 0.0 else -1.0


@numba.njit(**BORROW)
def _patch_boxes(x0, x1, rows, cols, size, thickness, boxes, ends, cones, stale):
    """
    Swept box (grown by ``thickness``), boxes at both ends and normal cone of the patches.

    Only the patches marked in ``stale`` are computed (the others' points have not moved
    since theirs were).

    Patch (I, J) holds the grid cells ``I size .. (I+1) size - 1`` by
    ``J size .. (J+1) size - 1``. ``boxes[P] = (min xyz, max xyz)`` over its vertices at
    the start and the end of the step; ``ends[P]``: see :func:`_block_boxes`;
    ``cones[P] = (axis xyz, smallest cosine)``: the
    axis is the normal of the patch's corner quadrilateral at the end of the step (its
    diagonals' cross product), the cosine is the smallest between it and the normal of one
    of its cells (their diagonals' cross product) at either time. A cell's normal stands
    for its two triangles' (a cell folded along its diagonal is caught by its
    neighbours').
    """
    pr, pc = boxes.shape[0], boxes.shape[1]
    for bi in range(pr):
        for bj in range(pc):
            if not stale[bi, bj]:
                continue
            r0, r1 = bi * size, min((bi + 1) * size, rows - 1)
            c0, c1 = bj * size, min((bj + 1) * size, cols - 1)
            box, cone = boxes[bi, bj], cones[bi, bj]
            ax, ay, az = _quad_normal(x1, r0 * cols + c0, r0 * cols + c1, r1 * cols + c0,
                                      r1 * cols + c1)
            cone[0], cone[1], cone[2] = ax, ay, az
            low = 1.0 if ax * ax + ay * ay + az * az > 0.0 else -1.0
            _block_boxes(x0, x1, r0, r1, c0, c1, cols, ends, bi, bj, True)
            for d in range(3):
                box[d] = min(ends[bi, bj, d], ends[bi, bj, 6 + d])
                box[3 + d] = max(ends[bi, bj, 3 + d], ends[bi, bj, 9 + d])
            for r in range(r0, r1):
                for x in (x0, x1):
                    for c in range(c0, c1):
                        i = r * cols + c
                        nx, ny, nz = _quad_cross(x, i, i + 1, i + cols, i + cols + 1)
                        if _below(nx, ny, nz, ax, ay, az, low):
                            nx, ny, nz = _unit(nx, ny, nz)
                            low = min(low, nx * ax + ny * ay + nz * az)
            for d in range(3):
                box[d] -= thickness
                box[3 + d] += thickness
            cone[3] = low


@numba.njit(**BORROW)
def _quad_normal(x, a, b, c, d):
    """
    Return the unit normal of the quadrilateral a, b (top), c, d (bottom).

    From its diagonals a-d and b-c (0 if degenerate).
    """
    nx, ny, nz = _quad_cross(x, a, b, c, d)
    return _unit(nx, ny, nz)


@numba.njit(**BORROW_INLINE)
def _quad_cross(x, a, b, c, d):
    """Return the cross product of quadrilateral a, b, c, d's diagonals a-d and b-c."""
    ex, ey, ez = x[0, d] - x[0, a], x[1, d] - x[1, a], x[2, d] - x[2, a]
    fx, fy, fz = x[0, c] - x[0, b], x[1, c] - x[1, b], x[2, c] - x[2, b]
    return ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx


@numba.njit(**BORROW_INLINE)
def _unit(nx, ny, nz):
    """Return ``n`` scaled to unit length (0 if it has none)."""
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    if not norm > 0.0:
        return 0.0, 0.0, 0.0
    return nx / norm, ny / norm, nz / norm


@numba.njit(**BORROW_INLINE)
def _below(nx, ny, nz, ax, ay, az, low):
    """
    Whether the cosine between a cell's normal ``n`` and the unit ``a*`` may be under ``low``.

    False only where it is not, with a margin (``1e-12``) far above the rounding of the
    cosine the unit normal (:func:`_unit`) gives, without its square root and divisions:
    the cosine of the normal ``n`` is ``n . a / |n|``, compared squared. A degenerate
    cell (its normal zero: cosine 0 there) and one whose squares leave the floating-point
    range always may. A patch's cone takes the smallest over its cells, and most cells do
    not lower it (the root and the divisions of each cell's unit normal were a third of a
    step's boxes).
    """
    dot = nx * ax + ny * ay + nz * az
    nn = nx * nx + ny * ny + nz * nz
    if not 1e-280 < nn < 1e280:
        return True
    bound = low + 1e-12
    square = nn * bound * bound
    # dot < bound |n|
    if bound > 0.0:
        return not (dot >= 0.0 and dot * dot >= square)
    return dot < 0.0 and dot * dot > square


@numba.njit(**BORROW)
def _overlap(a, b):
    # one branch: where about one test in five passes (the edge and point tests' boxes),
    # a branch per comparison mispredicted often (see _box_gap)
    return _box_gap(a, b[0], b[1], b[2], b[3], b[4], b[5]) <= 0.0


@numba.njit(**BORROW_INLINE)
def _box_gap(a, b0, b1, b2, b3, b4, b5):
    """
    Return the largest gap between box ``a`` and box ``b*`` (min xyz, max xyz): > 0, apart.

    The largest of the six differences, exact in floating point (``a - b <= 0`` where
    ``a <= b``): ``&`` of the six comparisons was compiled back into a branch each in the
    edge loop (3-4 % of a replayed call).
    """
    return max(max(max(a[0] - b3, b0 - a[3]), max(a[1] - b4, b1 - a[4])),
               max(a[2] - b5, b2 - a[5]))


@numba.njit(**BORROW)
def _pair_needed(cones, angles, ai, aj, bi, bj):
    """
    Return whether patches A and B, whose boxes overlap (:func:`_sweep` tests them), may touch.

    If they are the same patch or neighbours, their normals
    spread over more than ``FLAT_COSINE`` allows (a surface whose normals all lie within a
    cone narrower than a hemisphere around one axis cannot fold onto itself; the rest of
    that criterion, a contour that crosses itself, needs shears a cloth does not take).
    Neighbours side by side: the narrowest cone holding both patches' cones. Corner to
    corner: the four patches round their common corner in one cone (:func:`_block_flat`).
    ``angles``: see :func:`_cone_angles`.
    """
    if abs(ai - bi) > 1 or abs(aj - bj) > 1:
        return True
    if ai == bi and aj == bj:
        return cones[ai, aj, 3] < FLAT_COSINE
    if ai == bi or aj == bj:
        return _merged(_between(angles, ai, aj, bi, bj), angles[ai, aj, 0],
                       angles[bi, bj, 0])[0] > FLAT_HALF_ANGLE
    # corner to corner the two meet at one point, and each can be flat and lie over the
    # other through pleats in the two patches between them (a cloth folded twice, its
    # layers crushed, had a point 1 mm from a triangle of a patch culled so); with a
    # third patch between them in the same cone, a cube's corner (the fourth patch
    # folded shut, the two's edges along its fold) still is
    return angles[min(ai, bi), min(aj, bj), 3] == 0.0


@numba.njit(**BORROW)
def _merged(t, a, b):
    """
    Return the narrowest cone holding two cones, of half-angles a and b, axes t apart.

    As ``(half-angle, its axis' angle from the first's axis)``, the axis on the arc
    between the two: the wider of the two if it holds the other, else the cone whose
    edges touch both.
    """
    if t + b <= a:
        return a, 0.0
    if t + a <= b:
        return b, t
    m = 0.5 * (t + a + b)
    return m, m - a


@numba.njit(**BORROW)
def _block_flat(angles, i, j):
    """
    Whether patches (i, j), (i, j + 1), (i + 1, j + 1), (i + 1, j) fit in one flat cone.

    A cone of half-angle ``FLAT_HALF_ANGLE``: two of them side by side merged (the angle
    between their axes is known), each of the other two within it by the triangle
    inequality through its neighbour among those two (the merged axis lies on the arc
    between theirs). The four ways round are tried.
    """
    half = FLAT_HALF_ANGLE
    ri = (i, i, i + 1, i + 1)
    rj = (j, j + 1, j + 1, j)
    for m in range(4):
        x, y, u, w = m, (m + 1) % 4, (m + 2) % 4, (m + 3) % 4
        t = _between(angles, ri[x], rj[x], ri[y], rj[y])
        cone, off = _merged(t, angles[ri[x], rj[x], 0], angles[ri[y], rj[y], 0])
        if cone <= half and \
                _between(angles, ri[y], rj[y], ri[u], rj[u]) + t - off \
                + angles[ri[u], rj[u], 0] <= half and \
                _between(angles, ri[x], rj[x], ri[w], rj[w]) + off \
                + angles[ri[w], rj[w], 0] <= half:
            return True
    return False


@numba.njit(**BORROW)
def _between(angles, ai, aj, bi, bj):
    """Return the angle between the cone axes of patches A and B, next to each other."""
    if ai == bi:
        return angles[ai, min(aj, bj), 1]
    return angles[min(ai, bi), aj, 2]


@numba.njit(**JIT)
def _cone_angles(cones):
    """
    Return each patch's cone's half-angle and its axis' angles to its neighbours'.

    ``out[I, J] = (acos of the smallest cosine, angle to patch (I, J + 1)'s axis, angle
    to patch (I + 1, J)'s axis, 1 if the four patches from (I, J) to (I + 1, J + 1) fit
    in one flat cone, else 0)`` (0 past the grid's last patch; :func:`_block_flat` once
    a corner, not once for each of its two pairs of patches corner to corner).
    """
    pr, pc = cones.shape[0], cones.shape[1]
    out = np.zeros((pr, pc, 4))
    for a in range(pr):
        for b in range(pc):
            out[a, b, 0] = math.acos(cones[a, b, 3])
            for m, (a2, b2) in enumerate(((a, b + 1), (a + 1, b))):
                if a2 < pr and b2 < pc:
                    between = cones[a, b, 0] * cones[a2, b2, 0] \
                        + cones[a, b, 1] * cones[a2, b2, 1] + cones[a, b, 2] * cones[a2, b2, 2]
                    out[a, b, 1 + m] = math.acos(min(1.0, max(-1.0, between)))
    for a in range(pr - 1):
        for b in range(pc - 1):
            out[a, b, 3] = 1.0 if _block_flat(out, a, b) else 0.0
    return out


@numba.njit(**BORROW_INLINE)
def _block_boxes(x0, x1, r0, r1, c0, c1, cols, table, ti, tj, motion):
    """
    Write the boxes of a block of grid points at both ends of the step and its motion.

    Rows ``r0 .. r1`` by columns ``c0 .. c1`` (inclusive):
    ``table[ti, tj] = (min, max at x0, min, max at x1, mean displacement)``, the last
    three only if ``motion`` (a patch's, read for a pair's frame; not a block's). The table
    and the indices, not the row: a row passed is a view built for each block.
    """
    # a coordinate at a time in local variables (kept in the row through the loop, the
    # blocks' boxes of a whole 129 x 129 level took 0.25 ms, now 0.14-0.16 without the motion)
    for d in range(3):
        low0, high0, low1, high1, move = np.inf, -np.inf, np.inf, -np.inf, 0.0
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                i = r * cols + c
                low0, high0 = min(low0, x0[d, i]), max(high0, x0[d, i])
                low1, high1 = min(low1, x1[d, i]), max(high1, x1[d, i])
                if motion:
                    move += x1[d, i] - x0[d, i]
        table[ti, tj, d], table[ti, tj, 3 + d] = low0, high0
        table[ti, tj, 6 + d], table[ti, tj, 9 + d] = low1, high1
        if motion:
            table[ti, tj, 12 + d] = move / ((r1 - r0 + 1) * (c1 - c0 + 1))


@numba.njit(**BORROW)
def _moving_box(ends, shift, reach, out):
    """
    Write the box a block sweeps in a frame moving by ``shift``, grown by ``reach``.

    Paths in such a frame are the same up to one translation, so every test between two
    blocks may use one: the pair's mean motion, which leaves boxes as small as the
    blocks' motion relative to each other (a swinging cloth moves a point many grid
    spacings a step; its neighbours move with it).
    """
    for d in range(3):
        out[d] = min(ends[d], ends[6 + d] - shift[d]) - reach
        out[3 + d] = max(ends[3 + d], ends[9 + d] - shift[d]) + reach


@numba.njit(**BORROW)
def _patch_block_boxes(subs, bi, bj, shift, out):
    """Write the boxes of patch (bi, bj)'s blocks in the frame moving by ``shift``, row-major."""
    per = PATCH // SUB
    m = 0
    for si in range(bi * per, min((bi + 1) * per, subs.shape[0])):
        for sj in range(bj * per, min((bj + 1) * per, subs.shape[1])):
            _moving_box(subs[si, sj], shift, 0.0, out[m])
            m += 1


@numba.njit(**BORROW)
def _sub_boxes(x0, x1, rows, cols, bi, bj, subs):
    """
    Boxes of patch (bi, bj)'s blocks of ``SUB`` x ``SUB`` cells at both ends of the step.

    A point tests only the triangles of the blocks its path comes near: 16 boxes and a
    few blocks' triangles where the whole patch's 128 triangles cost 4x more on a cloth
    lying on itself. ``subs[si, sj] = (min, max at x0, min, max at x1)``
    (:func:`_block_boxes` without the motion: a pair's frame moves with its two patches'
    motion, :func:`_detect`, not with a block's).
    """
    per = PATCH // SUB
    for si in range(bi * per, min((bi + 1) * per, subs.shape[0])):
        for sj in range(bj * per, min((bj + 1) * per, subs.shape[1])):
            _block_boxes(x0, x1, si * SUB, min((si + 1) * SUB, rows - 1), sj * SUB,
                         min((sj + 1) * SUB, cols - 1), cols, subs, si, sj, False)


@numba.njit(**BORROW)
def _path_box(x0, x1, p, shift, reach, out):
    """Write the box p's path sweeps in a frame moving by ``shift``, grown by ``reach``."""
    for d in range(3):
        out[d] = min(x0[d, p], x1[d, p] - shift[d]) - reach
        out[3 + d] = max(x0[d, p], x1[d, p] - shift[d]) + reach


@numba.njit(**BORROW_INLINE)
def _pair_side(x0, x1, p, i, j, k, thickness, substeps, shift, rows, cols):
    """
    Whether p and triangle (i, j, k) make a pair: its side if it crossed (+-2) or ends near (+-1).

    Every sub-interval is tested, also when p ends on the side it started on: skipping
    those (a point that went through and back) doubled the folded 129 x 129 drop's
    largest strain, since the tangle they leave behind is resolved later and worse.
    """
    c0, c1, c2, c3, margin = _side_cubic(x0, x1, p, i, j, k)
    if not _may_change(c0, c1, c2, c3, margin):
        return _near(x1, p, i, j, k, thickness)
    # a sub-interval whose ends the cubic puts clearly on one side keeps p's side of the
    # plane at both (the planes' signs are the cubic's): it is not tested, and the
    # planes are computed only at the ends of those that are (each a third of the work)
    ca, have = c0, False
    for sub in range(substeps):
        ta, tb = sub / substeps, (sub + 1) / substeps
        cb = c0 + tb * (c1 + tb * (c2 + tb * c3))
        if (ca > margin and cb > margin) or (ca < -margin and cb < -margin):
            ca, have = cb, False
            continue
        if not have:
            sda, na = _plane_at(x0, x1, p, i, j, k, ta, shift)
        sdb, nb = _plane_at(x0, x1, p, i, j, k, tb, shift)
        side = _crossing(x0, x1, p, i, j, k, ta, tb, sda, na, sdb, nb, shift, thickness,
                         rows, cols, (c0, c1, c2, c3))
        if side != 0.0:
            return side
        sda, na, ca, have = sdb, nb, cb, True
    return _near(x1, p, i, j, k, thickness)


@numba.njit(**BORROW)
def _norm1(x, y, z):
    """Return ``|x| + |y| + |z|``."""
    return abs(x) + abs(y) + abs(z)


@numba.njit(**BORROW)
def _triple(ux, uy, uz, vx, vy, vz, wx, wy, wz):
    """Return ``(u x v) . w``."""
    return (uy * vz - uz * vy) * wx + (uz * vx - ux * vz) * wy + (ux * vy - uy * vx) * wz


@numba.njit(**BORROW)
def _may_cross(x0, x1, p, i, j, k):
    """
    Whether p's side of triangle (i, j, k)'s plane may change during the step.

    False: it cannot (see :func:`_side_cubic` and :func:`_may_change`).
    """
    return _may_change(*_side_cubic(x0, x1, p, i, j, k))


@numba.njit(**BORROW)
def _may_change(c0, c1, c2, c3, margin):
    """
    Whether the cubic ``c0 + c1 t + c2 t^2 + c3 t^3`` may change sign on [0, 1].

    When the four coefficients of its Bernstein form share one sign, clear of ``margin``,
    it keeps that sign: for a point's side cubic (:func:`_side_cubic`) no sub-interval's
    test can find it crossing, and they are skipped (on layers resting on each other, most
    pairs a point tests).
    """
    b1 = c0 + c1 / 3.0
    b2 = c0 + (2.0 * c1 + c2) / 3.0
    b3 = c0 + c1 + c2 + c3
    low = min(min(c0, b1), min(b2, b3))
    high = max(max(c0, b1), max(b2, b3))
    return not (low > margin or high < -margin)


@numba.njit(**BORROW_INLINE)
def _side_cubic(x0, x1, p, i, j, k):
    """
    Return p's side of triangle (i, j, k)'s plane as a cubic in time, and its rounding.

    Each point moves linearly, so the triple product ``((b - a) x (c - a)) . (p - a)``, the
    plane's signed distance times twice the triangle's area, is a cubic in the step's time
    t in [0, 1]: ``(c0, c1, c2, c3)`` its power coefficients, and ``margin`` a bound on
    the rounding of its value, within which its sign says nothing. The frame's shift
    cancels in the differences.
    """
    ex, ey, ez = x0[0, j] - x0[0, i], x0[1, j] - x0[1, i], x0[2, j] - x0[2, i]
    fx, fy, fz = x0[0, k] - x0[0, i], x0[1, k] - x0[1, i], x0[2, k] - x0[2, i]
    gx, gy, gz = x0[0, p] - x0[0, i], x0[1, p] - x0[1, i], x0[2, p] - x0[2, i]
    # the changes of those three differences over the step
    dix, diy, diz = x1[0, i] - x0[0, i], x1[1, i] - x0[1, i], x1[2, i] - x0[2, i]
    dex, dey, dez = x1[0, j] - x0[0, j] - dix, x1[1, j] - x0[1, j] - diy, \
        x1[2, j] - x0[2, j] - diz
    dfx, dfy, dfz = x1[0, k] - x0[0, k] - dix, x1[1, k] - x0[1, k] - diy, \
        x1[2, k] - x0[2, k] - diz
    dgx, dgy, dgz = x1[0, p] - x0[0, p] - dix, x1[1, p] - x0[1, p] - diy, \
        x1[2, p] - x0[2, p] - diz
    c0 = _triple(ex, ey, ez, fx, fy, fz, gx, gy, gz)
    c1 = (_triple(dex, dey, dez, fx, fy, fz, gx, gy, gz)
          + _triple(ex, ey, ez, dfx, dfy, dfz, gx, gy, gz)
          + _triple(ex, ey, ez, fx, fy, fz, dgx, dgy, dgz))
    c2 = (_triple(dex, dey, dez, dfx, dfy, dfz, gx, gy, gz)
          + _triple(dex, dey, dez, fx, fy, fz, dgx, dgy, dgz)
          + _triple(ex, ey, ez, dfx, dfy, dfz, dgx, dgy, dgz))
    c3 = _triple(dex, dey, dez, dfx, dfy, dfz, dgx, dgy, dgz)
    # rounding: a margin of 1e-9 of the products' size (1-norms, which bound the lengths)
    margin = 1e-9 * (_norm1(ex, ey, ez) + _norm1(dex, dey, dez)) \
        * (_norm1(fx, fy, fz) + _norm1(dfx, dfy, dfz)) \
        * (_norm1(gx, gy, gz) + _norm1(dgx, dgy, dgz))
    return c0, c1, c2, c3, margin


@numba.njit(**BORROW)
def _near_blocks(subs, ends, shift, thickness, ai, aj, bi, bj, fresh_blocks, b_boxes, near,
                 counts, work, kept, kept_boxes, kept_fresh, kept_gaps):
    """
    List, for each block of patch A, the blocks of patch B it may come near; return how many.

    In the frame moving by ``shift``: ``near[a, :counts[a]]`` are the B blocks (as
    ``si << BLOCK_BITS | sj``, :func:`_unpacked`, in row-major order) whose box meets the box
    of A's block ``a`` (``a = (ui - ai per) per + uj - aj per``, ``per`` blocks a patch side, also
    on border patches with fewer) grown by ``thickness``. A point's path lies in its block's
    box, so a point tests only its block's list instead of every B block (760,000 box tests
    a detection on the fold demo's resting layers, 2 % of them met), and so does an edge of
    the block (:func:`_edge_against`). ``b_boxes`` holds B's boxes. An A block with no
    vertex marked in ``fresh_blocks`` lists only the B blocks with one (its points need no
    test against the others). ``work`` (at least (2, 6)), ``kept``, ``kept_fresh`` and
    ``kept_gaps`` (``per * per``) and ``kept_boxes`` (6, ``per * per``) are scratch space.

    Only the blocks that meet the other patch's box (``ends``, :func:`_patch_boxes`) are
    tested against each other: a block's box lies in its patch's, so the others meet no
    block of it, and the lists are the same. Two patches of layers lying on each other
    overlap in part, and testing every block of one against every block of the other
    was 1.9 of the 4.1 ms of a detection of the folded drop at rest (129 x 129, 882
    pairs of patches, 450,000 box tests).
    """
    per = PATCH // SUB
    s0, s1 = bi * per, min((bi + 1) * per, subs.shape[0])
    t0, t1 = bj * per, min((bj + 1) * per, subs.shape[1])
    _patch_block_boxes(subs, bi, bj, shift, b_boxes)
    box, patch = work[0], work[1]
    # B's blocks that A's patch, grown by the thickness, meets (row-major, as in ``near``)
    _moving_box(ends[ai, aj], shift, thickness, patch)
    # (their bounds a row each, for the loop below)
    count = m = 0
    for si in range(s0, s1):
        for sj in range(t0, t1):
            if _overlap(patch, b_boxes[m]):
                kept[count] = si << BLOCK_BITS | sj
                for d in range(6):
                    kept_boxes[d, count] = b_boxes[m, d]
                kept_fresh[count] = fresh_blocks[si, sj]
                count += 1
            m += 1
    _moving_box(ends[bi, bj], shift, 0.0, patch)
    listed = 0
    for ui in range(ai * per, min((ai + 1) * per, subs.shape[0])):
        for uj in range(aj * per, min((aj + 1) * per, subs.shape[1])):
            a = (ui - ai * per) * per + uj - aj * per
            counts[a] = 0
            _moving_box(subs[ui, uj], shift, thickness, box)
            if not _overlap(box, patch):
                continue
            # the gaps to the kept blocks in a loop that vectorises, then those that meet
            # listed without a branch (as the edge loop's, _edge_against): a test and a
            # branch each were 14 % of a replayed call of the fold demo's resting layers
            for e in range(count):
                kept_gaps[e] = _box_gap(box, kept_boxes[0, e], kept_boxes[1, e],
                                        kept_boxes[2, e], kept_boxes[3, e], kept_boxes[4, e],
                                        kept_boxes[5, e])
            own = fresh_blocks[ui, uj]
            met = 0
            for e in range(count):
                near[a, met] = kept[e]
                met += (kept_gaps[e] <= 0.0) & (own | kept_fresh[e])
            counts[a] = met
            listed += met
    return listed


@numba.njit(**BORROW)
def _points_against(x0, x1, rows, cols, thickness, substeps, subs, shift, ai, aj, bi, bj,
                    fresh, fresh_blocks, pairs, sides, count, b_boxes, near, counts,
                    tri_boxes, tri_ready, work):
    """
    Test patch A's points against patch B's triangles; returns the new pair count.

    Boxes are taken in the frame moving by ``shift`` (see :func:`_moving_box`); each
    point tests the B blocks of its own block's list (``b_boxes``, ``near`` and
    ``counts``, as :func:`_near_blocks` filled them for this pair), in the order of the
    blocks. Only pairs with a point marked in ``fresh`` are tested (``fresh_blocks``: the
    blocks with a vertex marked): the others have not moved since a detection found them
    apart. ``work`` (3, 6) is scratch space.
    """
    path = work[2]
    tri_ready[:] = False
    r0, r1 = ai * PATCH, min((ai + 1) * PATCH, rows - 1)
    c0, c1 = aj * PATCH, min((aj + 1) * PATCH, cols - 1)
    # the points a patch owns: its cells' top-left corners, and the grid's last row and
    # column for the patches along them
    r_end = r1 + 1 if r1 == rows - 1 else r1
    c_end = c1 + 1 if c1 == cols - 1 else c1
    per = PATCH // SUB
    width = subs.shape[1]
    b_width = min((bj + 1) * per, width) - bj * per
    for r in range(r0, r_end):
        for c in range(c0, c_end):
            a = _block_of(r, c, ai, aj, rows, cols)
            if counts[a] == 0:
                continue
            p = r * cols + c
            moved = fresh[p]
            _path_box(x0, x1, p, shift, thickness, path)
            for e in range(counts[a]):
                si, sj = _unpacked(near[a, e])
                if not (moved or fresh_blocks[si, sj]):
                    continue
                # a block wholly within p's ring has no triangle to test: the cloth's own
                # surface, listed wherever a patch curves (the fold demo's crease and
                # rolled border), whose cells were each skipped below
                if _in_ring(si, sj, r - 1 - RING, r + RING, c - 1 - RING, c + RING, rows,
                            cols):
                    continue
                # B's boxes in _near_blocks' order
                m = (si - bi * per) * b_width + sj - bj * per
                if not _overlap(path, b_boxes[m]):
                    continue
                if not tri_ready[m]:
                    _triangle_boxes(x0, x1, rows, cols, si, sj, shift, tri_boxes[m])
                    tri_ready[m] = True
                boxes_m = tri_boxes[m]
                for u in range(si * SUB, min((si + 1) * SUB, rows - 1)):
                    # the cells with a vertex within RING rows and columns of p are
                    # skipped (from row and column: per triangle, its row and column
                    # from its index took two integer divisions)
                    if u - RING <= r <= u + 1 + RING:
                        v_skip0, v_skip1 = c - 1 - RING, c + RING
                    else:
                        v_skip0, v_skip1 = cols, -1
                    for v in range(sj * SUB, min((sj + 1) * SUB, cols - 1)):
                        if v_skip0 <= v <= v_skip1:
                            continue
                        i = u * cols + v
                        cell = 2 * ((u - si * SUB) * SUB + v - sj * SUB)
                        for half in range(2):
                            j, k = (i + 1, i + cols + 1) if half == 0 else \
                                (i + cols + 1, i + cols)
                            if not (moved or fresh[i] or fresh[j] or fresh[k]):
                                continue
                            if not _overlap(path, boxes_m[cell + half]):
                                continue
                            side = _pair_side(x0, x1, p, i, j, k, thickness, substeps,
                                              shift, rows, cols)
                            if side != 0.0:
                                if count < pairs.shape[0]:
                                    pairs[count, 0] = p
                                    pairs[count, 1] = 2 * (u * (cols - 1) + v) + half
                                    sides[count] = side
                                count += 1
    return count


@numba.njit(**BORROW)
def _edge(e, cols):
    """Flat indices of edge e's ends: ``e = 3 v + d``, d 0 along a row, 1 down, 2 diagonal."""
    v, d = e // 3, e % 3
    return v, v + (1, cols, cols + 1)[d]


@numba.njit(**BORROW)
def _on_border(a, b, rows, cols):
    """Whether the edge between grid points a and b lies on the grid's border."""
    return _border_rows(a // cols, b // cols, a % cols, b % cols, rows, cols)


@numba.njit(**BORROW)
def _border_rows(ra, rb, ca, cb, rows, cols):
    """Whether the edge between grid points (ra, ca) and (rb, cb) lies on the grid's border."""
    return (ra == rb and (ra == 0 or ra == rows - 1)) or \
        (ca == cb and (ca == 0 or ca == cols - 1))


@numba.njit(**BORROW)
def _segments(a, b, c, d):
    """
    Closest points of the lines through segments a-b and c-d: ``(s, t, ok)``.

    ``a + s (b - a)`` and ``c + t (d - c)``; ``ok`` False for (nearly) parallel lines,
    whose nearest points a vertex-triangle test finds.
    """
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    vx, vy, vz = d[0] - c[0], d[1] - c[1], d[2] - c[2]
    wx, wy, wz = a[0] - c[0], a[1] - c[1], a[2] - c[2]
    uu, uv, vv = ux * ux + uy * uy + uz * uz, ux * vx + uy * vy + uz * vz, \
        vx * vx + vy * vy + vz * vz
    uw, vw = ux * wx + uy * wy + uz * wz, vx * wx + vy * wy + vz * wz
    denom = uu * vv - uv * uv
    if not denom > 1e-12 * uu * vv:
        return 0.0, 0.0, False
    return (uv * vw - vv * uw) / denom, (uu * vw - uv * uw) / denom, True


@numba.njit(**BORROW)
def _gap(a, b, c, d, s, t):
    """Vector from ``c + t (d - c)`` to ``a + s (b - a)``, and its length."""
    gx = a[0] + s * (b[0] - a[0]) - c[0] - t * (d[0] - c[0])
    gy = a[1] + s * (b[1] - a[1]) - c[1] - t * (d[1] - c[1])
    gz = a[2] + s * (b[2] - a[2]) - c[2] - t * (d[2] - c[2])
    return gx, gy, gz, math.sqrt(gx * gx + gy * gy + gz * gz)


@numba.njit(**BORROW)
def _orient(a, b, c, d):
    """``((b - a) x (c - a)) . (d - a)``: its sign is edge a-b's side of edge c-d."""
    return _triple(b[0] - a[0], b[1] - a[1], b[2] - a[2], c[0] - a[0], c[1] - a[1],
                   c[2] - a[2], d[0] - a[0], d[1] - a[1], d[2] - a[2])


@numba.njit(**BORROW)
def _edges_meet(a, b, c, d, thickness):
    """Whether segments a-b and c-d pass within ``thickness`` at interior points of both."""
    s, t, ok = _segments(a, b, c, d)
    if not (ok and 0.0 < s < 1.0 and 0.0 < t < 1.0):
        return False
    return _gap(a, b, c, d, s, t)[3] < thickness


# inlined, as _pair_side, _side_cubic and _near are: called once for each pair tested, a
# sixth of its own time went to reading back the arrays its caller had just written to
# the stack for the call (2.5 % of a replayed call; 1 s more to compile)
@numba.njit(**BORROW_INLINE)
def _edge_side(x0, x1, a, b, c, d, thickness, substeps, shift, near=True):
    """
    Whether edges a-b and c-d make a pair: a-b's side if it crossed c-d (+-2) or ends near (+-1).

    ``near`` False: crossings only (0 for a pair that ends near).

    Crossing: the four points become coplanar (the side cubic of :func:`_side_cubic`
    changes sign in a sub-interval) while the two segments pass within ``thickness`` of
    each other at interior points; the side is the one before. Near: at the end they are
    nearer than ``thickness`` at interior points of both; the side is the present one.
    The side is the sign of :func:`_orient`, that of a-b's offset from c-d along
    ``(b - a) x (d - c)``.
    """
    c0, c1, c2, c3, margin = _side_cubic(x0, x1, d, a, b, c)
    if _may_change(c0, c1, c2, c3, margin):
        ca = c0
        for sub in range(substeps):
            ta, tb = sub / substeps, (sub + 1) / substeps
            cb = c0 + tb * (c1 + tb * (c2 + tb * c3))
            if (ca > margin and cb > margin) or (ca < -margin and cb < -margin):
                ca = cb
                continue
            ca = cb
            oa = _orient(_at(x0, x1, a, ta, shift), _at(x0, x1, b, ta, shift),
                         _at(x0, x1, c, ta, shift), _at(x0, x1, d, ta, shift))
            ob = _orient(_at(x0, x1, a, tb, shift), _at(x0, x1, b, tb, shift),
                         _at(x0, x1, c, tb, shift), _at(x0, x1, d, tb, shift))
            if not (oa != 0.0 and oa * ob <= 0.0):
                continue    # (coplanar at ``tb``: this sub-interval's crossing)
            tc = ta + (tb - ta) * oa / (oa - ob)
            if _edges_meet(_at(x0, x1, a, tc, shift), _at(x0, x1, b, tc, shift),
                           _at(x0, x1, c, tc, shift), _at(x0, x1, d, tc, shift), thickness):
                return 2.0 if oa > 0.0 else -2.0
    if not near:
        return 0.0
    pa, pb, pc, pd = _point(x1, a), _point(x1, b), _point(x1, c), _point(x1, d)
    if not _edges_meet(pa, pb, pc, pd, thickness):
        return 0.0
    return 1.0 if _orient(pa, pb, pc, pd) >= 0.0 else -1.0


@numba.njit(**BORROW)
def _segment_box(x0, x1, a, b, shift, reach, out):
    """Write the box edge a-b sweeps in a frame moving by ``shift``, grown by ``reach``."""
    for d in range(3):
        out[d] = min(x0[d, a], x0[d, b], x1[d, a] - shift[d], x1[d, b] - shift[d]) - reach
        out[3 + d] = max(x0[d, a], x0[d, b], x1[d, a] - shift[d], x1[d, b] - shift[d]) \
            + reach


@numba.njit(**BORROW)
def _block_edges(x0, x1, rows, cols, si, sj, shift, fresh, crease, boxes, ends):
    """
    List block (si, sj)'s edges for :func:`_edge_against`; return how many.

    Each cell's edge along its first row, down its first column and its diagonal, and
    along the grid's last row and column those of its cells there, cell by cell in
    row-major order (d as ``CELL_EDGES``). ``boxes[:, q]``: the box edge q sweeps in the
    frame moving by ``shift`` (a bound a row: the edge loop reads one bound of all the
    block's edges at a time); ``ends[q]``: its index (:func:`_edge`), its two ends, their
    rows (first, last) and columns, and flags: ``EDGE_FRESH`` (an end marked in
    ``fresh``), ``EDGE_FREE`` (on the grid's border), ``EDGE_CREASE`` (flagged in
    ``crease``). Made once a way round of a pair of patches, where a block is first
    tested: every edge tested against the block reads them instead of working out each
    of its edges again.
    """
    q = 0
    for u in range(si * SUB, min((si + 1) * SUB, rows - 1)):
        for v in range(sj * SUB, min((sj + 1) * SUB, cols - 1)):
            for d in range(5):
                if d == 3 and u != rows - 2 or d == 4 and v != cols - 2:
                    continue
                # the cell's last row or column edge: the grid's border. Its ends' rows
                # and columns from the cell's
                r_lo, r_hi = u + CELL_EDGES[d, 0], u + CELL_EDGES[d, 1]
                c_lo, c_hi = v + CELL_EDGES[d, 2], v + CELL_EDGES[d, 3]
                c, dd = r_lo * cols + c_lo, r_hi * cols + c_hi
                f = 3 * c + CELL_EDGES[d, 4]
                flags = EDGE_FRESH if fresh[c] or fresh[dd] else 0
                if _border_rows(r_lo, r_hi, c_lo, c_hi, rows, cols):
                    flags |= EDGE_FREE
                if crease[f]:
                    flags |= EDGE_CREASE
                out = ends[q]
                out[0], out[1], out[2] = f, c, dd
                out[3], out[4], out[5], out[6] = r_lo, r_hi, c_lo, c_hi
                out[7] = flags
                _segment_box(x0, x1, c, dd, shift, 0.0, boxes[:, q])
                q += 1
    return q


@numba.njit(**BORROW)
def _edge_against(x0, x1, rows, cols, thickness, substeps, subs, shift, e, r, c, bi, bj,
                  fresh, fresh_blocks, pairs, sides, count, boxes, b_boxes, crease, near,
                  near_count, seg_boxes, seg_ends, seg_count, gaps, chosen):
    """
    Test edge e, free or a crease, against the edges of patch B; returns the new pair count.

    (r, c): e's first end's row and column (not worked out from the index: integer
    divisions, here and per listed block, took 3 % of a replayed call).
    B's edges: those :func:`_block_edges` lists. Edges with an end within ``RING`` rows
    and columns of one of e's are skipped (the cloth's own surface), and each pair is
    tested once: of two free edges, from the lower index; a free edge and another, from
    the free edge; of two creases (``crease``: the flags of :func:`_patch_creases`, e one
    of them unless it is free), from the lower index. Only pairs with an end marked in
    ``fresh`` are tested (``fresh_blocks``: the blocks with one, see
    :func:`_fresh_blocks`). ``boxes``: room for a box (6 numbers); ``b_boxes``: the boxes
    B's blocks sweep in the frame moving by ``shift``, in row-major order
    (:func:`_moving_box`). ``near[:near_count]``: the B blocks e may come near, those of
    its block's list (:func:`_near_blocks`; the block holds both of e's ends, so its box
    holds e's path): looping over all of B's blocks instead was 87,000 box tests a
    detection, 2 % of them met, on the folded drop's landing at 129 x 129.
    ``seg_boxes[m]``, ``seg_ends[m]`` and ``seg_count[m]``: B's listed block m's edges
    (:func:`_block_edges`), made at its first test in this way round of the pair
    (``seg_count`` -1 until then). The boxes are tested first: of the edges the other
    tests let through, they rule out two in three (the folded drop's layers sliding over
    each other, 22,000 edges a call). ``gaps`` and ``chosen`` (``BLOCK_EDGES`` each): room
    for a block's edges' gaps to e's box and the indices of those that meet it.
    """
    a, b = _edge(e, cols)
    # its last end's row and column: CELL_EDGES' offsets for its direction (0..2)
    ra0, ra1 = r, r + CELL_EDGES[e % 3, 1]
    ca0, ca1 = c, c + CELL_EDGES[e % 3, 3]
    free = _border_rows(ra0, ra1, ca0, ca1, rows, cols)
    moved = fresh[a] or fresh[b]
    box = boxes[0]
    _segment_box(x0, x1, a, b, shift, thickness, box)
    per = PATCH // SUB
    width = subs.shape[1]
    b_width = min((bj + 1) * per, width) - bj * per
    for listed in range(near_count):
        si, sj = _unpacked(near[listed])
        if not (moved or fresh_blocks[si, sj]):
            continue
        # a block all of whose edges the ring test below skips (they run one row and
        # column past its cells): four in five edges chosen on the fold demo's resting
        # layers were, each after its box's test
        if _in_ring(si, sj, ra0 - RING, ra1 + RING - 1, ca0 - RING, ca1 + RING - 1, rows,
                    cols):
            continue
        m = (si - bi * per) * b_width + sj - bj * per
        if not _overlap(box, b_boxes[m]):
            continue
        if seg_count[m] < 0:
            seg_count[m] = _block_edges(x0, x1, rows, cols, si, sj, shift, fresh, crease,
                                        seg_boxes[m], seg_ends[m])
        # the boxes' gaps to e's for all the block's edges (a loop that vectorises), the
        # edges whose boxes meet e's listed without a branch, then those: a branch on each
        # box mispredicted often (with _overlap's change, 6-7 % of a replayed call)
        sb = seg_boxes[m]
        for q in range(seg_count[m]):
            gaps[q] = _box_gap(box, sb[0, q], sb[1, q], sb[2, q], sb[3, q], sb[4, q],
                               sb[5, q])
        met = 0
        for q in range(seg_count[m]):
            chosen[met] = q
            met += gaps[q] <= 0.0
        for h in range(met):
            q = chosen[h]
            ends = seg_ends[m, q]
            flags = ends[7]
            if not (moved or flags & EDGE_FRESH):
                continue
            if ra0 - RING <= ends[4] and ends[3] <= ra1 + RING and \
                    ca0 - RING <= ends[6] and ends[5] <= ca1 + RING:
                continue
            f = ends[0]
            if flags & EDGE_FREE:
                if not free or f < e:
                    continue    # found as e's partner when f was tested
            elif not free and f < e and flags & EDGE_CREASE:
                continue        # the same
            # a crease is kept from crossing, not a thickness away: the turns of a rolled
            # border, creased past the bound, pushed apart, stretched a double fold's
            # springs to 4.5 at 129 x 129 where crossings alone leave 0.77 (1.13 without
            # creases)
            side = _edge_side(x0, x1, a, b, ends[1], ends[2], thickness, substeps, shift,
                              free)
            if side != 0.0:
                if count < pairs.shape[0]:
                    pairs[count, 0], pairs[count, 1] = e, f
                    sides[count] = side
                count += 1
    return count


@numba.njit(**BORROW)
def _in_ring(si, sj, u0, u1, v0, v1, rows, cols):
    """Whether all of block (si, sj)'s cells lie in rows ``u0..u1`` and columns ``v0..v1``."""
    return si * SUB >= u0 and min(si * SUB + SUB - 1, rows - 2) <= u1 and \
        sj * SUB >= v0 and min(sj * SUB + SUB - 1, cols - 2) <= v1


@numba.njit(**BORROW)
def _unpacked(block):
    """Return the (row, column) of a block as :func:`_near_blocks` lists it."""
    return block >> BLOCK_BITS, block & ((1 << BLOCK_BITS) - 1)


@numba.njit(**BORROW)
def _block_of(r, c, ai, aj, rows, cols):
    """
    Return the index in patch (ai, aj) of the block holding grid point (r, c), a point of it.

    Row-major over the patch's blocks (as :func:`_near_blocks` numbers them); the grid's
    last row and column belong to the last block along them.
    """
    per = PATCH // SUB
    last_i, last_j = (rows - 2) // SUB, (cols - 2) // SUB
    return (min(r // SUB, last_i) - ai * per) * per + min(c // SUB, last_j) - aj * per


@numba.njit(**BORROW)
def _free_edges_against(x0, x1, rows, cols, thickness, substeps, subs, shift, ai, aj, bi,
                        bj, fresh, fresh_blocks, dirty, pairs, sides, count, crease, b_boxes,
                        near, counts, boxes, seg_boxes, seg_ends, seg_count, gaps, chosen):
    """
    Test patch A's edges on the grid's border against patch B's edges (see _edge_against).

    An edge with no end marked in ``fresh`` is tested only if B has a block marked in
    ``fresh_blocks`` (``dirty``: such patches). ``b_boxes``, ``near`` and ``counts``: B's
    blocks' boxes and A's blocks' lists of them, as :func:`_near_blocks` left them for
    this pair; ``boxes``: room for a box; ``seg_boxes``, ``seg_ends``, ``seg_count``:
    B's blocks' edges, ``gaps`` and ``chosen``: room (see _edge_against).
    """
    r0, r1 = ai * PATCH, min((ai + 1) * PATCH, rows - 1)
    c0, c1 = aj * PATCH, min((aj + 1) * PATCH, cols - 1)
    for side in range(4):
        if side == 0 and r0 == 0 or side == 1 and r1 == rows - 1:
            row = 0 if side == 0 else rows - 1
            for c in range(c0, c1):
                e = 3 * (row * cols + c)
                a, b = _edge(e, cols)
                block = _block_of(row, c, ai, aj, rows, cols)
                if counts[block] and (dirty[bi, bj] or fresh[a] or fresh[b]):
                    count = _edge_against(x0, x1, rows, cols, thickness, substeps, subs,
                                          shift, e, row, c, bi, bj, fresh, fresh_blocks,
                                          pairs, sides, count, boxes, b_boxes, crease,
                                          near[block], counts[block], seg_boxes, seg_ends,
                                          seg_count, gaps, chosen)
        if side == 2 and c0 == 0 or side == 3 and c1 == cols - 1:
            col = 0 if side == 2 else cols - 1
            for r in range(r0, r1):
                e = 3 * (r * cols + col) + 1
                a, b = _edge(e, cols)
                block = _block_of(r, col, ai, aj, rows, cols)
                if counts[block] and (dirty[bi, bj] or fresh[a] or fresh[b]):
                    count = _edge_against(x0, x1, rows, cols, thickness, substeps, subs,
                                          shift, e, r, col, bi, bj, fresh, fresh_blocks,
                                          pairs, sides, count, boxes, b_boxes, crease,
                                          near[block], counts[block], seg_boxes, seg_ends,
                                          seg_count, gaps, chosen)
    return count


@numba.njit(**BORROW)
def _crease_edges_against(x0, x1, rows, cols, thickness, substeps, subs, shift, ai, aj, bi,
                          bj, fresh, fresh_blocks, dirty, pairs, sides, count, crease,
                          b_boxes, near, counts, boxes, seg_boxes, seg_ends, seg_count,
                          gaps, chosen):
    """
    Test patch A's creases against patch B's edges (see _edge_against and _patch_creases).

    Away from the border, two layers folded sharply can hook over each other's crease
    with no point passing through or coming near a triangle (a cloth folded twice, where
    the second fold crosses the first, tangled so at 65 x 65). An edge with no end marked
    in ``fresh`` is tested only if B has a block marked in ``fresh_blocks`` (``dirty``).
    ``b_boxes``, ``near``, ``counts``, ``boxes``, ``seg_boxes``, ``seg_ends``,
    ``seg_count``, ``gaps`` and ``chosen``: as :func:`_free_edges_against` takes them.
    """
    for r in range(ai * PATCH, min((ai + 1) * PATCH, rows - 1)):
        for c in range(aj * PATCH, min((aj + 1) * PATCH, cols - 1)):
            block = _block_of(r, c, ai, aj, rows, cols)
            if counts[block] == 0:
                continue
            v = r * cols + c
            for d in range(3):
                e = 3 * v + d
                if not crease[e]:
                    continue
                a, b = _edge(e, cols)
                if not (dirty[bi, bj] or fresh[a] or fresh[b]):
                    continue
                count = _edge_against(x0, x1, rows, cols, thickness, substeps, subs, shift,
                                      e, r, c, bi, bj, fresh, fresh_blocks, pairs, sides, count,
                                      boxes, b_boxes, crease, near[block], counts[block],
                                      seg_boxes, seg_ends, seg_count, gaps, chosen)
    return count


@numba.njit(**BORROW)
def _triangle_normal(x, t, cols):
    """Return triangle t's normal, twice its area long (the vertices' order of _triangle)."""
    i, j, k = _triangle(t, cols)
    return _normal_of(x, i, j, k)


@numba.njit(**BORROW)
def _normal_of(x, i, j, k):
    """Return the normal of triangle (i, j, k), twice its area long."""
    ex, ey, ez = x[0, j] - x[0, i], x[1, j] - x[1, i], x[2, j] - x[2, i]
    fx, fy, fz = x[0, k] - x[0, i], x[1, k] - x[1, i], x[2, k] - x[2, i]
    return ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx


@numba.njit(**BORROW)
def _patch_creases(x, rows, cols, bi, bj, cosine, bit, crease, normals):
    """
    Set ``bit`` in ``crease`` at patch (bi, bj)'s creases in positions ``x``.

    ``crease`` holds 3 flags a point, as :func:`_edge` numbers edges. A crease: an edge
    between two triangles whose normals part by more than ``acos(cosine)`` (a degenerate
    triangle makes its edges creases); the bit is cleared at the others. An edge of a
    cloth bent less than that cannot pass through another layer unseen by the
    point-triangle tests (see :func:`self_contact`). Edges on the grid's border are free
    edges, never creases. Each triangle's normal is computed once, for the patch's cells
    and the row above and the column on the left (whose triangles its first row's and
    column's edges share), into ``normals`` (room for ``PATCH + 1`` by ``PATCH + 1``
    cells' two), with its squared length; the angles are compared without a square root.
    """
    r0, r1 = bi * PATCH, min((bi + 1) * PATCH, rows - 1)
    c0, c1 = bj * PATCH, min((bj + 1) * PATCH, cols - 1)
    lo_r, lo_c = max(r0 - 1, 0), max(c0 - 1, 0)
    # normals[cell row, cell column, triangle, (xyz, squared length)]
    # (the vertices from the cell's corner: from a triangle's index, the two integer
    # divisions a triangle were a quarter of the flags' time)
    for r in range(lo_r, r1):
        for c in range(lo_c, c1):
            i = r * cols + c
            for half in range(2):
                out = normals[r - lo_r, c - lo_c, half]
                j, k = (i + 1, i + cols + 1) if half == 0 else (i + cols + 1, i + cols)
                nx, ny, nz = _normal_of(x, i, j, k)
                out[0], out[1], out[2] = nx, ny, nz
                out[3] = nx * nx + ny * ny + nz * nz
    keep = ~np.uint8(bit)
    square = cosine * cosine
    for r in range(r0, r1):
        for c in range(c0, c1):
            v = r * cols + c
            u, w = r - lo_r, c - lo_c
            # along the row: the cell above's second triangle and this one's first; down
            # the column: the cell on the left's first and this one's second; the
            # diagonal: this cell's two
            for d, ua, wa, ha, hb, inside in ((0, u - 1, w, 1, 0, r > 0),
                                              (1, u, w - 1, 0, 1, c > 0),
                                              (2, u, w, 0, 1, True)):
                bent = False
                if inside:
                    a, b = normals[ua, wa, ha], normals[u, w, hb]
                    dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
                    both = a[3] * b[3]
                    # dot > cosine |a| |b|, squared on the side of cosine's sign
                    if cosine >= 0.0:
                        apart = dot > 0.0 and dot * dot > square * both
                    else:
                        apart = dot >= 0.0 or dot * dot < square * both
                    bent = not (apart and both > 0.0)
                flag = np.uint8(bit) if bent else np.uint8(0)
                crease[3 * v + d] = (crease[3 * v + d] & keep) | flag


@numba.njit(**BORROW)
def _triangle_boxes(x0, x1, rows, cols, si, sj, shift, out):
    """
    Write the boxes block (si, sj)'s triangles sweep in the frame moving by ``shift``.

    ``out[2 ((u - si SUB) SUB + v - sj SUB) + half]`` for cell (u, v)'s triangle ``half``.
    A point's path box grown by the thickness (:func:`_path_box`) is tested against them:
    made once for the points of a patch that test the block, not once a point (13 % of a
    detection's time on the folded drop's resting layers).
    """
    for u in range(si * SUB, min((si + 1) * SUB, rows - 1)):
        for v in range(sj * SUB, min((sj + 1) * SUB, cols - 1)):
            i = u * cols + v
            cell = 2 * ((u - si * SUB) * SUB + v - sj * SUB)
            for half in range(2):
                j, k = (i + 1, i + cols + 1) if half == 0 else (i + cols + 1, i + cols)
                box = out[cell + half]
                for d in range(3):
                    e = shift[d]
                    box[d] = min(x0[d, i], x0[d, j], x0[d, k], x1[d, i] - e, x1[d, j] - e,
                                 x1[d, k] - e)
                    box[3 + d] = max(x0[d, i], x0[d, j], x0[d, k], x1[d, i] - e,
                                     x1[d, j] - e, x1[d, k] - e)


@numba.njit(**JIT)
def _detect(x0, x1, rows, cols, thickness, substeps, dirty, fresh, fresh_blocks, pairs,
            sides, edge_pairs, edge_sides, boxes, ends, cones, subs, ready, crease,
            crease_ready, crease_cosine):
    """
    Collect (point, triangle) pairs and their sides over the step.

    Patches of ``PATCH`` x ``PATCH`` grid cells are culled by their swept boxes and, next
    to each other, by their normal cones (:func:`_pair_needed`; ``boxes``, ``ends`` and
    ``cones`` of :func:`_patch_boxes`, up to date); the pairs of patches left test points
    against triangles. Only pairs of patches with at least one marked in ``dirty`` are
    tested (after a response, those it moved a point of: elsewhere nothing changed since
    the last detection), and in them only the pairs with a point marked in ``fresh``
    (after a response, the points of the pairs it moved; the other pairs of those patches
    were apart at the last detection and have not moved since; ``fresh_blocks``: see
    :func:`_fresh_blocks`). ``subs`` holds the blocks' boxes (:func:`_sub_boxes`) of
    the patches marked in ``ready``; the others' are computed when a patch first meets
    another one and marked: a step's later calls keep those of the patches where nothing
    moved. In the pairs of patches along the grid's border, the free edges are tested
    against the other patch's edges (``edge_pairs``, ``edge_sides``:
    :func:`_edge_side`): a free edge can pass through another layer where no point
    passes through a triangle (a layer's corner hooked round another's edge); so can a
    sharp crease away from the border: each patch's creases (``crease``,
    :func:`_patch_creases` at ``crease_cosine``, computed when the patch and another first
    list blocks near each other and marked in ``crease_ready``, which the step's later
    calls keep where the patch and the patches above and on the left of it did not go
    stale: see ``BOXES_KEPT_NEW_START``) are tested against the other patch's edges. It
    returns how many point-triangle and edge pairs were found (those beyond the arrays'
    capacity are not kept).
    """
    pr, pc = boxes.shape[0], boxes.shape[1]
    box_a, box_b, shift = np.empty(6), np.empty(6), np.empty(3)
    # a patch pair's block lists (see _near_blocks)
    per = PATCH // SUB
    b_boxes = np.empty((per * per, 6))
    near = np.empty((per * per, per * per), dtype=np.int64)
    counts = np.empty(per * per, dtype=np.int64)
    tri_boxes = np.empty((per * per, 2 * SUB * SUB, 6))
    tri_ready = np.empty(per * per, dtype=np.bool_)
    work, kept = np.empty((3, 6)), np.empty(per * per, dtype=np.int64)     # scratch
    kept_boxes, kept_gaps = np.empty((6, per * per)), np.empty(per * per)
    kept_fresh = np.empty(per * per, dtype=np.bool_)
    edge_boxes = np.empty((1, 6))
    seg_boxes = np.empty((per * per, 6, BLOCK_EDGES))
    gaps, chosen = np.empty(BLOCK_EDGES), np.empty(BLOCK_EDGES, dtype=np.int64)
    seg_ends = np.empty((per * per, BLOCK_EDGES, 8), dtype=np.int64)
    seg_count = np.empty(per * per, dtype=np.int64)
    creased = np.full((pr, pc), -1, dtype=np.int8)     # per patch: unknown, no, yes
    normals = np.empty((PATCH + 1, PATCH + 1, 2, 4))     # see _patch_creases
    # sweep and prune along x over the patches' boxes
    lows = np.empty(pr * pc)
    for a in range(pr * pc):
        lows[a] = boxes[a // pc, a % pc, 0]
    order = np.argsort(lows)
    # (rows and columns once, not an integer division each time a patch is tested)
    order_i, order_j = order // pc, order % pc
    ranked, next_dirty = _ranked(boxes, dirty, order_i, order_j)
    angles = _cone_angles(cones)
    return _sweep(x0, x1, rows, cols, thickness, substeps, dirty, fresh, fresh_blocks, pairs,
                  sides, edge_pairs, edge_sides, boxes, ends, cones, subs, ready, crease,
                  crease_ready, crease_cosine, order, order_i, order_j, ranked, next_dirty,
                  angles, box_a, box_b,
                  shift, b_boxes, near, counts, tri_boxes, tri_ready, work, kept, kept_boxes,
                  kept_fresh, kept_gaps, edge_boxes, seg_boxes, seg_ends, seg_count, gaps,
                  chosen, creased, normals)


@numba.njit(**BORROW)
def _sweep(x0, x1, rows, cols, thickness, substeps, dirty, fresh, fresh_blocks, pairs, sides,
           edge_pairs, edge_sides, boxes, ends, cones, subs, ready, crease, crease_ready,
           crease_cosine, order, order_i, order_j, ranked, next_dirty, angles, box_a, box_b,
           shift, b_boxes,
           near, counts, tri_boxes, tri_ready, work, kept, kept_boxes, kept_fresh, kept_gaps,
           edge_boxes, seg_boxes, seg_ends, seg_count, gaps, chosen, creased, normals):
    """
    Run :func:`_detect`'s sweep over the pairs of patches; return its two pair counts.

    Apart from the arrays :func:`_detect` allocates (``order``, ``order_i``, ``order_j``:
    the patches by their boxes' low x, and their rows and columns; ``ranked`` and
    ``next_dirty``: see :func:`_ranked`; ``angles``:
    :func:`_cone_angles`; the rest scratch space), so that it only borrows them: compiled
    without reference counting, the views it takes of the patches' rows of ``ends`` and
    the arrays it hands to each pair's tests are not counted.
    """
    pr, pc = boxes.shape[0], boxes.shape[1]
    total = pr * pc
    count = edge_count = 0
    for m in range(total):
        a = order[m]
        ai, aj = order_i[m], order_j[m]
        # a clean patch is tested against the dirty ones alone: the clean ones between
        # are stepped over (a later call with a few patches dirty went through all of
        # the 5,600 pairs of patches the sweep meets on the folded drop's sliding layers)
        a_dirty = dirty[ai, aj]
        m2 = m if a_dirty else next_dirty[m]
        while m2 < total and ranked[m2, 0] <= ranked[m, 3]:
            k = m2
            m2 = m2 + 1 if a_dirty else next_dirty[m2 + 1]
            # the boxes along y and z (along x the sweep's order and bound hold them), on
            # the sweep's copy in its order (of those 5,600 pairs, 1,200 meet along all
            # three axes)
            if ranked[k, 1] > ranked[m, 4] or ranked[m, 1] > ranked[k, 4] or \
                    ranked[k, 2] > ranked[m, 5] or ranked[m, 2] > ranked[k, 5]:
                continue
            b = order[k]
            bi, bj = order_i[k], order_j[k]
            if not _pair_needed(cones, angles, ai, aj, bi, bj):
                continue
            # again in the frame of the two patches' mean motion
            for d in range(3):
                shift[d] = 0.5 * (ends[ai, aj, 12 + d] + ends[bi, bj, 12 + d])
            _moving_box(ends[ai, aj], shift, thickness, box_a)
            _moving_box(ends[bi, bj], shift, thickness, box_b)
            if not _overlap(box_a, box_b):
                continue
            for patch_i, patch_j in ((ai, aj), (bi, bj)):
                if not ready[patch_i, patch_j]:
                    _sub_boxes(x0, x1, rows, cols, patch_i, patch_j, subs)
                    ready[patch_i, patch_j] = True
            flags = False
            # each way round: A's blocks' lists of the B blocks near them, then A's points
            # against B's triangles and A's free edges and creases against B's edges, on
            # those lists. Most ways round list nothing (the fold demo's layers at rest:
            # three in four of the 1,400 a detection, patches whose boxes meet only
            # within the thickness they are grown by); a block is near another if and
            # only if the other is near it, so a first way round that lists nothing ends
            # the pair (the second's lists were 2-5 % of the fold's replayed calls)
            for patch_i, patch_j, other_i, other_j in ((ai, aj, bi, bj), (bi, bj, ai, aj)):
                if not _near_blocks(subs, ends, shift, thickness, patch_i, patch_j, other_i,
                                    other_j, fresh_blocks, b_boxes, near, counts, work, kept,
                                    kept_boxes, kept_fresh, kept_gaps):
                    break
                if not flags:
                    # the two patches' creases, once a way round lists blocks (A's edges
                    # read B's flags): most pairs of patches whose boxes meet list none
                    for patch_i2, patch_j2 in ((ai, aj), (bi, bj)):
                        _creases_ready(x0, x1, rows, cols, patch_i2, patch_j2, crease_cosine,
                                       crease, crease_ready, normals)
                    flags = True
                count = _points_against(x0, x1, rows, cols, thickness, substeps, subs, shift,
                                        patch_i, patch_j, other_i, other_j, fresh,
                                        fresh_blocks, pairs, sides, count, b_boxes, near,
                                        counts, tri_boxes, tri_ready, work)
                seg_count[:] = -1     # (B's blocks' edges, in this pair's frame)
                if patch_i == 0 or patch_i == pr - 1 or patch_j == 0 or patch_j == pc - 1:
                    edge_count = _free_edges_against(
                        x0, x1, rows, cols, thickness, substeps, subs, shift, patch_i,
                        patch_j, other_i, other_j, fresh, fresh_blocks, dirty, edge_pairs,
                        edge_sides, edge_count, crease, b_boxes, near, counts, edge_boxes,
                        seg_boxes, seg_ends, seg_count, gaps, chosen)
                # (most patches have no crease: their flags read once a detection)
                if creased[patch_i, patch_j] < 0:
                    creased[patch_i, patch_j] = _has_creases(crease, rows, cols, patch_i,
                                                             patch_j)
                if creased[patch_i, patch_j]:
                    edge_count = _crease_edges_against(
                        x0, x1, rows, cols, thickness, substeps, subs, shift, patch_i,
                        patch_j, other_i, other_j, fresh, fresh_blocks, dirty, edge_pairs,
                        edge_sides, edge_count, crease, b_boxes, near, counts, edge_boxes,
                        seg_boxes, seg_ends, seg_count, gaps, chosen)
                if a == b:
                    break
    return count, edge_count


@numba.njit(**JIT)
def _ranked(boxes, dirty, order_i, order_j):
    """
    Return the patches' boxes in the sweep's order, and where the next dirty patch lies.

    ``ranked[m] = boxes[order_i[m], order_j[m]]`` (read in turn by the sweep, not
    gathered a pair at a time); ``next_dirty[m]``: the first place from ``m`` on whose
    patch is marked in ``dirty`` (``len(order_i)`` past the last; one more place holds it).
    """
    total = order_i.shape[0]
    ranked = np.empty((total, 6))
    next_dirty = np.empty(total + 1, dtype=np.int64)
    next_dirty[total] = total
    for m in range(total - 1, -1, -1):
        for d in range(6):
            ranked[m, d] = boxes[order_i[m], order_j[m], d]
        next_dirty[m] = m if dirty[order_i[m], order_j[m]] else next_dirty[m + 1]
    return ranked, next_dirty


@numba.njit(**BORROW)
def _creases_ready(x0, x1, rows, cols, bi, bj, cosine, crease, crease_ready, normals):
    """
    Flag patch (bi, bj)'s creases at the start and at the end, where not yet done.

    The start's are kept for the step's calls (``crease_ready``, :func:`_patch_creases`).
    """
    for time, x in enumerate((x0, x1)):
        if not crease_ready[bi, bj, time]:
            _patch_creases(x, rows, cols, bi, bj, cosine, time + 1, crease, normals)
            crease_ready[bi, bj, time] = True


@numba.njit(**BORROW)
def _flags_stale(crease_ready, time, stale):
    """
    Mark the crease flags at ``time`` (0 start, 1 end) out of date where ``stale`` round them.

    The patches marked and those below and to the right of one: a patch's flags on its
    first row's and first column's edges take the bend from the triangles of the cells
    above and on the left (:func:`_patch_creases`), points of the patches there.
    """
    pr, pc = stale.shape
    for bi in range(pr):
        for bj in range(pc):
            if stale[bi, bj] or (bi > 0 and stale[bi - 1, bj]) or \
                    (bj > 0 and stale[bi, bj - 1]):
                crease_ready[bi, bj, time] = False


@numba.njit(**BORROW)
def _crease_cosine(thickness, edge, angle):
    """
    Return the cosine of the bend (angle between two normals) past which an edge is a crease.

    ``edge``: the level's longest edge at the step's start. A crease is an edge bent by
    more than the lesser of two angles. The thickness's: an edge as long as ``edge``
    passing under a crease with both its ends a thickness clear of the crease's two
    triangles needs each of them to drop by a thickness within half that edge of the
    crease's line, so to slope by ``asin(2 thickness / edge)`` or more from the edge
    passing under it: their normals part by twice that at least (the edge across the
    crease's line: the least bend; a bend spread over two edges a spacing apart needs more
    than the thickness allows). And ``angle`` (rad; ``CREASE_ANGLE`` by default): the
    point tests keep the ends a thickness clear only at the ends of a step; in it a point
    may come as near a layer as it likes without crossing it, and edges bent less than the
    thickness's angle hooked through each other where layers fell onto each other fast or
    crumpled (the 129 x 129 double fold, whose thickness's angle is 93 degrees, tangled
    so in 6 of 44 runs at other fold speeds and seeds, and none with 10 degrees:
    doc/self_contact_log.md). ``angle`` 0: every bent edge (a cloth crumpled in
    compression brings rows a few apart together, and there two edges can hook through
    each other while their ends cross only triangles within ``RING`` of them, which are
    not tested: ``multigrid`` solving the 129 x 129 folded drop's finest level tangled so
    from step 21, edges 3 rows apart bent 8-47 degrees); pi: the thickness's angle alone.
    ``angle`` is taken within 0..pi; with no edge length (``edge`` not above 0) it alone
    bounds the bend (pi: no creases).
    """
    sine = math.sin(0.5 * min(max(angle, 0.0), math.pi))
    if edge > 0.0:
        sine = min(sine, 2.0 * thickness / edge)
    return math.cos(2.0 * math.asin(sine))


@numba.njit(**BORROW)
def _has_creases(crease, rows, cols, bi, bj):
    """Whether patch (bi, bj) has a crease (at either end of the step, :func:`_patch_creases`)."""
    for r in range(bi * PATCH, min((bi + 1) * PATCH, rows - 1)):
        for c in range(bj * PATCH, min((bj + 1) * PATCH, cols - 1)):
            v = 3 * (r * cols + c)
            if crease[v] or crease[v + 1] or crease[v + 2]:
                return 1
    return 0


@numba.njit(**JIT)
def _fresh_blocks(fresh, rows, cols):
    """
    Return which blocks of ``SUB`` x ``SUB`` cells have a vertex marked in ``fresh``.

    Block ``(si, sj)`` holds the grid points of rows ``si SUB .. (si + 1) SUB`` and the
    same columns. A block row at a time: its rows' marks or-ed column by column (a loop
    that vectorises), then each block's columns read. Reading each block's vertices until
    one was marked cost 0.03 ms a call at 129 x 129 where a response had marked a few
    hundred points, most of a detection's test round them.
    """
    block_rows, block_cols = (rows - 2) // SUB + 1, (cols - 2) // SUB + 1
    out = np.zeros((block_rows, block_cols), dtype=np.bool_)
    column = np.empty(cols, dtype=np.bool_)
    for si in range(block_rows):
        column[:] = False
        for r in range(si * SUB, min((si + 1) * SUB, rows - 1) + 1):
            row = fresh[r * cols:(r + 1) * cols]
            for c in range(cols):
                column[c] |= row[c]
        for sj in range(block_cols):
            for c in range(sj * SUB, min((sj + 1) * SUB, cols - 1) + 1):
                if column[c]:
                    out[si, sj] = True
                    break
    return out


@numba.njit(**BORROW)
def _longest_move(x0, x1, ta, tb, shift):
    """
    Return the longest path of a point between ``ta`` and ``tb`` in the shifted frame.

    Squared lengths compared, one square root at the end (a root a point cost 0.03 ms a
    call on 129 x 129).
    """
    longest = 0.0
    for i in range(x0.shape[1]):
        longest = max(longest, _squared_move(x0, x1, i, shift))
    return abs(tb - ta) * math.sqrt(longest)


@numba.njit(**BORROW_INLINE)
def _squared_move(x0, x1, i, shift):
    """Return the squared length of point i's move from ``x0`` to ``x1`` less ``shift``."""
    ex = x1[0, i] - x0[0, i] - shift[0]
    ey = x1[1, i] - x0[1, i] - shift[1]
    ez = x1[2, i] - x0[2, i] - shift[2]
    return ex * ex + ey * ey + ez * ez


@numba.njit(**BORROW)
def _longest_move_of(x0, x1, points, shift):
    """
    :func:`_longest_move` over the step where only ``points`` move (the others stay put).

    A point that stays moves by ``-shift`` in the shifted frame.
    """
    longest = 0.0
    if points.shape[0] < x0.shape[1]:
        longest = shift[0] * shift[0] + shift[1] * shift[1] + shift[2] * shift[2]
    for p in points:
        longest = max(longest, _squared_move(x0, x1, p, shift))
    return math.sqrt(longest)


@numba.njit(**BORROW)
def _squared(x, i, j):
    """Squared distance between points i and j of ``x`` (3, n)."""
    ex, ey, ez = x[0, j] - x[0, i], x[1, j] - x[1, i], x[2, j] - x[2, i]
    return ex * ex + ey * ey + ez * ez


@numba.njit(**BORROW)
def _longest_edge_from(x, i0, j0, count, longest):
    """
    Return the larger of ``longest`` and the squared lengths of ``count`` edges i0 + m, j0 + m.

    Four running maxima: one waits for the comparison before it every edge.
    """
    a = b = c = d = longest
    whole = count - count % 4
    for m in range(0, whole, 4):
        a = max(a, _squared(x, i0 + m, j0 + m))
        b = max(b, _squared(x, i0 + m + 1, j0 + m + 1))
        c = max(c, _squared(x, i0 + m + 2, j0 + m + 2))
        d = max(d, _squared(x, i0 + m + 3, j0 + m + 3))
    for m in range(whole, count):
        a = max(a, _squared(x, i0 + m, j0 + m))
    return max(max(a, b), max(c, d))


@numba.njit(**BORROW)
def _longest_edge(x, rows, cols):
    """
    Return the longest structural or diagonal edge of the triangles (m).

    One run of edges of one direction a row, without a bounds test per edge.
    """
    longest = 0.0
    for r in range(rows):
        i = r * cols
        longest = _longest_edge_from(x, i, i + 1, cols - 1, longest)          # right
        if r + 1 < rows:
            longest = _longest_edge_from(x, i, i + cols, cols, longest)        # down
            longest = _longest_edge_from(x, i, i + cols + 1, cols - 1, longest)  # diagonal
    return math.sqrt(longest)


@numba.njit(**BORROW)
def _shift(x, i, weight, nx, ny, nz):
    x[0, i] += weight * nx
    x[1, i] += weight * ny
    x[2, i] += weight * nz


@numba.njit(**BORROW)
def _move(x, qd, dv, i, weight, nx, ny, nz, h):
    x[0, i] += weight * nx
    x[1, i] += weight * ny
    x[2, i] += weight * nz
    qd[0, i] += weight * nx / h
    qd[1, i] += weight * ny / h
    qd[2, i] += weight * nz / h
    dv[0, i] += weight * nx / h
    dv[1, i] += weight * ny / h
    dv[2, i] += weight * nz / h


@numba.njit(**BORROW_INLINE)
def _separation(x, p, i, j, k, side, thickness):
    """
    Return how to push p away from triangle (i, j, k): ``(n xyz, gap, u, v, w)``.

    The direction, how far p is inside the thickness (negative: violated) and the
    triangle's weights.

    A pair found crossing (``|side| == 2``) goes back along the triangle's normal to the
    side it came from, at its projection (clipped into the triangle). A pair found near
    separates from the triangle's closest point: along the side's normal where that is
    inside the triangle, along the line from the closest point on an edge or vertex to p
    otherwise.
    """
    sd, nx, ny, nz, u, v, w = _plane(_point(x, p), _point(x, i), _point(x, j), _point(x, k))
    sign = 1.0 if side > 0.0 else -1.0
    if abs(side) > 1.5:
        u, v, w = max(u, 0.0), max(v, 0.0), max(w, 0.0)
        total = u + v + w
        if not total > 0.0:
            return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        return sign * nx, sign * ny, sign * nz, sign * sd - thickness, u / total, \
            v / total, w / total
    u, v, w = _closest(_point(x, p), _point(x, i), _point(x, j), _point(x, k))
    ox, oy, oz, dist = _offset(x, p, i, j, k, u, v, w)
    if (u > 0.0 and v > 0.0 and w > 0.0) or not dist > 0.0:
        return sign * nx, sign * ny, sign * nz, sign * sd - thickness, u, v, w
    return ox / dist, oy / dist, oz / dist, dist - thickness, u, v, w


@numba.njit(**BORROW)
def _blocked(support, v, nx, ny, nz):
    """Whether vertex v has no room left to move along n (into its obstacle)."""
    return support[3, v] <= ROOM_TOLERANCE and \
        support[0, v] * nx + support[1, v] * ny + support[2, v] * nz < 0.0


@numba.njit(**BORROW)
def _room(support, v, a, nx, ny, nz):
    """
    Return the part of a move ``a`` along n that vertex v may make, and use its room.

    Towards its obstacle it moves at most the room left (then stays at the margin).
    """
    into = -a * (support[0, v] * nx + support[1, v] * ny + support[2, v] * nz)
    if into > support[3, v]:
        a *= max(support[3, v], 0.0) / into
        into = max(support[3, v], 0.0)
    support[3, v] -= into
    return a


@numba.njit(**BORROW)
def _motion(x0, x1, verts, weights):
    """Return the motion over the step of the four vertices' weighted sum."""
    rx = ry = rz = 0.0
    for m in range(4):
        idx, wt = verts[m], weights[m]
        rx += wt * (x1[0, idx] - x0[0, idx])
        ry += wt * (x1[1, idx] - x0[1, idx])
        rz += wt * (x1[2, idx] - x0[2, idx])
    return rx, ry, rz


@numba.njit(**BORROW)
def _free_mass(inv_mass, support, v, n, ahead, held=False):
    """
    Vertex v's inverse mass for a push along n (against it if not ``ahead``), 0 if blocked.

    ``held``: the weight of a held vertex instead (a grasp, a pin: 1, and 0 for a free
    one), for a pair whose free vertices cannot move (see :func:`_push`).
    """
    sign = 1.0 if ahead else -1.0
    if _blocked(support, v, sign * n[0], sign * n[1], sign * n[2]):
        return 0.0
    if held:
        return 1.0 if inv_mass[v] == 0.0 else 0.0
    return inv_mass[v]


@numba.njit(**BORROW_INLINE)
def _push(x1, qd, dv, inv_mass, support, verts, weights, ahead, nx, ny, nz, gap, one_side):
    """
    Move a pair's four vertices so that their weighted sum gains ``-gap`` along n.

    A pair is a point and a triangle (weights ``1, -u, -v, -w``) or two edges (``1 - s,
    s, t - 1, -t``): the first ``ahead`` vertices move along n, the others against it.
    Velocities lose the sum's approach along n (inelastic: a push turned into velocity,
    push / h, made the layers bounce and stretched the cloth). A vertex resting on an
    obstacle does not move into it (its weight is zero for this push); ``one_side``:
    only the first side moves (only the second if the first is held). When nothing free
    can move, the held vertices with room move instead, equally. A side pushed up
    off one that rests comes to rest (:func:`_come_to_rest`). Returns ``(lam, denom,
    inverse masses used)``; ``denom`` 0: nothing could move.
    """
    n_ = (nx, ny, nz)
    ims = (_free_mass(inv_mass, support, verts[0], n_, 0 < ahead),
           _free_mass(inv_mass, support, verts[1], n_, 1 < ahead),
           _free_mass(inv_mass, support, verts[2], n_, False),
           _free_mass(inv_mass, support, verts[3], n_, False))
    if one_side:
        first = ims[0] + ims[1] if ahead == 2 else ims[0]
        ims = (ims[0] if first > 0.0 else 0.0,
               ims[1] if (first > 0.0) == (ahead == 2) else 0.0,
               0.0 if first > 0.0 else ims[2], 0.0 if first > 0.0 else ims[3])
    denom = _share(weights, ims)
    if not denom > 0.0:
        # nothing free can move: a held point pressed into a layer that lies on an
        # obstacle (a grasped corner put down on the cloth on the table). Held apart by
        # neither side, the layers tangled (the fold with its 65 x 65 level solved, and a
        # grasp lowered onto a folded cloth on the ground: 6-18 edges through triangles);
        # the hold yields instead, and the grasp pulls it back next step
        ims = (_free_mass(inv_mass, support, verts[0], n_, 0 < ahead, True),
               _free_mass(inv_mass, support, verts[1], n_, 1 < ahead, True),
               _free_mass(inv_mass, support, verts[2], n_, False, True),
               _free_mass(inv_mass, support, verts[3], n_, False, True))
        denom = _share(weights, ims)
        if not denom > 0.0:
            return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    lam = -gap / denom
    clipped = 0         # bit m: vertex m reached its obstacle
    for m in range(4):
        if ims[m] == 0.0:
            continue    # (it does not move: a point on a resting layer moves alone)
        v = verts[m]
        move = lam * ims[m] * weights[m]
        allowed = _room(support, v, move, nx, ny, nz)
        if allowed != move:
            clipped |= 1 << m
        _shift(x1, v, allowed, nx, ny, nz)
    if not one_side:    # (the last round: nothing detects after it)
        _come_to_rest(inv_mass, support, verts, weights, ims, ahead, nx, ny, nz)
    _inelastic(qd, verts, weights, ims, clipped, ahead, nx, ny, nz, dv)
    return lam, denom, ims[0], ims[1], ims[2], ims[3]


@numba.njit(**BORROW_INLINE)
def _share(weights, ims):
    """
    Return a push's denominator: the weighted inverse masses, at least the largest one.

    No vertex moves further than the gap: with the point held (a pin, a grasp), a free
    vertex of small weight w alone would move gap / w (12 m once, on a 257 x 257 folded
    drop with points held); the pair is then only partly separated and the next pass
    goes on. With every point free it does not bind (masses within 4x of each other).
    """
    total, most = 0.0, 0.0
    for m in range(4):
        total += weights[m] * weights[m] * ims[m]
        most = max(most, abs(weights[m]) * ims[m])
    return max(total, most)


@numba.njit(**BORROW_INLINE)
def _come_to_rest(inv_mass, support, verts, weights, ims, ahead, nx, ny, nz):
    """
    After a push: a side pushed up off a side that rests comes to rest on it.

    A side rests when every vertex of it in the pair (non-zero weight) is free but did
    not move, blocked by its obstacle (:func:`_blocked`; ``ims`` zero, the pushes not
    one-sided). The other side's vertices that the push moved (``ims`` non-zero) up
    along their own obstacle's normal (within 45 degrees) lose their room: for the rest
    of the call nothing pushes them down either, and the layer on them moves alone. A
    stack of layers on the ground is so resolved from the bottom up, one layer a pass at
    least (the shock propagation of rigid stacks); with the weights shared a layer pushed
    down by the one above was pushed back up by the one below, and the passes did not
    converge (the hierarchical double fold's four layers at rest,
    doc/self_contact_log.md).
    """
    rests = (True, True)        # the first side (the ``ahead`` vertices), the other
    for m in range(4):
        if weights[m] != 0.0 and not (ims[m] == 0.0 and inv_mass[verts[m]] > 0.0):
            rests = (False, rests[1]) if m < ahead else (rests[0], False)
    if not (rests[0] or rests[1]):
        return
    for m in range(4):
        v = verts[m]
        if ims[m] == 0.0 or rests[0 if m < ahead else 1] or support[3, v] <= 0.0:
            continue
        sign = 1.0 if m < ahead else -1.0
        if sign * (support[0, v] * nx + support[1, v] * ny + support[2, v] * nz) > UPWARD:
            support[3, v] = 0.0


@numba.njit(**BORROW_INLINE)
def _inelastic(qd, verts, weights, ims, clipped, ahead, nx, ny, nz, dv):
    """
    Take a pushed pair's approach along n off its vertices' velocities.

    Shared as the push was (``ims``), but a vertex the push brought to its obstacle (bit
    m of ``clipped``) takes none of it (it stays at the obstacle): with the push's
    shares, a layer lying on the ground took its part of the approach of the layer
    falling onto it, every step, and the stack on it never came to rest (4 cm/s
    downwards at rest).
    """
    vn = 0.0
    for d, n_d in ((0, nx), (1, ny), (2, nz)):
        along = 0.0
        for m in range(4):
            along += weights[m] * qd[d, verts[m]]
        vn += along * n_d
    if not vn < 0.0:
        return
    shares = (0.0 if clipped & 1 else ims[0], 0.0 if clipped & 2 else ims[1],
              0.0 if clipped & 4 else ims[2], 0.0 if clipped & 8 else ims[3])
    denom = _share(weights, shares)
    if not denom > 0.0:
        return
    mu = -vn / denom
    for d, n_d in ((0, nx), (1, ny), (2, nz)):
        for m in range(4):
            if shares[m] != 0.0:
                qd[d, verts[m]] += mu * shares[m] * weights[m] * n_d
                dv[d, verts[m]] += mu * shares[m] * weights[m] * n_d
    # a side that stays (resting, held, or not moved in the last round): no vertex of the
    # other leaves it faster than it moves along n. The shares follow the weights, and a
    # triangle's vertex of large weight overshot (the layers of a stack rose off each
    # other at up to a third of the speed they fell with). Between two sides that move,
    # the pushes and this change keep the pair's momentum, and a cap would not
    still = (True, True)
    for m in range(4):
        if ims[m] > 0.0:
            still = (False, still[1]) if m < ahead else (still[0], False)
    if not (still[0] or still[1]):
        return
    alongs = (qd[0, verts[0]] * nx + qd[1, verts[0]] * ny + qd[2, verts[0]] * nz,
              qd[0, verts[1]] * nx + qd[1, verts[1]] * ny + qd[2, verts[1]] * nz,
              qd[0, verts[2]] * nx + qd[1, verts[2]] * ny + qd[2, verts[2]] * nz,
              qd[0, verts[3]] * nx + qd[1, verts[3]] * ny + qd[2, verts[3]] * nz)
    sides = (0.0, 0.0)
    for m in range(4):
        sides = (sides[0] + weights[m] * alongs[m], sides[1]) if m < ahead else \
            (sides[0], sides[1] - weights[m] * alongs[m])
    for m in range(4):
        if shares[m] == 0.0:
            continue
        excess = alongs[m] - sides[1] if m < ahead else alongs[m] - sides[0]
        if (excess > 0.0) == (m < ahead) and excess != 0.0:
            for d, n_d in ((0, nx), (1, ny), (2, nz)):
                qd[d, verts[m]] -= excess * n_d
                dv[d, verts[m]] -= excess * n_d


@numba.njit(**BORROW_INLINE)
def _resolve(x0, x1, qd, dv, inv_mass, support, cols, p, t, side, thickness, friction, h,
             one_side):
    """
    Push one pair apart (and apply its friction); returns whether it was violated.

    ``one_side``: only the point moves (only the triangle if the point is held): a pair
    pushed apart alone is then satisfied whatever its neighbours do. A vertex resting on an
    obstacle does not move into it (its weight is zero for this push).
    """
    i, j, k = _triangle(t, cols)
    nx, ny, nz, gap, u, v, w = _separation(x1, p, i, j, k, side, thickness)
    if not gap < 0.0:
        return False
    verts, weights = (p, i, j, k), (1.0, -u, -v, -w)
    rx, ry, rz = _motion(x0, x1, verts, weights)
    if -gap > 2.0 * thickness + math.sqrt(rx * rx + ry * ry + rz * rz):
        return False
    lam, denom, ip, ii, ij, ik = _push(x1, qd, dv, inv_mass, support, verts, weights, 1,
                                       nx, ny, nz, gap, one_side)
    if not denom > 0.0:
        return False
    if friction > 0.0:
        _rub(x1, qd, dv, support, verts, (u, v, w), (ip, ii, ij, ik), lam, denom,
             (rx, ry, rz), (nx, ny, nz), friction * -gap, h)
    return True


@numba.njit(**BORROW_INLINE)
def _rub(x1, qd, dv, support, verts, uvw, ims, lam, denom, motion, n, most, h):
    """
    Friction after a point-triangle push: up to ``most`` (m) off the pair's sliding.

    ``motion``: the point's motion relative to the triangle's point over the step before
    the push (:func:`_motion`), ``lam``, ``denom`` and ``ims`` the push's (:func:`_push`),
    ``uvw`` the triangle's weights, ``n`` the push's direction. The sliding left after
    the push (its part across n) is taken off, at most ``most`` of it, shared by inverse
    masses, and that move divided by ``h`` off the velocities.
    """
    p, i, j, k = verts
    u, v, w = uvw
    ip, ii, ij, ik = ims
    nx, ny, nz = n
    push = lam * (ip + u * u * ii + v * v * ij + w * w * ik)
    rx, ry, rz = motion[0] + push * nx, motion[1] + push * ny, motion[2] + push * nz
    rn = rx * nx + ry * ny + rz * nz
    rx, ry, rz = rx - rn * nx, ry - rn * ny, rz - rn * nz
    slide = math.sqrt(rx * rx + ry * ry + rz * rz)
    if not slide > 0.0:
        return
    stop = min(slide, most) / denom / slide
    # nor does friction drag a vertex into its obstacle
    for idx, wt in ((p, -stop * ip), (i, stop * ii * u), (j, stop * ij * v),
                    (k, stop * ik * w)):
        if wt != 0.0:
            _move(x1, qd, dv, idx, _room(support, idx, wt, rx, ry, rz), rx, ry, rz, h)


@numba.njit(**BORROW)
def _clamped_segments(a, b, c, d):
    """Closest points ``(s, t)`` of segments a-b and c-d (the lines' clamped into both)."""
    s, t, ok = _segments(a, b, c, d)
    if not ok:
        return 0.5, 0.5
    s = min(1.0, max(0.0, s))
    # t for that s, then s for that t
    vx, vy, vz = d[0] - c[0], d[1] - c[1], d[2] - c[2]
    vv = vx * vx + vy * vy + vz * vz
    px = a[0] + s * (b[0] - a[0]) - c[0]
    py = a[1] + s * (b[1] - a[1]) - c[1]
    pz = a[2] + s * (b[2] - a[2]) - c[2]
    t = min(1.0, max(0.0, (px * vx + py * vy + pz * vz) / vv)) if vv > 0.0 else 0.0
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    uu = ux * ux + uy * uy + uz * uz
    qx = c[0] + t * vx - a[0]
    qy = c[1] + t * vy - a[1]
    qz = c[2] + t * vz - a[2]
    s = min(1.0, max(0.0, (qx * ux + qy * uy + qz * uz) / uu)) if uu > 0.0 else 0.0
    return s, t


@numba.njit(**BORROW)
def _resolve_edges(x0, x1, qd, dv, inv_mass, support, cols, e, f, side, thickness, one_side):
    """
    Push edge e (a free edge) and edge f apart; returns whether they were too close.

    As :func:`_resolve` for a point and a triangle, between the edges' closest points
    (weights ``1 - s, s`` and ``1 - t, t``): a crossed pair along the normal of both
    edges to the side e came from, a near one along the line between the closest points.
    Inelastic, no friction (a layer slides over a free edge on the points near it).
    """
    a, b = _edge(e, cols)
    c, d = _edge(f, cols)
    pa, pb, pc, pd = _point(x1, a), _point(x1, b), _point(x1, c), _point(x1, d)
    s, t = _clamped_segments(pa, pb, pc, pd)
    gx, gy, gz, dist = _gap(pa, pb, pc, pd, s, t)
    if abs(side) > 1.5:
        ux, uy, uz = pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]
        vx, vy, vz = pd[0] - pc[0], pd[1] - pc[1], pd[2] - pc[2]
        nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        norm = math.sqrt(nx * nx + ny * ny + nz * nz)
        if not norm > 0.0:
            return False
        sign = 1.0 if side > 0.0 else -1.0
        nx, ny, nz = sign * nx / norm, sign * ny / norm, sign * nz / norm
        gap = gx * nx + gy * ny + gz * nz - thickness
    else:
        if not dist > 0.0:
            return False
        nx, ny, nz = gx / dist, gy / dist, gz / dist
        gap = dist - thickness
    if not gap < 0.0:
        return False
    # the closest points' motion over the step: a pair this deep was not made by it
    verts, weights = (a, b, c, d), (1.0 - s, s, t - 1.0, -t)
    rx, ry, rz = _motion(x0, x1, verts, weights)
    if -gap > 2.0 * thickness + math.sqrt(rx * rx + ry * ry + rz * rz):
        return False
    return _push(x1, qd, dv, inv_mass, support, verts, weights, 2, nx, ny, nz, gap,
                 one_side)[1] > 0.0


@numba.njit(**JIT)
def self_contact(
        # inputs / outputs: the level after the step and its velocity change, corrected
        q, qd, dv,
        # inputs: positions at the start of the step (friction takes the sliding since
        # then), where the points' paths start (the step's start, or where an earlier call
        # of the step left nothing near: see the returned ``clean``), masses, holds, which
        # points moved since this step's last call (all of them at its first); in / out:
        # the outward unit normal of the obstacle below each point and its room to the
        # obstacle's margin (shape (4, rows, cols); normal zero: none), the room used up
        # in place
        q_prev, q_from, mass, hold_kind, moved, support,
        # inputs: cloth thickness (m), friction coefficient, resolution passes, step (s),
        # the longest move against the level's mean motion a step may hold (m), the unit
        # vector against gravity (what a point lies on is below it)
        thickness, friction, iterations, h, max_move, up,
        # in / out: the patches' boxes, ends and cones and the patches the last call moved
        # points of (:func:`patch_cache`); whether they hold this step's boxes as of the
        # last call, but at the patches of those points and of the points marked moved
        # (``reuse``: ``BOXES_NEW``, ``BOXES_KEPT`` or ``BOXES_KEPT_NEW_START``); the
        # blocks' boxes of those patches and whether
        # each patch has them; the longest edge at the start positions; the creases' flags
        # (bit 1: at the start positions, bit 2: at the end) and whether each patch has
        # them at the start and at the end; the calls' scratch arrays; the triangle each
        # point was last pushed off (see carry and _resolve_passes)
        boxes, ends, cones, touched, subs, subs_ready, start_edge, crease, crease_ready,
        scratch, carried, reuse,
        # input: the most an edge may bend (rad) and not be a crease, tested against the
        # other patches' edges (:func:`_crease_cosine`; 0: every bent edge)
        crease_angle=CREASE_ANGLE):
    """
    Keep a level's points ``thickness`` away from its triangles (see the module docstring).

    Returns ``(pairs, substeps, dropped, clean)``: the pairs found (point-triangle and
    edge pairs), the detection's sub-intervals, pairs beyond the per-step capacity (0
    normally) and whether the last round's detection found nothing (then ``q`` may be the
    ``q_from`` of the step's next call: nothing is near it, nothing crossed on the way).
    ``pairs`` is -1, and nothing is moved, when a point moved more than ``max_move``
    against the mean.
    """
    rows, cols = hold_kind.shape
    n = rows * cols
    if rows < 2 or cols < 2:
        return 0, 0, 0, True
    x1, x0, xs = q.reshape((3, n)), q_from.reshape((3, n)), q_prev.reshape((3, n))
    qdf, dvf, held_up = qd.reshape((3, n)), dv.reshape((3, n)), support.reshape((4, n))
    # the mean displacement; sub-intervals so that no point moves more than half the
    # longest edge relative to it in one
    if reuse == BOXES_KEPT_NEW_START:
        # the points not marked start where they end (as _still_sweeps takes them): the
        # moved ones' sums alone, the same numbers (a later call's two passes over the
        # level were a third of its time on the folded drop's sliding layers)
        moving = np.flatnonzero(moved)
        shift = _mean_move_of(x0, x1, moving)
        longest = _longest_move_of(x0, x1, moving, shift)
    else:
        shift = _mean_move(x0, x1)
        longest = _longest_move(x0, x1, 0.0, 1.0, shift)
    if reuse == BOXES_NEW:
        start_edge[0] = _longest_edge(x0, rows, cols)
        crease_ready[:, :, 0] = False
    # (the mean of the end positions' moves is finite only if all of them are)
    if not (math.isfinite(longest) and math.isfinite(shift[0] + shift[1] + shift[2])):
        return 0, 0, 0, False   # a blown-up step: the solver's check refuses it
    # the longest edge at the end only where it can matter: no move longer than the
    # longest edge at the start gives the fewest sub-intervals whatever the end's (a pass
    # over the level a call, 0.09 ms at 129 x 129; most calls of a cloth in contact)
    edge = start_edge[0]
    if not (0.0 < longest <= edge):
        edge = max(edge, _longest_edge(x1, rows, cols))
        if not math.isfinite(edge):
            return 0, 0, 0, False
    if longest > max_move:
        # a spring stretched across the cloth makes every patch meet every other: a
        # gripper sent 2.8 m in one step took 43 s of detection on 65 x 65
        return -1, 0, 0, False
    substeps = min(MAX_SUBSTEPS, max(MIN_SUBSTEPS, int(math.ceil(longest / (0.5 * edge)))))
    crease_cosine = _crease_cosine(thickness, start_edge[0], crease_angle)
    # the first detection tests only round the points marked moved (the caller's: those
    # that moved since its last call's first detection)
    _check_scratch(scratch, n)
    fresh = scratch.fresh
    fresh[:] = moved.reshape(n)
    fresh_blocks = _fresh_blocks(fresh, rows, cols)
    dirty = np.zeros(((rows - 2) // PATCH + 1, (cols - 2) // PATCH + 1), dtype=np.bool_)
    _dirty_patches(fresh_blocks, dirty)
    if boxes.shape[0] != dirty.shape[0] or boxes.shape[1] != dirty.shape[1]:
        raise ValueError('self_contact: the patch cache does not fit the level')
    # the patches whose boxes are out of date: those round points that moved since they
    # were computed. At this call's first detection: those the caller marks (moved since
    # the last call started) and those the last call moved points of (their boxes may be
    # of a position the point has left again, even for its start)
    stale = np.ones_like(dirty) if reuse == BOXES_NEW else dirty | touched
    if reuse == BOXES_KEPT_NEW_START:
        _flags_stale(crease_ready, 0, stale)
    touched[:, :] = False
    if subs.shape[:2] != fresh_blocks.shape or crease.shape[0] != 3 * n:
        raise ValueError('self_contact: the block cache does not fit the level')
    if reuse == BOXES_KEPT_NEW_START:
        _still_sweeps(boxes, ends, subs, subs_ready, stale, thickness)
    first, dropped, clean = _rounds(x0, xs, x1, qdf, dvf, mass, hold_kind, held_up, rows, cols,
                                    thickness, friction, iterations, h, substeps,
                                    crease_cosine, fresh, fresh_blocks, dirty, stale, touched,
                                    boxes, ends, cones, subs, subs_ready, crease, crease_ready,
                                    scratch, up, carried, False)
    return first, substeps, dropped, clean


@numba.njit(**JIT)
def _rounds(x0, xs, x1, qd, dv, mass, hold_kind, support, rows, cols, thickness, friction,
            iterations, h, substeps, crease_cosine, fresh, fresh_blocks, dirty, stale, touched,
            boxes, ends, cones, subs, subs_ready, crease, crease_ready, scratch, up, carried,
            surface):
    """
    Run rounds of detection and response (:func:`self_contact`); return (first, dropped, clean).

    ``clean``: the last detection found nothing (the rounds did not run out), so no point
    is within the thickness of a triangle at ``x1`` and none crossed one on the way there.

    The paths detected run from ``x0`` to ``x1``; the pushes' friction takes the sliding
    since ``xs`` (the step's start); their weights, the points' inverse masses, come from
    ``mass`` and ``hold_kind`` (made at the first pushes: most calls find nothing).
    ``fresh``, ``fresh_blocks``, ``dirty``: what the first detection tests round;
    ``stale``: the patches whose boxes are out of date; ``touched`` gains the patches the
    rounds moved points of. ``surface`` (:func:`settle`): ``x0`` is ``x1`` (the creases at
    the start move with the points) and a near pair takes the side the point's own
    surface lies on (:func:`_surface_side`).
    """
    pairs, sides = scratch.pairs, scratch.sides
    edge_pairs, edge_sides = scratch.edge_pairs, scratch.edge_sides
    # (what _rests keeps, made at the first pushes)
    x_rest, lay, no_room, asked = scratch.x_rest, scratch.lay, scratch.no_room, scratch.asked
    lies_on, stack, inv_mass = scratch.lies_on, scratch.stack, scratch.inv_mass
    first, dropped, clean = -1, 0, False
    # pairs are pushed a little further than detection looks: one pushed to exactly the
    # thickness would be found again by rounding, and every round would run
    target = thickness * (1.0 + SLACK)
    for attempt in range(iterations + 1):
        # pushing a pair apart can bring a point near another triangle: detect again
        _patch_boxes(x0, x1, rows, cols, PATCH, thickness, boxes, ends, cones, stale)
        subs_ready &= ~stale
        _flags_stale(crease_ready, 1, stale)
        if surface:
            _flags_stale(crease_ready, 0, stale)
        found, edges_found = _detect(x0, x1, rows, cols, thickness, substeps, dirty, fresh,
                                     fresh_blocks, pairs, sides, edge_pairs, edge_sides,
                                     boxes, ends, cones, subs, subs_ready, crease,
                                     crease_ready, crease_cosine)
        kept = min(found, pairs.shape[0])
        edges_kept = min(edges_found, edge_pairs.shape[0])
        first = found + edges_found if first < 0 else first
        dropped = max(dropped, found - kept + edges_found - edges_kept)
        if found + edges_found == 0:
            clean = True
            break
        if attempt == 0:
            _inverse_masses(mass, hold_kind, inv_mass)
        if not surface:
            # what rests on a layer that rests stays (see _rests), as of the first
            # pushes: the pushes alone read the room, so a call that finds nothing needs
            # none of it (the fold demo's later calls: a fifth of their time)
            if attempt == 0:
                x_rest[:, :] = x1
                lay[:] = carried
                for v in range(no_room.shape[0]):
                    no_room[v] = support[3, v] <= ROOM_TOLERANCE
                asked[:] = 0
            _rest_pairs(pairs, kept, edge_pairs, edges_kept, x_rest, no_room, lay, inv_mass,
                        support, rows, cols, thickness, up, asked, lies_on, stack)
        # the last round moves points alone: Gauss-Seidel over a cluster of pairs that
        # share vertices converges slowly (a fast fold left 1-3 of 300 pairs crossed
        # after 16 rounds)
        if surface:
            for e in range(kept):
                side = _surface_side(x1, pairs[e, 0], pairs[e, 1], rows, cols)
                if side != 0.0:
                    sides[e] = side
        fresh[:] = False
        _resolve_passes(xs, x1, qd, dv, inv_mass, support, cols, pairs, sides, kept,
                        target, friction, h, attempt == iterations, fresh, edge_pairs,
                        edge_sides, edges_kept, up, carried, scratch.stamps,
                        scratch.checked)
        fresh_blocks = _fresh_blocks(fresh, rows, cols)
        _dirty_patches(fresh_blocks, dirty)
        stale[:, :] = dirty
        touched |= dirty
    return first, dropped, clean


@numba.njit(**BORROW)
def _resolve_passes(x0, x1, qd, dv, inv_mass, support, cols, pairs, sides, kept, target,
                    friction, h, one_side, fresh, edge_pairs, edge_sides, edges_kept,
                    up, carried, stamps, checked):
    """
    ``RESOLVE_PASSES`` Gauss-Seidel passes over the pairs; mark in ``fresh`` the points they move.

    Each pass takes the point-triangle pairs, then the ``edges_kept`` edge pairs. A point
    pushed up off a triangle (the triangle's normal on its side within 45 degrees,
    ``UPWARD``, of ``up``) is noted in ``carried`` as lying on it (``2 t + 1`` on the side
    of its normal, ``2 t`` on the other; the last such push wins; see :func:`carry`). (Any
    push noted, a layer between two others, pushed down by the one above after it was
    pushed up, was noted on the one above, and was not carried.)

    A pair found apart is not tested again until a push moves one of its vertices: the
    test would find it apart again and do nothing, so the result is the same bit for bit
    (time counted in pushes: ``stamps`` (a point each) when a vertex last moved,
    ``checked`` (at least ``kept``) when a pair was found apart; scratch, set here). Most
    pairs are apart after the first pass.
    """
    for v in range(stamps.shape[0]):
        stamps[v] = 0
    for e in range(kept):
        checked[e] = -1
    pushes = 0
    for _ in range(RESOLVE_PASSES):
        for e in range(kept):
            p, t = np.int64(pairs[e, 0]), np.int64(pairs[e, 1])     # (held in 32 bits)
            i, j, k = _triangle(t, cols)
            if checked[e] >= 0 and \
                    max(max(stamps[p], stamps[i]), max(stamps[j], stamps[k])) <= checked[e]:
                continue
            if _resolve(x0, x1, qd, dv, inv_mass, support, cols, p, t, sides[e], target,
                        friction, h, one_side):
                pushes += 1
                if _faces(x1, t, sides[e], up, cols):
                    carried[p] = 2 * t + (1 if sides[e] > 0.0 else 0)
                for v in (p, i, j, k):
                    fresh[v] = True
                    stamps[v] = pushes
                checked[e] = -1
            else:
                checked[e] = pushes
        for e in range(edges_kept):
            if _resolve_edges(x0, x1, qd, dv, inv_mass, support, cols, edge_pairs[e, 0],
                              edge_pairs[e, 1], edge_sides[e], target, one_side):
                pushes += 1
                a, b = _edge(edge_pairs[e, 0], cols)
                c, d = _edge(edge_pairs[e, 1], cols)
                for v in (a, b, c, d):
                    fresh[v] = True
                    stamps[v] = pushes


@numba.njit(**BORROW)
def _faces(x, t, side, up, cols):
    """Whether triangle t's normal on ``side`` points within 45 degrees of ``up``."""
    nx, ny, nz = _triangle_normal(x, t, cols)
    along = (nx * up[0] + ny * up[1] + nz * up[2]) * (1.0 if side > 0.0 else -1.0)
    return along > UPWARD * math.sqrt(nx * nx + ny * ny + nz * nz)


# What _rests knows of a point: not yet asked, being asked (on its stack), rests, not
UNASKED, ASKING, RESTS, MOVES = 0, 1, 2, 3


@numba.njit(**BORROW)
def _lying_on(x, p, no_room, carried, inv_mass, support, rows, cols, thickness, up):
    """
    Return the triangle free point p lies on, if resting there may take its room, or -1.

    p has room left (not in ``no_room``) above an obstacle that faces up, is noted in
    ``carried`` (:func:`carry`) and still lies on that triangle (:func:`_track` at ``x``:
    on its noted side, the triangle facing up, at most ``1 + SLACK`` thicknesses above
    it).
    """
    code = carried[p]
    if code < 0 or inv_mass[p] == 0.0 or no_room[p]:
        return -1
    if support[0, p] * up[0] + support[1, p] * up[1] + support[2, p] * up[2] <= UPWARD:
        return -1
    side = 1.0 if code % 2 else -1.0
    t, plane = _track(x, p, code // 2, rows, cols)
    target = thickness * (1.0 + SLACK) * (1.0 + 1e-6)     # (pushed there, within rounding)
    if t < 0 or not 0.0 < side * plane[0] <= target or not _faces(x, t, side, up, cols):
        return -1
    return t


@numba.njit(**BORROW)
def _rests(v, x, no_room, carried, inv_mass, support, rows, cols, thickness, up, asked,
           lies_on, stack):
    """
    Settle whether point v rests on a layer that rests; if it does, take its room.

    A free point lying on a triangle (:func:`_lying_on`, at the call's first pushes:
    ``x``, ``no_room`` and ``carried`` as they were then) all of whose vertices have no
    room left or rest in turn, rests: it has no room left either (``support``), and a push
    from above moves what lies on it (:func:`_come_to_rest`, as a side pushed up off a
    resting side rests). The supports are taken anew before each call, so a point lying
    on a layer that lies on the ground had room left to it, and a push from a layer above
    moved it down into the layer it lay on: on the fold demo's sandwich (the top layer's
    rolled border between the bottom layer and its own roll) each side's pushes undid the
    other's, and a call took four detections.

    Asked for the pairs' vertices before their pushes (:func:`_rounds`): only the pushes
    read the room, and asking for every noted point (7,700 on the fold demo at 129 x 129,
    where a call pushes about 450) was 7 % of the kernel's time there. Depth first down
    the stack of layers (``asked``, ``lies_on`` and ``stack``: a point's state, triangle
    and the points being asked); points lying on each other in a ring do not rest (none
    of them can rest before the others), as passes over every point until none changed
    found.
    """
    if asked[v] != UNASKED:
        return
    top = 0
    stack[0] = v
    while top >= 0:
        p = stack[top]
        if asked[p] == UNASKED:
            t = _lying_on(x, p, no_room, carried, inv_mass, support, rows, cols, thickness,
                          up)
            if t < 0:
                asked[p] = MOVES
                top -= 1
                continue
            asked[p] = ASKING
            lies_on[p] = t
        i, j, k = _triangle(lies_on[p], cols)
        verdict = RESTS
        for w in (i, j, k):
            if no_room[w] or asked[w] == RESTS:
                continue
            verdict = ASKING if asked[w] == UNASKED else MOVES
            if verdict == ASKING:
                top += 1
                stack[top] = w
            break
        if verdict == ASKING:
            continue
        asked[p] = verdict
        if verdict == RESTS:
            support[3, p] = 0.0
        top -= 1


@numba.njit(**BORROW)
def _rest_pairs(pairs, kept, edge_pairs, edges_kept, x, no_room, carried, inv_mass, support,
                rows, cols, thickness, up, asked, lies_on, stack):
    """Settle, for every vertex of the pairs to be pushed, whether it rests (:func:`_rests`)."""
    for e in range(kept):
        i, j, k = _triangle(pairs[e, 1], cols)
        for v in (np.int64(pairs[e, 0]), i, j, k):
            _rests(v, x, no_room, carried, inv_mass, support, rows, cols, thickness, up, asked,
                   lies_on, stack)
    for e in range(edges_kept):
        a, b = _edge(edge_pairs[e, 0], cols)
        c, d = _edge(edge_pairs[e, 1], cols)
        for v in (a, b, c, d):
            _rests(v, x, no_room, carried, inv_mass, support, rows, cols, thickness, up, asked,
                   lies_on, stack)


@numba.njit(**BORROW)
def _inverse_masses(mass, hold_kind, inv_mass):
    """Write the points' inverse masses into ``inv_mass``, flat (0 for held points)."""
    rows, cols = hold_kind.shape
    for r in range(rows):
        for c in range(cols):
            inv_mass[r * cols + c] = 0.0 if hold_kind[r, c] != FREE else 1.0 / mass[r, c]


@numba.njit(**BORROW)
def _next_to(t, vertex, rows, cols):
    """
    Return the triangle across triangle t's edge opposite its vertex ``vertex`` (0-2), or -1.

    -1 on the grid's border. The two triangles of a cell (see the module docstring) and
    their neighbours: the first's edges border the second (its diagonal), the cell on the
    right's second and the cell above's second; the second's the first, the cell below's
    first and the cell on the left's first.
    """
    cell = t // 2
    r, c = cell // (cols - 1), cell % (cols - 1)
    if t % 2 == 0:
        if vertex == 1:
            return t + 1
        if vertex == 0:
            return 2 * (cell + 1) + 1 if c + 1 <= cols - 2 else -1
        return 2 * (cell - (cols - 1)) + 1 if r >= 1 else -1
    if vertex == 2:
        return t - 1
    if vertex == 0:
        return 2 * (cell + cols - 1) if r + 1 <= rows - 2 else -1
    return 2 * (cell - 1) if c >= 1 else -1


@numba.njit(**BORROW)
def _track(x, p, t, rows, cols):
    """
    Return the triangle p's projection lies in, walking from t across the grid, or -1.

    With p's plane (:func:`_plane`'s seven numbers) of that triangle (zeros with -1).

    At most ``WALKS`` triangles on, each across the edge beyond which the projection lies
    farthest (its most negative barycentric weight); within ``INSIDE`` of a triangle is
    in it, and so is a projection past the grid's border within ``BEYOND`` of the triangle
    on it (a layer's free edge lying on another's, overhanging it a little: a cloth folded
    in half, its far edge on its near one, where the top edge, let go, sank every step
    and was pushed out again). -1 when the walk leaves the grid farther out, comes within
    ``RING`` rows and columns of p (its own surface, see the module docstring) or does not
    arrive. All triangles of the grid turn the same way, so p's side of the one it
    arrives at is its side of t's.
    """
    pr, pc = p // cols, p % cols
    none = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    for walked in range(WALKS + 1):
        cell = t // 2
        r, c = cell // (cols - 1), cell % (cols - 1)
        if pr - 1 - RING <= r <= pr + RING and pc - 1 - RING <= c <= pc + RING:
            return -1, none
        i, j, k = _triangle(t, cols)
        plane = _plane(_point(x, p), _point(x, i), _point(x, j), _point(x, k))
        low = min(plane[4], plane[5], plane[6])
        if low >= -INSIDE:
            return t, plane
        if walked == WALKS:
            return -1, none
        nxt = _next_to(t, 0 if plane[4] == low else (1 if plane[5] == low else 2), rows,
                       cols)
        if nxt < 0:
            return (t, plane) if low >= -BEYOND else (-1, none)
        t = nxt
    return -1, none


@numba.njit(**JIT)
def carry(q, qd, dv, q_prev, mass, hold_kind, support, carried, up, thickness, friction,
          h, scratch):
    """
    Keep the points lying on a layer on it, before the step's detection; return how many moved.

    ``q``, ``qd``, ``dv``: the level after the step (corrected in place), ``q_prev`` its
    start; ``support``: the obstacles below (see :func:`self_contact`); ``carried``: the
    triangle each point was last pushed up off (:func:`_resolve_passes`), updated here;
    ``up``: the unit vector against gravity; ``scratch``: the patch cache's
    (:func:`patch_cache`).

    A layer lying on another sinks into it every step (``g h^2`` from rest; the solvers
    do not know the layer below) and self-contact, finding it within the thickness,
    pushed it out again: every point of it a pair, every step (33,000-39,000 pairs and
    34 ms a step on a folded 129 x 129 cloth at rest). Here each point is followed on the
    triangle it was last pushed up off (:func:`_track` at the start positions, where the
    last check left it; it has left the triangle when it lies on the other side or more
    than ``REACH`` thicknesses above it) and, where that triangle faces up (within 45
    degrees, ``UPWARD``), pushed back up to ``1 + SLACK`` thicknesses above it at the end
    of the step (:func:`_bear`), as the detection would push that pair, without
    detecting it: the layer below bears the point. The detection after it then finds
    what else came near (a faster fall, a press, another layer's edge) and not, every
    step, the whole layer. A stack is carried from the bottom up: a point after the
    vertices of its triangle, so that each layer, once lifted off one that rests, rests
    in turn (:func:`_come_to_rest`) and the next one up is lifted alone, as the
    detection's pushes resolve a stack.
    """
    rows, cols = hold_kind.shape
    n = rows * cols
    if rows < 2 or cols < 2:
        return 0
    x1, x0 = q.reshape((3, n)), q_prev.reshape((3, n))
    qdf, dvf, held_up = qd.reshape((3, n)), dv.reshape((3, n)), support.reshape((4, n))
    _check_scratch(scratch, n)
    inv_mass, waiting = scratch.inv_mass, scratch.waiting
    _inverse_masses(mass, hold_kind, inv_mass)
    waiting[:] = False
    return _carry_points(x0, x1, qdf, dvf, inv_mass, held_up, carried, up, thickness,
                         friction, h, rows, cols, waiting)


@numba.njit(**BORROW)
def _carry_points(x0, x1, qd, dv, inv_mass, support, carried, up, thickness, friction, h,
                  rows, cols, waiting):
    """
    Run :func:`carry` on its flat arrays (``waiting`` all False); return how many moved.

    Apart from :func:`carry`'s views of its arrays, so that it only borrows them (compiled
    without reference counting, as :func:`_sweep`): counting the arrays handed to each
    point's tracking and push was half of the time of a carry (the fold demo's 7,700
    points lying on the layer below, 129 x 129).
    """
    n = rows * cols
    # each point followed onto the triangle under it at the start; those lying on one
    # that faces up wait for their turn
    for p in range(n):
        code = carried[p]
        if code < 0:
            continue
        side = 1.0 if code % 2 else -1.0
        t, plane = _track(x0, p, code // 2, rows, cols)
        if t < 0 or inv_mass[p] == 0.0:
            carried[p] = -1
            continue
        above, nx, ny, nz = plane[0], plane[1], plane[2], plane[3]
        if not 0.0 < side * above <= REACH * thickness:
            carried[p] = -1
            continue
        carried[p] = 2 * t + code % 2
        waiting[p] = side * (nx * up[0] + ny * up[1] + nz * up[2]) > UPWARD
    # from the bottom of a stack up: a point's turn comes when no vertex of its triangle
    # waits (it rests, or is carried already); what is left when no turn comes (points
    # lying on each other in a ring) in the order of the points
    count, left, ring = 0, int(waiting.sum()), False
    while left:
        turns = 0
        for p in range(n):
            if not waiting[p]:
                continue
            i, j, k = _triangle(carried[p] // 2, cols)
            if not ring and (waiting[i] or waiting[j] or waiting[k]):
                continue
            waiting[p] = False
            turns += 1
            if _bear(x0, x1, qd, dv, inv_mass, support, p, carried[p] // 2,
                     1.0 if carried[p] % 2 else -1.0, up, thickness, friction, rows, cols,
                     h):
                count += 1
        left -= turns
        ring = turns == 0
    return count


@numba.njit(**BORROW_INLINE)
def _bear(x0, x1, qd, dv, inv_mass, support, p, t, side, up, thickness, friction, rows,
          cols, h):
    """
    Push p up off the triangle under it (tracked from t, p on its ``side``) to 1 + SLACK.

    Returns whether it pushed. See :func:`carry`. At the end of the step p is followed
    again from t (:func:`_track`: it may have slid onto the next triangle; past the
    layer's edge it falls freely). The push is self-contact's own (:func:`_push`: shared
    by inverse masses, so a layer lying on a hanging layer weighs it down; held points stay
    unless nothing else can move, and so do points with no room left to their obstacle;
    inelastic), at p's projection
    clipped into the triangle, along its normal, and so is the friction (:func:`_rub`, up
    to ``friction`` times the push: under a point that only fell onto it, Coulomb's law
    under its weight). A second push when the first left the pair short: a vertex of the
    triangle that reached its obstacle on the way stopped there (:func:`_room`) and now
    rests, so p moves alone. A point that ended more than a thickness below the plane, or
    on a triangle that no longer faces up, is left to the detection.
    """
    t, plane = _track(x1, p, t, rows, cols)
    if t < 0:
        return False
    i, j, k = _triangle(t, cols)
    target = thickness * (1.0 + SLACK)
    pushed = False
    for again in range(2):
        if again:
            plane = _plane(_point(x1, p), _point(x1, i), _point(x1, j), _point(x1, k))
        sd, nx, ny, nz, u, v, w = plane
        sd, nx, ny, nz = side * sd, side * nx, side * ny, side * nz
        if not (nx * up[0] + ny * up[1] + nz * up[2] > UPWARD and
                -thickness < sd < target - ROOM_TOLERANCE):
            break
        lift = target - sd
        u, v, w = max(u, 0.0), max(v, 0.0), max(w, 0.0)
        total = u + v + w
        if not total > 0.0:
            break
        u, v, w = u / total, v / total, w / total
        verts, weights = (p, i, j, k), (1.0, -u, -v, -w)
        motion = _motion(x0, x1, verts, weights)
        lam, denom, ip, ii, ij, ik = _push(x1, qd, dv, inv_mass, support, verts, weights, 1,
                                           nx, ny, nz, -lift, False)
        if not denom > 0.0:
            break
        if friction > 0.0:
            _rub(x1, qd, dv, support, verts, (u, v, w), (ip, ii, ij, ik), lam, denom, motion,
                 (nx, ny, nz), friction * lift, h)
        pushed = True
    return pushed


@numba.njit(**BORROW)
def _surface_side(x, p, t, rows, cols):
    """
    Return the side (+-1) of triangle t's plane that p's own surface lies on, or 0.

    The sum of the signed distances to the plane of p and of the points within ``RING``
    rows and columns of it, the cloth round p (see :func:`settle`); 0 when they sum to
    nothing (a degenerate triangle). Where two layers lie a thickness apart the cloth
    round a point lies on its side; where a coarser level laid a point level with another
    layer at a tight crease, its neighbours back from the crease still lie above.
    """
    i, j, k = _triangle(t, cols)
    ax, ay, az = x[0, i], x[1, i], x[2, i]
    ux, uy, uz = x[0, j] - ax, x[1, j] - ay, x[2, j] - az
    vx, vy, vz = x[0, k] - ax, x[1, k] - ay, x[2, k] - az
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    pr, pc = p // cols, p % cols
    total = 0.0
    for r in range(max(0, pr - RING), min(rows, pr + RING + 1)):
        for c in range(max(0, pc - RING), min(cols, pc + RING + 1)):
            q = r * cols + c
            total += nx * (x[0, q] - ax) + ny * (x[1, q] - ay) + nz * (x[2, q] - az)
    return 1.0 if total > 0.0 else (-1.0 if total < 0.0 else 0.0)


@numba.njit(**JIT)
def settle(q, mass, hold_kind, support, thickness, iterations, boxes, ends, cones, touched,
           subs, subs_ready, start_edge, crease, crease_ready, scratch, carried):
    """
    Push a level restarted from the coarser one out of its own triangles; return the pairs found.

    ``q`` (3, rows, cols) is corrected in place (velocities are not changed); ``support``
    and the patch cache (:func:`patch_cache`, recomputed) as :func:`self_contact`'s.

    A level that comes back is the coarser level's surface prolonged, and the coarser
    level's self-contact skipped the triangles within ``RING`` of its rows and columns,
    twice as far on the cloth as the finer level's: at a crease tighter than that the
    coarser level may lay the two layers in each other's first cells (the fold demo's
    33 x 33 crease left top-layer points on the ground in the bottom layer's first cell,
    level with it). With no motion to tell which side such a point came from, a pair
    found near takes the side the point's own surface lies on (:func:`_surface_side`),
    not the side of the plane the point happens to be on, and is pushed apart as the
    detection's pairs are: rounds of a static detection (the start positions the end
    ones) and ``RESOLVE_PASSES`` passes, until none is found or ``iterations`` rounds
    ran. A point more than about a thickness through the other layer is left as it is
    (as :func:`_resolve` leaves it).
    """
    rows, cols = hold_kind.shape
    n = rows * cols
    if rows < 2 or cols < 2:
        return 0
    x = q.reshape((3, n))
    if not np.all(np.isfinite(x)):
        return 0
    qd, dv = np.zeros((3, n)), np.zeros((3, n))   # pushes move positions alone
    subs_ready[:, :] = False
    crease_ready[:, :, :] = False
    # no creases: they are tested for crossings alone, and nothing moves here (a bound
    # would cost a pass over the level for edge tests that cannot find a pair)
    crease_cosine = -1.0
    _check_scratch(scratch, n)
    fresh = scratch.fresh
    fresh[:] = True
    fresh_blocks = _fresh_blocks(fresh, rows, cols)
    dirty = np.zeros(((rows - 2) // PATCH + 1, (cols - 2) // PATCH + 1), dtype=np.bool_)
    _dirty_patches(fresh_blocks, dirty)
    first = _rounds(x, x, x, qd, dv, mass, hold_kind, support.reshape((4, n)), rows, cols,
                    thickness, 0.0, iterations, 1.0, MIN_SUBSTEPS, crease_cosine, fresh,
                    fresh_blocks, dirty, dirty.copy(), touched, boxes, ends, cones, subs,
                    subs_ready, crease, crease_ready, scratch, np.zeros(3), carried, True)[0]
    touched[:, :] = True        # the boxes are the settled positions', not a step's
    return first


def patch_cache(rows, cols):
    """
    Return what :func:`self_contact` keeps between calls (:func:`carry` between steps).

    The patch boxes, ends, cones and moved patches, the blocks' boxes and which patches
    have theirs, the longest edge at the start positions, the creases' flags and which
    patches have theirs at the start and at the end positions, the calls' scratch arrays
    (:class:`Scratch`) and the triangle each point lies on (-1: none).
    """
    pr, pc = (rows - 2) // PATCH + 1, (cols - 2) // PATCH + 1
    blocks = ((rows - 2) // SUB + 1, (cols - 2) // SUB + 1)
    return (np.empty((pr, pc, 6)), np.empty((pr, pc, 15)), np.empty((pr, pc, 4)),
            np.zeros((pr, pc), dtype=np.bool_), np.empty(blocks + (12,)),
            np.zeros((pr, pc), dtype=np.bool_), np.zeros(1),
            np.zeros(3 * rows * cols, dtype=np.uint8), np.zeros((pr, pc, 2), dtype=np.bool_),
            scratch(rows, cols), np.full(rows * cols, -1, dtype=np.int64))


# The arrays a call works in, whose contents it sets before it reads them (none carries
# anything from one call to the next). Kept with the patch cache, not made a call: a
# level's arrays made afresh were mapped afresh, and the first touch of each page faulted
# (about 200 pages, 0.56 ms, of a sliding call's 2.2 ms on the folded drop at 129 x 129,
# 2.8 us a fault on this machine's virtual memory: doc/self_contact_log.md, session 47).
# The pairs found and their sides; the edge pairs and theirs; the positions, notes of
# what lies on what, rooms used up, answers and stacks of :func:`_rests`; the inverse
# masses; the pushes' time stamps (a point each) and the pairs' (a pair each); the points
# a detection tests round; the points :func:`carry` has yet to bear.
Scratch = collections.namedtuple('Scratch', (
    'pairs', 'sides', 'edge_pairs', 'edge_sides', 'x_rest', 'lay', 'no_room', 'asked',
    'lies_on', 'stack', 'inv_mass', 'stamps', 'checked', 'fresh', 'waiting'))


@numba.njit(**JIT)
def _check_scratch(scratch, n):
    """
    Refuse scratch arrays made for a level of other than ``n`` points.

    The kernels do not test their indices: arrays too small would be written past.
    """
    if scratch.fresh.shape[0] != n or scratch.pairs.shape[0] != PAIRS_PER_POINT * n:
        raise ValueError('self_contact: the scratch arrays do not fit the level')


def scratch(rows, cols):
    """
    Return the :class:`Scratch` arrays of a level of ``rows`` x ``cols`` points.

    The pairs, the edge pairs, the stamps and the pairs' checks in 32-bit integers (a
    level's triangles and a call's pushes stay far below 2**31): half of the 64-bit ones'
    memory, the pairs' capacity most of it.
    """
    n = rows * cols
    # free edges' pairs, and one a point for the creases'
    edge_capacity = EDGE_PAIRS_PER_EDGE * 2 * (rows + cols) + n
    points = np.empty(n, dtype=np.int64)
    return Scratch(
        np.empty((PAIRS_PER_POINT * n, 2), dtype=np.int32), np.empty(PAIRS_PER_POINT * n),
        np.empty((edge_capacity, 2), dtype=np.int32), np.empty(edge_capacity),
        np.empty((3, n)), points, np.empty(n, dtype=np.bool_), np.empty(n, dtype=np.int8),
        points.copy(), points.copy(), np.empty(n), np.empty(n, dtype=np.int32),
        np.empty(PAIRS_PER_POINT * n, dtype=np.int32), np.empty(n, dtype=np.bool_),
        np.empty(n, dtype=np.bool_))


@numba.njit(**JIT)
def _mean_move(x0, x1):
    """
    Return the mean displacement from ``x0`` to ``x1`` (3, n).

    The three sums in one pass, each in the order of the points as before: a pass a
    coordinate waited for each addition in turn (0.042 against 0.015 ms at 129 x 129).
    """
    sx = sy = sz = 0.0
    for i in range(x0.shape[1]):
        sx += x1[0, i] - x0[0, i]
        sy += x1[1, i] - x0[1, i]
        sz += x1[2, i] - x0[2, i]
    n = x0.shape[1]
    return np.array([sx / n, sy / n, sz / n])


@numba.njit(**JIT)
def _mean_move_of(x0, x1, points):
    """:func:`_mean_move` where only ``points`` (ascending) move: its sums, less their zeros."""
    sx = sy = sz = 0.0
    for p in points:
        sx += x1[0, p] - x0[0, p]
        sy += x1[1, p] - x0[1, p]
        sz += x1[2, p] - x0[2, p]
    n = x0.shape[1]
    return np.array([sx / n, sy / n, sz / n])


@numba.njit(**JIT)
def obstacle_supports(planes, boxes, margin, q, out):
    """
    Write into ``out`` (4, rows, cols) the obstacle below each point and its room to it.

    ``planes`` (P, 4) and ``boxes`` (B, 6) as :class:`~hcloth_ros.core.scene.Scene` holds
    them; see :func:`~hcloth_ros.core.self_contact.supports` for what is written. A point
    at a time: numpy's passes over the level took ten times as long (0.40 against 0.04 ms
    a call on the folded drop's 129 x 129 level with a ground, doc/self_contact_log.md;
    three calls a step in contact).
    """
    rows, cols = q.shape[1], q.shape[2]
    for r in range(rows):
        for c in range(cols):
            x, y, z = q[0, r, c], q[1, r, c], q[2, r, c]
            nx = ny = nz = 0.0
            best = np.inf
            for m in range(planes.shape[0]):
                room = max(planes[m, 0] * x + planes[m, 1] * y + planes[m, 2] * z
                           - planes[m, 3] - margin, 0.0)
                if room < best:
                    nx, ny, nz, best = planes[m, 0], planes[m, 1], planes[m, 2], room
            for m in range(boxes.shape[0]):
                height = z - (boxes[m, 2] + boxes[m, 5])
                if abs(x - boxes[m, 0]) < boxes[m, 3] + margin and \
                        abs(y - boxes[m, 1]) < boxes[m, 4] + margin and height >= -margin:
                    room = max(height - margin, 0.0)
                    if room < best:
                        nx, ny, nz, best = 0.0, 0.0, 1.0, room
            out[0, r, c], out[1, r, c], out[2, r, c], out[3, r, c] = nx, ny, nz, best


@numba.njit(**BORROW)
def _still_sweeps(boxes, ends, subs, subs_ready, stale, reach):
    """
    Cut the kept boxes of the patches not ``stale`` down to where their points are, unmoving.

    For a call whose paths start where the last clean call left the level: the points of
    such a patch have not moved since its boxes were swept, so they start and end where
    that sweep ended. Its boxes (:func:`_patch_boxes`, ``boxes`` grown by ``reach``) and
    its blocks' (``subs``, where ``subs_ready``) become their end's, at both ends, and
    the patch's motion none. Kept whole, a sweep's motion moved the frame a pair's boxes are
    taken in (:func:`_moving_box`), and its start box, shifted with it, need not hold the
    points' start: a patch that fell a centimetre in the sweep lay, in that frame, half a
    centimetre from its points at the start of the call.
    """
    pr, pc = boxes.shape[0], boxes.shape[1]
    per = PATCH // SUB
    for bi in range(pr):
        for bj in range(pc):
            if stale[bi, bj]:
                continue
            for d in range(6):
                ends[bi, bj, d] = ends[bi, bj, 6 + d]
            for d in range(3):
                ends[bi, bj, 12 + d] = 0.0
                boxes[bi, bj, d] = ends[bi, bj, d] - reach
                boxes[bi, bj, 3 + d] = ends[bi, bj, 3 + d] + reach
            if not subs_ready[bi, bj]:
                continue
            for si in range(bi * per, min((bi + 1) * per, subs.shape[0])):
                for sj in range(bj * per, min((bj + 1) * per, subs.shape[1])):
                    for d in range(6):
                        subs[si, sj, d] = subs[si, sj, 6 + d]


@numba.njit(**BORROW)
def _dirty_patches(fresh_blocks, dirty):
    """Mark in ``dirty`` the patches holding a block of ``fresh_blocks`` (only those)."""
    per = PATCH // SUB
    dirty[:, :] = False
    for si in range(fresh_blocks.shape[0]):
        for sj in range(fresh_blocks.shape[1]):
            if fresh_blocks[si, sj]:
                dirty[si // per, sj // per] = True
