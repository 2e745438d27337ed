"""
Contact with static obstacles: ground planes, axis-aligned boxes and spheres.

A point found inside an obstacle (grown by ``margin``) is moved out along the obstacle's
normal; its inward normal velocity stops and Coulomb friction slows its tangential
velocity (never reversing it). See :mod:`hcloth_ros.core.scene` for the obstacle arrays.

A solver calls it twice a step on a level. The first pass (``integration_pass``), right
after the integration, also takes friction off the step's motion of the points that rest
on the obstacle (that started the step within ``RESTING`` margins of it): a point's
tangential displacement since the start of the step shrinks by up to ``h`` times the
friction's velocity budget (``friction`` times the normal speed stopped), as if the step
had moved it with the slowed velocity (exactly so when the displacement is ``h`` times
the tangential velocity, as after backward Euler). Friction on
velocity alone stopped a point only from the next step on, after the step had moved it:
the fold demo's cloth crept 20 cm along the ground towards the grippers, under any
friction coefficient, and a cloth crept 3.7-5.5 cm in 1 s down a 20-degree incline of
friction 0.5. Points landing keep their step's motion (friction on their velocity only):
held where they landed, at an impact's friction, they stretched the springs to the
points still in the air (the contact bench's folded cloth dropped 10 cm onto the ground:
98 % strain for a step with every point held, 59 % within 3 margins, 26 % with none;
within 2 margins the fold demo's far corners, lifted by the top layer, slid 2.4 cm).
The second pass comes after strain limiting and acts on velocity alone: taking strain
limiting's moves back too fought it: a cloth draped over a table kept its springs at the
edge stretched and the part on the table rippled by 3.9 mm (``test_physics``' drape
allows 1 mm).

A point that was already inside the bare obstacle when the step started (an obstacle set
where the cloth is, a cloth started inside one) gains ``RECOVERY_SPEED * h`` on its way
out each call after the first, on top of whatever the step moved it back in (the cloth's
weight pulling it down, strain limiting), and no more (a solver calling contact several
times a step, as its rounds on the finest level do, moves it out that much faster):
pushed out at once, a cloth across a box had springs stretched to 390 % and kept them for
seconds; pulled out at a fixed rate, the weight of the draped cloth held points inside
for good.
"""

import math

from hcloth_ros.core.kernels.jit import BORROW, JIT
from hcloth_ros.core.kernels.layout import FREE
import numba

RECOVERY_SPEED = 1.0     # m/s: how fast a point found inside an obstacle is moved out
# Margins from an obstacle's bare surface within which a point that started the step
# rests on it (friction on its position too, see the module docstring).
RESTING = 3.0


@numba.njit(**BORROW)
def _resolve(q, qd, dv, q_prev, r, c, nx, ny, nz, depth, friction, h, on_position):
    """
    Move point (r, c) ``depth`` along the unit normal n; apply friction.

    The contact's velocity change is applied and added to the step's ``dv``. Friction
    removes up to ``friction`` times the normal speed stopped from the tangential velocity
    and, ``on_position``, ``h`` times that from the tangential displacement since
    ``q_prev``.
    """
    q[0, r, c] += depth * nx
    q[1, r, c] += depth * ny
    q[2, r, c] += depth * nz
    vx, vy, vz = qd[0, r, c], qd[1, r, c], qd[2, r, c]
    vn = vx * nx + vy * ny + vz * nz
    if vn >= 0.0:
        return
    budget = friction * (-vn)
    tx, ty, tz = vx - vn * nx, vy - vn * ny, vz - vn * nz
    vt = math.sqrt(tx * tx + ty * ty + tz * tz)
    scale = max(0.0, 1.0 - budget / vt) if vt > 0.0 else 0.0
    for d, new in ((0, tx * scale), (1, ty * scale), (2, tz * scale)):
        dv[d, r, c] += new - qd[d, r, c]
        qd[d, r, c] = new
    if not on_position:
        return
    mx = q[0, r, c] - q_prev[0, r, c]
    my = q[1, r, c] - q_prev[1, r, c]
    mz = q[2, r, c] - q_prev[2, r, c]
    mn = mx * nx + my * ny + mz * nz
    mx, my, mz = mx - mn * nx, my - mn * ny, mz - mn * nz
    moved = math.sqrt(mx * mx + my * my + mz * mz)
    if moved > 0.0:
        hold = min(1.0, budget * h / moved)
        q[0, r, c] -= mx * hold
        q[1, r, c] -= my * hold
        q[2, r, c] -= mz * hold


@numba.njit(**BORROW)
def _box_exit(q, q_prev, r, c, box, margin):
    """
    Return the axis and side (+-1) a point inside ``box`` leaves by (axis -1: outside).

    And whether it was inside the bare box at the start of the step.

    The face it entered by: the axis on which its start-of-step position was furthest
    outside the bare box (a point the margin away, where last step's push left it, is
    outside within rounding). The nearest face alone pushes points that fall onto a table
    top near its edge out sideways, tearing the cloth. A point already inside the bare box
    (a box that appeared in the cloth, a cloth started in one) leaves by the top: by the
    nearest face, the points of a cloth across a box went up, down and sideways, and
    springs stretched 200-600 % stayed so for seconds.
    """
    axis = -1
    entry = -1e300
    for d in range(3):
        if box[3 + d] + margin - abs(q[d, r, c] - box[d]) <= 0.0:
            return -1, 0.0, False
        outside_before = abs(q_prev[d, r, c] - box[d]) - box[3 + d]
        if outside_before > entry:
            entry, axis = outside_before, d
    if entry <= 0.0:
        return 2, 1.0, True
    return axis, 1.0 if (q_prev[axis, r, c] - box[axis]) >= 0.0 else -1.0, False


@numba.njit(**BORROW)
def _movable(hold_kind, inherited_fixed, r, c):
    """
    Tell whether contact may move point (r, c).

    It must be free and, with ``inherited_fixed``, not inherited from the coarser level.
    """
    return hold_kind[r, c] == FREE and not (inherited_fixed and r % 2 == 0 and c % 2 == 0)


@numba.njit(**JIT)
def contact(
        # inputs / outputs: the level after the step and its velocity change, corrected
        q, qd, dv,
        # inputs: positions at the start of the step (which face a point entered a box
        # by), holds, whether inherited points belong to the coarser level
        q_prev, hold_kind, inherited_fixed,
        # inputs: the obstacles, the step (s)
        planes, boxes, spheres, friction, margin, h,
        # whether this is the pass right after the integration (see the module docstring)
        integration_pass):
    """
    Push the movable points of a level out of the obstacles.

    Held points and, with ``inherited_fixed``, inherited points stay where they are. Each
    point meets the planes, then the boxes, then the spheres. Returns how many pushes it
    made (0: the level touched nothing this step). The loops run over the
    points inside each obstacle's loop, with the test inline: a function call per point
    (array arguments and all) cost 17x the kernel.
    """
    rows, cols = hold_kind.shape
    x, y, z = q[0], q[1], q[2]
    recovery = 0.0 if integration_pass else RECOVERY_SPEED * h
    pushes = 0
    for p in range(planes.shape[0]):
        nx, ny, nz, offset = planes[p, 0], planes[p, 1], planes[p, 2], planes[p, 3]
        for r in range(rows):
            for c in range(cols):
                dist = x[r, c] * nx + y[r, c] * ny + z[r, c] * nz - offset - margin
                if dist < 0.0 and _movable(hold_kind, inherited_fixed, r, c):
                    depth = -dist
                    before = q_prev[0, r, c] * nx + q_prev[1, r, c] * ny + \
                        q_prev[2, r, c] * nz - offset
                    if before < 0.0:
                        depth = min(depth, recovery + max(0.0, before - dist - margin))
                    _resolve(q, qd, dv, q_prev, r, c, nx, ny, nz, depth, friction, h,
                             integration_pass and before <= RESTING * margin)
                    pushes += 1
    for b in range(boxes.shape[0]):
        box = boxes[b]
        hx, hy, hz = box[3] + margin, box[4] + margin, box[5] + margin
        for r in range(rows):
            for c in range(cols):
                inside = (abs(x[r, c] - box[0]) < hx) & (abs(y[r, c] - box[1]) < hy) & \
                    (abs(z[r, c] - box[2]) < hz)
                if not (inside and _movable(hold_kind, inherited_fixed, r, c)):
                    continue
                axis, sign, started_inside = _box_exit(q, q_prev, r, c, box, margin)
                if axis >= 0:
                    depth = box[3 + axis] + margin - sign * (q[axis, r, c] - box[axis])
                    if started_inside:      # leaving by the top (+z)
                        depth = min(depth, recovery + max(0.0, q_prev[2, r, c] - z[r, c]))
                    before = sign * (q_prev[axis, r, c] - box[axis]) - box[3 + axis]
                    _resolve(q, qd, dv, q_prev, r, c, sign if axis == 0 else 0.0,
                             sign if axis == 1 else 0.0, sign if axis == 2 else 0.0, depth,
                             friction, h, integration_pass and before <= RESTING * margin)
                    pushes += 1
    for s in range(spheres.shape[0]):
        cx, cy, cz, reach = spheres[s, 0], spheres[s, 1], spheres[s, 2], spheres[s, 3] + margin
        for r in range(rows):
            for c in range(cols):
                dx, dy, dz = x[r, c] - cx, y[r, c] - cy, z[r, c] - cz
                dist = math.sqrt(dx * dx + dy * dy + dz * dz)
                pen = reach - dist
                if not (pen > 0.0 and _movable(hold_kind, inherited_fixed, r, c)):
                    continue
                before = math.sqrt((q_prev[0, r, c] - cx) ** 2 + (q_prev[1, r, c] - cy) ** 2 +
                                   (q_prev[2, r, c] - cz) ** 2)
                if before < spheres[s, 3]:
                    pen = min(pen, recovery + max(0.0, before - dist))
                resting = integration_pass and before - spheres[s, 3] <= RESTING * margin
                if dist > 0.0:
                    _resolve(q, qd, dv, q_prev, r, c, dx / dist, dy / dist, dz / dist, pen,
                             friction, h, resting)
                else:
                    _resolve(q, qd, dv, q_prev, r, c, 0.0, 0.0, 1.0, pen, friction, h,
                             resting)
                pushes += 1
    return pushes
