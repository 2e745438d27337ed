"""
Contact with moving rigid bodies: oriented boxes, spheres and capsules.

Each body comes as one packed row (:data:`ROW` numbers, built by
:class:`hcloth_ros.core.bodies.MovingBodies`): its shape, friction coefficient, size, and
its pose at the end and at the start of the step. The body moves rigidly from one pose to
the other during the step, so a point fixed to it moves by ``R1 l + t1 - (R0 l + t0)``:
that difference over ``h`` is the surface velocity the cloth's friction and normal
velocity are measured against (rotation included, no angular velocity needed).

A movable point inside a body (grown by ``margin``) at the end of the step is moved out
along the body's normal; its velocity relative to the surface loses its inward normal
part and Coulomb friction slows its tangential part, never reversing it. The friction
budget is the larger of the normal speed removed and the push over ``h``: a point resting
on a body loses ``mu g h`` a step (Coulomb's ``mu g`` deceleration), and a point squeezed
between a body and the ground (pushed by the body, pushed back by the ground, its normal
velocity zero) is still dragged by a body pressing it.
"""

import math

from hcloth_ros.core.kernels.contact import _movable
from hcloth_ros.core.kernels.jit import BORROW, JIT

import numba
import numpy as np

BOX, SPHERE, CAPSULE = 0, 1, 2
# packed row: kind, friction, size (box: half extents; sphere: radius; capsule: radius and
# half length along the body's z), rotation at the end (row-major), translation at the end,
# rotation at the start, translation at the start
KIND, FRICTION, SIZE, R_END, T_END, R_START, T_START = 0, 1, 2, 5, 14, 17, 26
ROW = 29


@numba.njit(**BORROW)
def _to_local(b, rot, tr, x, y, z):
    """Return ``R^T (p - t)`` for the pose at offsets ``rot`` and ``tr`` of row b."""
    dx, dy, dz = x - b[tr], y - b[tr + 1], z - b[tr + 2]
    return (b[rot] * dx + b[rot + 3] * dy + b[rot + 6] * dz,
            b[rot + 1] * dx + b[rot + 4] * dy + b[rot + 7] * dz,
            b[rot + 2] * dx + b[rot + 5] * dy + b[rot + 8] * dz)


@numba.njit(**BORROW)
def _to_local_direction(b, x, y, z):
    """Return ``R^T v`` for the rotation at the end of the step of row b."""
    return (b[R_END] * x + b[R_END + 3] * y + b[R_END + 6] * z,
            b[R_END + 1] * x + b[R_END + 4] * y + b[R_END + 7] * z,
            b[R_END + 2] * x + b[R_END + 5] * y + b[R_END + 8] * z)


@numba.njit(**BORROW)
def _rotate(b, rot, x, y, z):
    """Return ``R l`` for the rotation at offset ``rot`` of row b."""
    return (b[rot] * x + b[rot + 1] * y + b[rot + 2] * z,
            b[rot + 3] * x + b[rot + 4] * y + b[rot + 5] * z,
            b[rot + 6] * x + b[rot + 7] * y + b[rot + 8] * z)


@numba.njit(**BORROW)
def _reach(b):
    """Radius of a sphere around the body's origin that holds the whole body."""
    kind = int(b[KIND])
    if kind == BOX:
        return math.sqrt(b[SIZE] ** 2 + b[SIZE + 1] ** 2 + b[SIZE + 2] ** 2)
    if kind == SPHERE:
        return b[SIZE]
    return b[SIZE] + b[SIZE + 1]


@numba.njit(**BORROW)
def _grown_reach(b, grow):
    """
    Radius of a sphere around the body's origin that holds the body grown by ``grow``.

    A box grows along each axis, so its corners move out by ``grow`` in all three: the
    half diagonal plus ``grow`` left points inside the grown box near its corners out
    (1.4 mm at the tests' table with a 2 mm margin); a sphere or a capsule grows along
    its normal.
    """
    if int(b[KIND]) == BOX:
        return math.sqrt((b[SIZE] + grow) ** 2 + (b[SIZE + 1] + grow) ** 2
                         + (b[SIZE + 2] + grow) ** 2)
    return _reach(b) + grow


@numba.njit(**BORROW)
def _off_core(b, x, y, z):
    """Return a local point minus the nearest point of a round body's core (centre, axis)."""
    if int(b[KIND]) == CAPSULE:
        z -= min(max(z, -b[SIZE + 1]), b[SIZE + 1])
    return x, y, z


@numba.njit(**BORROW)
def _inside_round(b, radius, x, y, z):
    ox, oy, oz = _off_core(b, x, y, z)
    return ox * ox + oy * oy + oz * oz < radius * radius


@numba.njit(**BORROW)
def _round_exit(b, margin, lx, ly, lz, sx, sy, sz):
    """
    Local unit normal and depth of a point inside a sphere or capsule (0 depth: outside).

    A point that started outside leaves by the side it came in: along the normal where
    its path (``s`` to ``l``, relative to the body) entered, found by bisection. The
    nearest surface point would push a point that went past the core out of the far
    side (a cloth falling onto a rising ball went through it). A point that started
    inside leaves by the nearest surface point.
    """
    radius = b[SIZE] + margin
    if not _inside_round(b, radius, lx, ly, lz):
        return 0.0, 0.0, 0.0, 0.0
    if _inside_round(b, radius, sx, sy, sz):
        ox, oy, oz = _off_core(b, lx, ly, lz)
        d = math.sqrt(ox * ox + oy * oy + oz * oz)
        if d == 0.0:
            return 0.0, 0.0, 1.0, radius
        return ox / d, oy / d, oz / d, radius - d
    outside, inside = 0.0, 1.0     # fractions of the path
    for _ in range(40):
        mid = 0.5 * (outside + inside)
        if _inside_round(b, radius, sx + mid * (lx - sx), sy + mid * (ly - sy),
                         sz + mid * (lz - sz)):
            inside = mid
        else:
            outside = mid
    ox, oy, oz = _off_core(b, sx + outside * (lx - sx), sy + outside * (ly - sy),
                           sz + outside * (lz - sz))
    d = math.sqrt(ox * ox + oy * oy + oz * oz)
    nx, ny, nz = ox / d, oy / d, oz / d
    return nx, ny, nz, _exit_along(b, margin, lx, ly, lz, nx, ny, nz)


@numba.njit(**BORROW)
def _box_exit(b, margin, lx, ly, lz, sx, sy, sz):
    """
    Local unit normal and depth of a point inside the box (0 depth: outside).

    ``l``: the point at the end of the step, ``s``: at its start, each in the body's frame
    of that time. It leaves by the face it entered by (where its start was furthest
    outside the bare box: a point pushed to the margin last step is on that face's side,
    within rounding), or by the nearest face if it started inside the bare box.
    """
    half = (b[SIZE] + margin, b[SIZE + 1] + margin, b[SIZE + 2] + margin)
    end = (lx, ly, lz)
    start = (sx, sy, sz)
    axis = -1
    entry = -1e300
    for d in range(3):
        if half[d] - abs(end[d]) <= 0.0:
            return 0.0, 0.0, 0.0, 0.0
        outside_before = abs(start[d]) - b[SIZE + d]
        if outside_before > entry:
            entry, axis = outside_before, d
    side = start[axis]
    if entry <= 0.0:
        best = 1e300
        for d in range(3):
            if half[d] - abs(end[d]) < best:
                best, axis = half[d] - abs(end[d]), d
        side = end[axis]
    sign = 1.0 if side >= 0.0 else -1.0
    depth = half[axis] - sign * end[axis]
    return (sign if axis == 0 else 0.0, sign if axis == 1 else 0.0,
            sign if axis == 2 else 0.0, depth)


@numba.njit(**BORROW)
def _exit(b, margin, lx, ly, lz, sx, sy, sz):
    """Local unit normal and depth of a point inside body row b (0 depth: outside)."""
    if int(b[KIND]) == BOX:
        return _box_exit(b, margin, lx, ly, lz, sx, sy, sz)
    return _round_exit(b, margin, lx, ly, lz, sx, sy, sz)


@numba.njit(**BORROW)
def _push(q, r, c, b, depth, nx, ny, nz):
    """Move point (r, c) ``depth`` along the local normal n; return n in the world."""
    nx, ny, nz = _rotate(b, R_END, nx, ny, nz)
    q[0, r, c] += depth * nx
    q[1, r, c] += depth * ny
    q[2, r, c] += depth * nz
    return nx, ny, nz


@numba.njit(**BORROW)
def _exit_along(b, margin, lx, ly, lz, vx, vy, vz):
    """
    Distance from local point l, inside body b (grown by margin), to its surface along v.

    ``v`` is a unit vector in the body's frame; 0 if l is outside.
    """
    kind = int(b[KIND])
    if kind == BOX:
        end = 1e300
        for p, v, half in ((lx, vx, b[SIZE] + margin), (ly, vy, b[SIZE + 1] + margin),
                           (lz, vz, b[SIZE + 2] + margin)):
            if abs(p) >= half:
                return 0.0
            if v > 0.0:
                end = min(end, (half - p) / v)
            elif v < 0.0:
                end = min(end, (-half - p) / v)
        return end
    radius = b[SIZE] + margin
    if not _inside_round(b, radius, lx, ly, lz):
        return 0.0
    if kind == SPHERE:
        along = lx * vx + ly * vy + lz * vz
        return -along + math.sqrt(along * along + radius * radius - (lx * lx + ly * ly + lz * lz))
    inside, outside = 0.0, 2.0 * (radius + b[SIZE + 1])     # the capsule is convex: bisect
    for _ in range(40):
        mid = 0.5 * (inside + outside)
        if _inside_round(b, radius, lx + mid * vx, ly + mid * vy, lz + mid * vz):
            inside = mid
        else:
            outside = mid
    return outside


@numba.njit(**BORROW)
def _pressed(q, r, c, b, planes, margin, lx, ly, lz):
    """
    How deep body b presses point (r, c) into a plane it lies on, and the plane's normal.

    A point on a plane (within two margins of it) that a body overlaps is squeezed between
    them, whichever face of the body is nearest: the plane keeps it (contact with static
    obstacles runs next) and the body, reaching that far below the point's place on the
    plane, drags it by friction. Pushing it out of a side face instead would plough the
    cloth a body presses into the ground (it tore it: strain 7 on a pad held on an
    incline).
    """
    deepest, nx, ny, nz = 0.0, 0.0, 0.0, 0.0
    for p in range(planes.shape[0]):
        dist = q[0, r, c] * planes[p, 0] + q[1, r, c] * planes[p, 1] + \
            q[2, r, c] * planes[p, 2] - planes[p, 3]
        if dist >= 2.0 * margin:
            continue
        # the plane's normal in the body's frame, and the point lifted to the margin
        mx, my, mz = _to_local_direction(b, planes[p, 0], planes[p, 1], planes[p, 2])
        lift = margin - dist
        reach = _exit_along(b, margin, lx + lift * mx, ly + lift * my, lz + lift * mz,
                            -mx, -my, -mz)
        if reach > deepest:
            deepest, nx, ny, nz = reach, planes[p, 0], planes[p, 1], planes[p, 2]
    return deepest, nx, ny, nz


@numba.njit(**BORROW)
def _carried(b, ox, oy, oz):
    """How far body b carried its surface point at local o over the step (world)."""
    ex, ey, ez = _rotate(b, R_END, ox, oy, oz)
    sx, sy, sz = _rotate(b, R_START, ox, oy, oz)
    return (ex + b[T_END] - sx - b[T_START], ey + b[T_END + 1] - sy - b[T_START + 1],
            ez + b[T_END + 2] - sz - b[T_START + 2])


@numba.njit(**BORROW)
def _rub(q, qd, dv, q_prev, r, c, n, carried, budget, dt):
    """
    Friction between point (r, c) and a surface of normal n that moved by ``carried``.

    The velocity relative to the surface loses its inward normal part and up to
    ``budget`` of its tangential part (never reversed); up to ``budget * dt`` of the
    tangential displacement relative to the surface over the step is taken back, so a point
    held by friction moves with the surface whatever else moved it (springs, strain
    limiting). An infinite budget holds it.
    """
    u = (qd[0, r, c] - carried[0] / dt, qd[1, r, c] - carried[1] / dt,
         qd[2, r, c] - carried[2] / dt)
    moved = (q[0, r, c] - q_prev[0, r, c] - carried[0], q[1, r, c] - q_prev[1, r, c] - carried[1],
             q[2, r, c] - q_prev[2, r, c] - carried[2])
    un = u[0] * n[0] + u[1] * n[1] + u[2] * n[2]
    mn = moved[0] * n[0] + moved[1] * n[1] + moved[2] * n[2]
    ut = math.sqrt(max(u[0] ** 2 + u[1] ** 2 + u[2] ** 2 - un * un, 0.0))
    mt = math.sqrt(max(moved[0] ** 2 + moved[1] ** 2 + moved[2] ** 2 - mn * mn, 0.0))
    slow = min(1.0, budget / ut) if ut > 0.0 else 0.0
    hold = min(1.0, budget * dt / mt) if mt > 0.0 else 0.0
    for d in range(3):
        new = carried[d] / dt + max(un, 0.0) * n[d] + (u[d] - un * n[d]) * (1.0 - slow)
        q[d, r, c] -= (moved[d] - mn * n[d]) * hold
        dv[d, r, c] += new - qd[d, r, c]
        qd[d, r, c] = new


@numba.njit(**BORROW)
def _respond(q, qd, dv, q_prev, r, c, b, h, dt, planes, plane_friction, margin,
             lx, ly, lz, sx, sy, sz):
    """
    Move point (r, c) out of body b, or hold it where b presses it into a plane.

    ``l``/``s``: the point in the body's frame at the end / start of the step; ``h``: the
    velocity's scale (``x = x^ + h v``; see ``body_contact``); ``dt``: the step, over which
    the body moved.
    Returns whether the point was inside.

    Pushed out: friction's budget is ``mu`` times the larger of the normal speed removed
    and the push over ``h`` (the speed the push stands for).
    Pressed into a plane: a kinematic body against a rigid plane presses with whatever
    force it takes, so by Coulomb's law the surface of larger friction holds the point
    (the body if its coefficient is larger, else the plane; neither if both are 0).
    """
    nx, ny, nz, depth = _exit(b, margin, lx, ly, lz, sx, sy, sz)
    if depth <= 0.0:
        return False
    pressed, px, py, pz = _pressed(q, r, c, b, planes, margin, lx, ly, lz)
    if pressed > 0.0:
        # the body's motion along the plane only: a body rising off a point it pressed
        # does not lift it (the point lies under it)
        cx, cy, cz = _carried(b, lx, ly, lz)
        along = cx * px + cy * py + cz * pz
        carried = (cx - along * px, cy - along * py, cz - along * pz)
        if b[FRICTION] > plane_friction:
            _rub(q, qd, dv, q_prev, r, c, (px, py, pz), carried, math.inf, dt)
        elif plane_friction > 0.0:
            _rub(q, qd, dv, q_prev, r, c, (px, py, pz), (0.0, 0.0, 0.0), math.inf, dt)
        return True
    carried = _carried(b, lx + depth * nx, ly + depth * ny, lz + depth * nz)
    wx, wy, wz = _push(q, r, c, b, depth, nx, ny, nz)
    un = (qd[0, r, c] - carried[0] / dt) * wx + (qd[1, r, c] - carried[1] / dt) * wy + \
        (qd[2, r, c] - carried[2] / dt) * wz
    _rub(q, qd, dv, q_prev, r, c, (wx, wy, wz), carried, b[FRICTION] * max(-un, depth / h), dt)
    if int(b[KIND]) != BOX:
        # dragged along a curved surface, the point may have cut into it: back to it
        lx, ly, lz = _to_local(b, R_END, T_END, q[0, r, c], q[1, r, c], q[2, r, c])
        nx, ny, nz, depth = _exit(b, margin, lx, ly, lz, sx, sy, sz)
        if depth > 0.0:
            _push(q, r, c, b, depth, nx, ny, nz)
    return True


@numba.njit(**BORROW)
def _inside(b, margin, lx, ly, lz):
    """Whether local point l is inside body b grown by margin."""
    if int(b[KIND]) == BOX:
        return abs(lx) < b[SIZE] + margin and abs(ly) < b[SIZE + 1] + margin and \
            abs(lz) < b[SIZE + 2] + margin
    return _inside_round(b, b[SIZE] + margin, lx, ly, lz)


@numba.njit(**BORROW)
def _beyond_box(b, margin, lx, ly, lz, sx, sy, sz):
    """
    Whether the path from s to l (body frame) stays out of the grown body's local box.

    The box of the body grown by ``margin`` along its axes holds the grown body (a round
    one grows along its normal, no further); a path whose ends lie beyond one of its faces
    never enters it. The reach sphere of a long thin body (the finger: 40 cm by 2 cm) left
    14 % of a cloth's points to :func:`_first_inside`, its box 1 %.
    """
    kind = int(b[KIND])
    if kind == BOX:
        hx, hy, hz = b[SIZE], b[SIZE + 1], b[SIZE + 2]
    else:
        hx = hy = b[SIZE]
        hz = b[SIZE] + (b[SIZE + 1] if kind == CAPSULE else 0.0)
    return (min(lx, sx) > hx + margin or max(lx, sx) < -hx - margin
            or min(ly, sy) > hy + margin or max(ly, sy) < -hy - margin
            or min(lz, sz) > hz + margin or max(lz, sz) < -hz - margin)


@numba.njit(**BORROW)
def _first_inside(b, margin, sx, sy, sz, lx, ly, lz):
    """
    Fraction of the path from s to l (body frame) where it is first inside b, or -1.

    Samples no farther apart than the body's thinnest half size, so a point the body
    passes in one step (a thin finger, a fast one) is caught.
    """
    if int(b[KIND]) == BOX:
        thinnest = min(b[SIZE], min(b[SIZE + 1], b[SIZE + 2])) + margin
    else:
        thinnest = b[SIZE] + margin
    length = math.sqrt((lx - sx) ** 2 + (ly - sy) ** 2 + (lz - sz) ** 2)
    samples = min(64, int(math.ceil(length / thinnest)))
    for k in range(1, samples):
        f = k / samples
        if _inside(b, margin, sx + f * (lx - sx), sy + f * (ly - sy), sz + f * (lz - sz)):
            return f
    return -1.0


@numba.njit(**BORROW)
def _far(lx, ly, lz, sx, sy, sz, reach):
    """
    Whether the path from s to l (relative to the body) stays beyond ``reach`` of its origin.

    Relative, not in the world: a body that jumps past a point standing still crosses it.
    """
    dx, dy, dz = lx - sx, ly - sy, lz - sz
    length2 = dx * dx + dy * dy + dz * dz
    f = 0.0 if length2 == 0.0 else min(1.0, max(0.0, -(sx * dx + sy * dy + sz * dz) / length2))
    cx, cy, cz = sx + f * dx, sy + f * dy, sz + f * dz
    return cx * cx + cy * cy + cz * cz >= reach * reach


@numba.njit(**BORROW)
def _origin_path(b, box):
    """
    Write the box of the body's origin over the step into ``box``; return how far it turns.

    ``box = (min xyz, max xyz)`` of its start and end translations; the turn is the
    Frobenius norm of ``R_end - R_start`` (0 for a body that only translates), so that
    ``|(R_end - R_start)^T d| <= turn |d|`` for every vector d.
    """
    turn = 0.0
    for m in range(9):
        turn += (b[R_END + m] - b[R_START + m]) ** 2
    for d in range(3):
        box[d] = min(b[T_START + d], b[T_END + d])
        box[3 + d] = max(b[T_START + d], b[T_END + d])
    return math.sqrt(turn)


@numba.njit(**BORROW)
def _clear(q, q_prev, r, c, b, box, reach, turn):
    """
    Whether point (r, c) stays beyond ``reach`` of the body's origin, tested in the world.

    A few comparisons instead of two transforms a point (:func:`_far` then decides): the
    relative path ``(1 - f) R0^T (p0 - t0) + f R1^T (p1 - t1)`` is at least
    ``|p(f) - t(f)| - turn |p1 - t1|`` long, and ``p(f) - t(f)`` keeps beyond ``reach +
    turn |p1 - t1|`` if the boxes of the point's path and of the origin's, that far apart
    along one axis, do not overlap (``|p1 - t1|`` taken as its 1-norm, not smaller).
    The contact bench's finger on 257 x 257 leaves 18 % of the points to the transforms.
    """
    grow = reach * (1.0 + 1e-9) + turn * (abs(q[0, r, c] - b[T_END])
                                          + abs(q[1, r, c] - b[T_END + 1])
                                          + abs(q[2, r, c] - b[T_END + 2]))
    for d in range(3):
        a, e = q[d, r, c], q_prev[d, r, c]
        if min(a, e) > box[3 + d] + grow or max(a, e) < box[d] - grow:
            return True
    return False


@numba.njit(**JIT)
def body_contact(
        # inputs / outputs: the level after the step and its velocity change, corrected
        q, qd, dv,
        # inputs: positions at the start of the step (which face a point entered a box by),
        # holds, whether inherited points belong to the coarser level
        q_prev, hold_kind, inherited_fixed,
        # inputs: the bodies (rows of ROW numbers), distance kept from them, the velocity's
        # scale (x = x^ + h v: the step, or BDF2's beta below a refined finest level,
        # MultigridSolver._corrections_leave_history) and the step the bodies moved over
        bodies, margin, h, dt,
        # inputs: the static planes (a body pressing a point into one squeezes it) and their
        # friction coefficient
        planes, plane_friction):
    """
    Push the movable points of a level out of the moving bodies.

    Held points and, with ``inherited_fixed``, inherited points stay where they are.
    A point whose path relative to a body crossed it during the step (ends outside, but
    was inside on the way) is put back where it first was inside, then pushed out as if
    it had stopped there. Points whose path relative to a body stays beyond its reach are
    skipped. Returns how many pushes it made.
    """
    rows, cols = hold_kind.shape
    pushes = 0
    box = np.empty(6)
    for i in range(bodies.shape[0]):
        b = bodies[i]
        reach = _grown_reach(b, margin)
        turn = _origin_path(b, box)
        for r in range(rows):
            for c in range(cols):
                if not _movable(hold_kind, inherited_fixed, r, c):
                    continue
                if _clear(q, q_prev, r, c, b, box, reach, turn):
                    continue
                lx, ly, lz = _to_local(b, R_END, T_END, q[0, r, c], q[1, r, c], q[2, r, c])
                sx, sy, sz = _to_local(b, R_START, T_START, q_prev[0, r, c],
                                       q_prev[1, r, c], q_prev[2, r, c])
                if _far(lx, ly, lz, sx, sy, sz, reach) or \
                        _beyond_box(b, margin, lx, ly, lz, sx, sy, sz):
                    continue
                if not _inside(b, margin, lx, ly, lz):
                    f = _first_inside(b, margin, sx, sy, sz, lx, ly, lz)
                    if f < 0.0:
                        continue
                    lx, ly, lz = sx + f * (lx - sx), sy + f * (ly - sy), sz + f * (lz - sz)
                    wx, wy, wz = _rotate(b, R_END, lx, ly, lz)
                    q[0, r, c], q[1, r, c], q[2, r, c] = \
                        wx + b[T_END], wy + b[T_END + 1], wz + b[T_END + 2]
                if _respond(q, qd, dv, q_prev, r, c, b, h, dt, planes, plane_friction, margin,
                            lx, ly, lz, sx, sy, sz):
                    pushes += 1
    return pushes
