"""
Strain limiting for the contact rounds: points lying on an obstacle move along its surface.

The rounds of :meth:`~hcloth_ros.core.solvers.Solver._wrap` alternate strain limiting and
contact on a level draped over an obstacle. A spring bridging a box's edge (one end on the
top, the other on a side face) is shortened by moving its ends towards each other, into
the box; contact then pushes each end back out along its face's normal and undoes that
part of the correction, so the spring stays long: at 129 x 129 on the table scene these
springs sat at 0.17 mean strain (up to 0.29) while the springs beside them were within the
limit (issue 10's note). Here a point lying on an obstacle (within ``BAND`` of its grown
surface, outside it) moves only within the surface's tangent plane, or away from it, and
the spring's correction is scaled so that the moves it keeps shorten the spring to its
limit (position-based projection with the gradients restricted to those planes).

Gauss-Seidel over the structural and shear springs (stencil directions 0, 2, 4, 6), row
by row: each correction is seen by the next spring, so a correction travels along a flap
within one sweep instead of one point a sweep. Against the sweeps' order it still travels
one spring a sweep: where held points pull a whole sheet (a finger dragging the cloth)
and the sweeps do not settle, the points are tethered to them (:func:`_tether`).
Velocities and the step's velocity change take each move divided by ``h``, as
:mod:`~hcloth_ros.core.kernels.strain` does.
"""

import math

from hcloth_ros.core.kernels.bodies import _grown_reach, _inside, _off_core, _pressed, \
    _rotate, _to_local, BOX, FRICTION, KIND, R_END, SIZE, T_END
from hcloth_ros.core.kernels.jit import BORROW, JIT
from hcloth_ros.core.kernels.layout import FREE, STENCIL_DC, STENCIL_DR
import numba
import numpy as np

# A point lies on an obstacle when it is within this distance (m) of its grown surface
# (the obstacle plus the contact margin), outside it: contact leaves points exactly on
# that surface, strain limiting a fraction of a millimetre off it.
BAND = 0.0005
# A spring whose kept moves shorten it by less than this fraction of a free spring's rate
# is skipped (both ends pinned against faces the spring is normal to: no move can help).
SMALLEST_RATE = 0.05
# A spring whose kept moves shorten it at more than this fraction of a free spring's rate
# is over-relaxed (see tangent_strain_limit); one whose moves its surfaces bend is not.
FREE_RATE = 0.9
# Columns of a row a sweep skips or looks at together (see tangent_strain_limit).
RUN = 16
# Sweeps before the points are tethered to the held ones (see tangent_strain_limit): on
# the contact bench's finger at 257 x 257 46 ms a step with 8 or 16, 58 with 0 or 32 (one
# run each, with two scans of the anchors' propagation instead of the four it has).
TETHER_AFTER = 8
# The spring directions limited: right, down, down-right, down-left.
DIRECTIONS = np.array([0, 2, 4, 6])
STEP_ROWS = np.asarray(STENCIL_DR)[DIRECTIONS].astype(np.int64)
STEP_COLS = np.asarray(STENCIL_DC)[DIRECTIONS].astype(np.int64)


@numba.njit(**BORROW)
def _box_face(x, y, z, hx, hy, hz, margin):
    """
    Outward normal of the face of a box at the origin (half extents h) a point lies on.

    ``(found, nx, ny, nz)``: a point on the top, within its x and y extent, takes +z; on a
    side face, below the top, that face's normal; away from the box or inside it, none
    (inside is contact's business).
    """
    out_x = abs(x) - hx - margin
    out_y = abs(y) - hy - margin
    out_z = abs(z) - hz - margin
    if not -BAND < max(out_x, out_y, out_z) < BAND:
        return False, 0.0, 0.0, 0.0
    if out_z > -BAND:
        return True, 0.0, 0.0, 1.0 if z > 0.0 else -1.0
    if out_x > -BAND:
        return True, 1.0 if x > 0.0 else -1.0, 0.0, 0.0
    return True, 0.0, 1.0 if y > 0.0 else -1.0, 0.0


@numba.njit(**BORROW)
def _round_face(ox, oy, oz, radius, margin):
    """
    Outward normal of a sphere's surface (``radius``) a point lies on, offset o from its centre.

    ``(found, nx, ny, nz)``; none off the surface grown by the margin (or at the centre).
    """
    dist = math.sqrt(ox * ox + oy * oy + oz * oz)
    if not (dist > 0.0 and abs(dist - radius - margin) < BAND):
        return False, 0.0, 0.0, 0.0
    return True, ox / dist, oy / dist, oz / dist


@numba.njit(**BORROW)
def _body_normal(b, x, y, z, margin):
    """
    Outward normal (world) of moving body row b's surface where a point lies, at the step's end.

    ``(found, nx, ny, nz)``; a box as :func:`_box_face` in the body's frame, a sphere or
    capsule as :func:`_round_face` from the nearest point of its core.
    """
    lx, ly, lz = _to_local(b, R_END, T_END, x, y, z)
    if int(b[KIND]) == BOX:
        found, nx, ny, nz = _box_face(lx, ly, lz, b[SIZE], b[SIZE + 1], b[SIZE + 2], margin)
    else:
        ox, oy, oz = _off_core(b, lx, ly, lz)
        found, nx, ny, nz = _round_face(ox, oy, oz, b[SIZE], margin)
    if not found:
        return False, 0.0, 0.0, 0.0
    nx, ny, nz = _rotate(b, R_END, nx, ny, nz)
    return True, nx, ny, nz


@numba.njit(**BORROW)
def _without_into(mx, my, mz, found, nx, ny, nz):
    """Return the move (mx, my, mz) less its part into a surface of outward normal n (if found)."""
    into = mx * nx + my * ny + mz * nz
    if found and into < 0.0:
        return mx - into * nx, my - into * ny, mz - into * nz
    return mx, my, mz


@numba.njit(**BORROW)
def _kept(q, r, c, mx, my, mz, planes, boxes, spheres, bodies, margin):
    """
    Return the move (mx, my, mz) of point (r, c) without its parts into the surfaces it lies on.

    Every surface the point lies on takes its part out in turn (planes, the boxes' faces
    (:func:`_box_face`), spheres (:func:`_round_face`), then the moving bodies where they
    are at the end of the step): a point on the ground under a finger moves along both,
    where with only one surface kept it could be moved into the other. (On the contact
    bench's finger scene the largest strain was 1.02 either way, ``hcloth_contact_bench
    --sizes 129 --steps 60 --intervals 1 --rounds 16 --option contact_sweeps=100``: the
    points the finger pressed moved, and were put back; 0.11 since they stay put,
    :func:`_held`.)

    The surfaces are found where the point is now, not once a round: with the normals
    taken at the start of each round the 129 x 129 table drop reached 0.252 (0.171 this
    way) and 0.105-0.211 over its last 3 s (``tools/table_flaps.py multigrid --levels 5
    --option contact_strain=tangent --option contact_sweeps=100``, one run each),
    presumably as a point pulled off a face during the sweeps kept that face's normal.
    """
    x, y, z = q[0, r, c], q[1, r, c], q[2, r, c]
    for p in range(planes.shape[0]):
        gap = x * planes[p, 0] + y * planes[p, 1] + z * planes[p, 2] - planes[p, 3] - margin
        mx, my, mz = _without_into(mx, my, mz, -BAND < gap < BAND, planes[p, 0],
                                   planes[p, 1], planes[p, 2])
    for b in range(boxes.shape[0]):
        found, nx, ny, nz = _box_face(x - boxes[b, 0], y - boxes[b, 1], z - boxes[b, 2],
                                      boxes[b, 3], boxes[b, 4], boxes[b, 5], margin)
        mx, my, mz = _without_into(mx, my, mz, found, nx, ny, nz)
    for s in range(spheres.shape[0]):
        found, nx, ny, nz = _round_face(x - spheres[s, 0], y - spheres[s, 1],
                                        z - spheres[s, 2], spheres[s, 3], margin)
        mx, my, mz = _without_into(mx, my, mz, found, nx, ny, nz)
    for b in range(bodies.shape[0]):
        if _far_from(bodies[b], x, y, z, margin + BAND):
            continue
        found, nx, ny, nz = _body_normal(bodies[b], x, y, z, margin)
        mx, my, mz = _without_into(mx, my, mz, found, nx, ny, nz)
    return mx, my, mz


@numba.njit(**BORROW)
def _far_from(b, x, y, z, grow):
    """
    Whether a point is outside the sphere holding body row b grown by ``grow``.

    The sphere of :func:`.bodies._grown_reach`, with a margin for rounding: outside it a
    point lies on none of the grown surface and inside none of it. Most points strain
    limiting looks at on a cloth a finger drags lie far from the finger, and skip its
    frame change.
    """
    far = _grown_reach(b, grow) * (1.0 + 1e-9)
    dx, dy, dz = x - b[T_END], y - b[T_END + 1], z - b[T_END + 2]
    return dx * dx + dy * dy + dz * dz > far * far


@numba.njit(**BORROW)
def _held(q, r, c, bodies, planes, plane_friction, margin):
    """
    Whether a moving body presses point (r, c) into a plane and friction holds it there.

    The moving bodies' contact puts such a point back where the body's motion (or the
    plane) holds it whatever strain limiting did (:func:`.bodies._respond`), so a move of
    it here is undone and its spring's other end must take the whole correction. Moved
    like a free point, pressed points under the contact bench's finger were put back
    every round and held the springs between them and their free neighbours at 0.63
    strain (1.02 at the worst step).
    """
    x, y, z = q[0, r, c], q[1, r, c], q[2, r, c]
    for i in range(bodies.shape[0]):
        b = bodies[i]
        if b[FRICTION] == 0.0 and plane_friction == 0.0:
            continue        # neither surface holds it
        if _far_from(b, x, y, z, margin):
            continue        # not inside it
        lx, ly, lz = _to_local(b, R_END, T_END, x, y, z)
        if _inside(b, margin, lx, ly, lz) and \
                _pressed(q, r, c, b, planes, margin, lx, ly, lz)[0] > 0.0:
            return True
    return False


@numba.njit(**BORROW)
def _held_once(q, r, c, held, bodies, planes, plane_friction, margin):
    """
    :func:`_held` of point (r, c), decided the first time a call asks (``held``: 0 not yet).

    Asked at every spring end over its limit, the check (a body's frame and depth) took 37 %
    of the contact bench's finger scene's sweeps; made for every point at the start of a
    call it would cost a pass over the level where no spring is over. A held point does not
    move in the sweeps, so it stays held; a free one that slides under the body afterwards
    is moved as free, and the body's contact, which runs after strain limiting, holds it.
    """
    if held[r, c] == 0:
        held[r, c] = 1 if _held(q, r, c, bodies, planes, plane_friction, margin) else 2
    return held[r, c] == 1


@numba.njit(**BORROW)
def _shift(q, qd, dv, r, c, lam, mx, my, mz, h):
    """Move point (r, c) by ``lam`` times (mx, my, mz); its velocities follow."""
    for d, m in ((0, mx), (1, my), (2, mz)):
        q[d, r, c] += lam * m
        qd[d, r, c] += lam * m / h
        dv[d, r, c] += lam * m / h


@numba.njit(**BORROW)
def _touch(r, c, rows, cols, now, later):
    """
    Mark the runs of the springs with an end at point (r, c), which moved.

    Those springs start at the point, left of it, above it, above left and above right
    (the directions go right and down). Marked for this sweep (those after the point in
    its order) and for the next (those before it); a run marked more than needed only
    looks at springs within their limit again.
    """
    for dr, dc in ((0, 0), (0, -1), (-1, 0), (-1, -1), (-1, 1)):
        sr, sc = r + dr, c + dc
        if 0 <= sr < rows and 0 <= sc < cols:
            now[sr, sc // RUN] = True
            later[sr, sc // RUN] = True


@numba.njit(**BORROW)
def _anchors(q, hold_kind, held, bodies, planes, plane_friction, margin, anchor):
    """
    Mark the points no sweep moves: held by a grip or a pin, or pressed by a body (_held).

    ``anchor[:, r, c]``: the point's own row and column if it is one, else -1. Decides
    :func:`_held` (into ``held``) for the free points near a body; returns how many there
    are.
    """
    rows, cols = hold_kind.shape
    pressing = bodies.shape[0] > 0 and planes.shape[0] > 0
    count = 0
    for r in range(rows):
        for c in range(cols):
            fixed = hold_kind[r, c] != FREE
            if not fixed and pressing:
                # _held culls the bodies a point is far from too, but a call a point (its
                # array arguments, the held flag written) took 3.1 ms of a 257 x 257
                # level against 0.6 with the cull here first
                for b in range(bodies.shape[0]):
                    if not _far_from(bodies[b], q[0, r, c], q[1, r, c], q[2, r, c], margin):
                        fixed = _held_once(q, r, c, held, bodies, planes, plane_friction,
                                           margin)
                        break
            anchor[0, r, c], anchor[1, r, c] = (r, c) if fixed else (-1, -1)
            count += fixed
    return count


@numba.njit(**BORROW)
def _nearest_anchors(anchor, row_step, col_step, squared):
    """
    Give each point an anchor near it and their squared distance at rest (``squared``, m^2).

    Danielsson's vector propagation (a point takes the anchor of a neighbour already passed
    if that one is nearer to it at rest): down the rows, each row from its left taking the
    anchors of the row above and its left neighbour, then from its right taking its right
    neighbour's; then up the rows the other way round. The nearest anchor for nearly every
    point, a near one for the rest; any anchor bounds the distance (see :func:`_tether`).
    ``anchor`` (row and column) holds the anchors' own and -1 elsewhere on entry; points
    with none keep -1.
    """
    rows, cols = anchor.shape[1], anchor.shape[2]
    for r in range(rows):
        for c in range(cols):
            squared[r, c] = 0.0 if anchor[0, r, c] >= 0 else np.inf
    for i in range(2 * rows):
        up = i >= rows                  # the second pass, from the last row
        r = 2 * rows - 1 - i if up else i
        r_before = r + 1 if up else r - 1
        for c in range(cols):
            # the row passed before (three neighbours), then the left neighbour
            for k in range(4):
                r2, c2 = (r_before, c + k - 1) if k < 3 else (r, c - 1)
                if r2 < 0 or r2 >= rows or c2 < 0 or c2 >= cols or anchor[0, r2, c2] < 0:
                    continue
                ar, ac = anchor[0, r2, c2], anchor[1, r2, c2]
                d2 = ((r - ar) * row_step) ** 2 + ((c - ac) * col_step) ** 2
                if d2 < squared[r, c]:
                    squared[r, c] = d2
                    anchor[0, r, c], anchor[1, r, c] = ar, ac
        for c in range(cols - 2, -1, -1):
            if anchor[0, r, c + 1] < 0:
                continue
            ar, ac = anchor[0, r, c + 1], anchor[1, r, c + 1]
            d2 = ((r - ar) * row_step) ** 2 + ((c - ac) * col_step) ** 2
            if d2 < squared[r, c]:
                squared[r, c] = d2
                anchor[0, r, c], anchor[1, r, c] = ar, ac


@numba.njit(**BORROW)
def _tether(q, qd, dv, anchor, squared, planes, boxes, spheres, bodies, margin, stretch,
            tolerance, h):
    """
    Pull each point no farther from its anchor than ``1 + stretch`` times their rest distance.

    A point farther than that (by over ``tolerance``, relative) moves towards its anchor
    along the surfaces it lies on (:func:`_kept`), the anchor stays; returns how many
    moved. The springs within their limit keep the points within it too, along a row, a
    column or a diagonal of the grid; between those directions the springs allow more (a
    uniform stretch at 63 degrees to the rows reaches 11.1 % with none over 10 %, more
    where the cloth is also compressed across it), so a tether is tighter there. One pass
    does what the sweeps take hundreds for: a cloth dragged by a finger lies at its strain
    limit behind it, and the finger's pull crosses the sheet one spring a sweep
    (long-range attachments, Kim, Chentanez and Mueller 2012).
    """
    rows, cols = anchor.shape[1], anchor.shape[2]
    moved = 0
    bound = (1.0 + stretch) * (1.0 + tolerance)
    for r in range(rows):
        for c in range(cols):
            ar, ac = anchor[0, r, c], anchor[1, r, c]
            if ar < 0 or squared[r, c] == 0.0:
                continue
            dx, dy, dz = q[0, ar, ac] - q[0, r, c], q[1, ar, ac] - q[1, r, c], \
                q[2, ar, ac] - q[2, r, c]
            length2 = dx * dx + dy * dy + dz * dz
            # squared: the roots only for the points pulled (a few in a hundred)
            if not length2 > bound * bound * squared[r, c]:
                continue
            length = math.sqrt(length2)
            limit = (1.0 + stretch) * math.sqrt(squared[r, c])
            ux, uy, uz = dx / length, dy / length, dz / length
            mx, my, mz = _kept(q, r, c, ux, uy, uz, planes, boxes, spheres, bodies, margin)
            rate = mx * ux + my * uy + mz * uz
            if rate < SMALLEST_RATE:
                continue
            _shift(q, qd, dv, r, c, (length - limit) / rate, mx, my, mz, h)
            moved += 1
    return moved


@numba.njit(**JIT)
def _pull_to_anchors(q, qd, dv, rest, hold_kind, held, planes, boxes, spheres, bodies, margin,
                     plane_friction, stretch, tolerance, h):
    """Tether every point to an anchor near it (:func:`_tether`); returns how many moved."""
    rows, cols = hold_kind.shape
    anchor = np.empty((2, rows, cols), dtype=np.int64)
    if not _anchors(q, hold_kind, held, bodies, planes, plane_friction, margin, anchor):
        return 0
    squared = np.empty((rows, cols))
    _nearest_anchors(anchor, rest[2], rest[0], squared)
    return _tether(q, qd, dv, anchor, squared, planes, boxes, spheres, bodies, margin,
                   stretch, tolerance, h)


@numba.njit(**JIT)
def tangent_strain_limit(q, qd, dv, rest, hold_kind, planes, boxes, spheres, bodies, margin,
                         plane_friction, max_stretch, max_sweeps, tolerance, h, relaxation,
                         tethers):
    """
    Limit the springs of a level to ``(1 + max_stretch)`` times their rest length.

    Gauss-Seidel sweeps (see the module docstring), every free point movable but those a
    moving body presses into a plane of friction ``plane_friction`` (:func:`_held`), a
    point lying on an obstacle of the scene's arrays or on a moving body (packed rows of
    :mod:`.bodies`, where they are at the end of the step) only along its surface (where
    it lies when its spring is corrected). Stops
    after a sweep that found no spring over its limit by more than ``tolerance``
    (relative); returns how many sweeps found one (0: none over).

    A spring whose ends may move along it (the rate its kept moves shorten it is over
    ``FREE_RATE`` of a free spring's) is moved ``relaxation`` times its correction,
    leaving it shorter than its limit (successive over-relaxation; 1: plain projection).
    The springs round a body dragging the cloth over the ground, all lying on it, take a
    smooth correction that plain Gauss-Seidel spreads slowly: 122-150 sweeps a call at the
    median on the contact bench's finger scene, 48 with 1.5. Over-relaxing every
    spring, those whose moves a surface bends too (where the first-order rate misjudges
    the move), made that scene run away at 1.6.

    After the first sweep a spring is looked at again only if an end of it moved since
    it was last looked at (:func:`_touch`, by runs of ``RUN`` columns of a row): the
    others were within their limit then and are now, or could not be shortened then and
    cannot now, so the positions are those of looking at every spring in every sweep (a
    spring that cannot be shortened no longer keeps the sweeps, and their count, going
    once nothing else moves). On the 129 x 129 table drop a step's call ran 187
    sweeps, thousands of corrections in 30-40 of 81 blocks of 16 x 16 cells for the first
    hundred, a few in a few blocks after.

    ``tethers``: when the sweeps have not settled after ``TETHER_AFTER`` and the level has
    held points (a grip or a pin, or a point a body presses into a plane), every point is
    pulled within the limit of an anchor near it at rest (:func:`_pull_to_anchors`), and
    the next sweep looks at every spring. Behind the contact bench's finger at 257 x 257
    the dragged cloth lies at its limit and the sweeps passed the finger's pull on one
    spring a sweep: 300 (the cap) at the median, 3.7 calls a step, 48.5 ms; tethered, 2.0
    calls a step, 11.9 ms (``tools/finger_profile.py --size 257``). A call that settles within
    ``TETHER_AFTER`` sweeps never pays for the anchors (a pass over the level and the two
    of :func:`_nearest_anchors`).
    """
    rows, cols = hold_kind.shape
    runs = (cols + RUN - 1) // RUN
    now = np.ones((rows, runs), dtype=np.bool_)     # runs a sweep looks at
    later = np.zeros((rows, runs), dtype=np.bool_)  # runs the next sweep looks at
    corrected = 0
    # a body can press a point into a plane (see _held): decided once a call for each
    # point a spring over its limit asks about (:func:`_held_once`)
    pressing = bodies.shape[0] > 0 and planes.shape[0] > 0
    held = np.zeros((rows, cols), dtype=np.int8)
    tethers = tethers and (pressing or np.any(hold_kind != FREE))
    # each direction's limit and the bound a spring is corrected beyond
    limits = np.empty(DIRECTIONS.shape[0])
    bounds = np.empty(DIRECTIONS.shape[0])
    for e in range(DIRECTIONS.shape[0]):
        limits[e] = rest[DIRECTIONS[e]] * (1.0 + max_stretch)
        bounds[e] = limits[e] * (1.0 + tolerance)
    for sweep in range(max_sweeps):
        if tethers and sweep == TETHER_AFTER and _pull_to_anchors(
                q, qd, dv, rest, hold_kind, held, planes, boxes, spheres, bodies, margin,
                plane_friction, max_stretch, tolerance, h):
            now[:, :] = True
        over = False
        for r in range(rows):
            for run in range(runs):
                # a run's flag once, not each point's: on the contact bench's finger at
                # 257 x 257 a sweep looks at 200-900 points, and reading 66,049 flags
                # took a fifth of the sweeps' time
                if not now[r, run]:
                    continue
                for c in range(run * RUN, min((run + 1) * RUN, cols)):
                    wp = 1.0 if hold_kind[r, c] == FREE else 0.0
                    for e in range(STEP_ROWS.shape[0]):
                        r2, c2 = r + STEP_ROWS[e], c + STEP_COLS[e]
                        if r2 < 0 or r2 >= rows or c2 < 0 or c2 >= cols:
                            continue
                        wn = 1.0 if hold_kind[r2, c2] == FREE else 0.0
                        limit, bound = limits[e], bounds[e]
                        dx = q[0, r2, c2] - q[0, r, c]
                        dy = q[1, r2, c2] - q[1, r, c]
                        dz = q[2, r2, c2] - q[2, r, c]
                        squared = dx * dx + dy * dy + dz * dz
                        # the root only for a spring near its bound or over (most of
                        # those looked at are well within; the margin covers rounding)
                        if wp + wn == 0.0 or squared <= bound * bound * (1.0 - 1e-9):
                            continue
                        length = math.sqrt(squared)
                        if not length > bound:
                            continue
                        over = True
                        if pressing:
                            if wp > 0.0 and _held_once(q, r, c, held, bodies, planes,
                                                       plane_friction, margin):
                                wp = 0.0
                            if wn > 0.0 and _held_once(q, r2, c2, held, bodies, planes,
                                                       plane_friction, margin):
                                wn = 0.0
                            if wp + wn == 0.0:
                                continue
                        ux, uy, uz = dx / length, dy / length, dz / length
                        ax, ay, az = _kept(q, r, c, wp * ux, wp * uy, wp * uz, planes, boxes,
                                           spheres, bodies, margin)
                        bx, by, bz = _kept(q, r2, c2, -wn * ux, -wn * uy, -wn * uz, planes,
                                           boxes, spheres, bodies, margin)
                        # how fast the kept moves shorten the spring (to first order)
                        rate = (ax - bx) * ux + (ay - by) * uy + (az - bz) * uz
                        if rate < SMALLEST_RATE * (wp + wn):
                            continue
                        lam = (length - limit) / rate
                        if rate > FREE_RATE * (wp + wn):
                            lam *= relaxation
                        _shift(q, qd, dv, r, c, lam, ax, ay, az, h)
                        _shift(q, qd, dv, r2, c2, lam, bx, by, bz, h)
                        _touch(r, c, rows, cols, now, later)
                        _touch(r2, c2, rows, cols, now, later)
        if not over:
            break
        corrected += 1
        now[:, :] = later
        later[:, :] = False
    return corrected
