"""
Drop the tests' cloth on the tests' table and report how far its flaps hang.

The README's table section quotes these figures: after 4 s at 1/60 s (air drag
1 N s/m^3), the height range of the points beyond 0.45 m from the centre along x (the flaps
over the table's x edges; the top is at 0.70 m, a flap is 0.2 m long), the largest strain
of the finest level over the run, over its last 3 s and in the last step, where its most
stretched spring is at the end, and the mean wall time of a step (with the other core busy
or not: see the load), for each solver given.

    .venv/bin/python tools/table_flaps.py --levels 2 multigrid implicit hierarchical
    .venv/bin/python tools/table_flaps.py --levels 2 --k-bend 0 multigrid
    .venv/bin/python tools/table_flaps.py multigrid hierarchical --levels 3 --contact-rounds 0 16
    .venv/bin/python tools/table_flaps.py multigrid --levels 5 --contact-rounds 16
    .venv/bin/python tools/table_flaps.py multigrid --levels 5 --option contact_sweeps=40
    .venv/bin/python tools/table_flaps.py multigrid --levels 5 --option accurate_level=3 --edge
    .venv/bin/python tools/table_flaps.py multigrid --levels 5 --rising 0.05 \
        --option contact_strain=tangent --option contact_sweeps=300

``--edge`` also prints, for each level from 33 x 33 up, the strain at the end of the
structural springs that bridge the table's edge (one end on the top, the other on a side
face, each within 1.5 mm of the grown box's surface) and of those lying on the top and on
the sides; ``--friction`` sets the table's and the ground's friction coefficient,
``--contraction`` the springs' resistance to compression; ``--rising`` makes the table a
moving body (a box the solver's moving-body contact handles) rising at that speed (m/s;
0: still) instead of part of the static scene (``--edge`` then measures where it started).
"""

import argparse
import time

from hcloth_ros.core import ClothBuilder, Control, make_solver, Placement, State
from hcloth_ros.core.kernels.layout import STENCIL_DC, STENCIL_DR
from hcloth_ros.core.scene import make_scene
from hcloth_ros.params import assignments
import numpy as np

TABLE = (0.0, 0.0, 0.35, 0.3, 0.3, 0.35)      # centre xyz, half extents xyz (m)
MARGIN = 0.002                                # m
OPTIONS = {'implicit': {'tolerance': 1e-4, 'strain_limit': None}}


def flaps(solver_name, levels, k_bend, contact_rounds=16, seconds=4.0, dt=1 / 60,
          extra=None, friction=0.5, contraction=None, rising=None):
    """
    Drop the cloth and measure it.

    ``extra``: more solver options; ``contraction``: the springs' resistance to
    compression, one value per level (default 1); ``rising``: the table as a moving body
    rising at this speed (m/s), None: part of the static scene.

    Returns the flaps' lowest and highest z (m) or None, the largest strain over the run,
    its range over the last 3 s, in the last step, where the most stretched finest spring
    is at the end (x, y, z of its first point), the mean seconds a step took, and the
    model and state at the end.
    """
    boxes = [TABLE] if rising is None else []
    scene = make_scene(ground_z=0.0, boxes=boxes, friction=friction, margin=MARGIN)
    model = ClothBuilder(resolution=(9, 9), level_count=levels, scene=scene, air_drag=1.0,
                         k_bend=k_bend, contraction=contraction,
                         placement=Placement(origin=(-0.5, -0.5, 1.0))).finalize()
    state, control = State.at_rest(model), Control(model)

    def place(step):
        if rising is not None:
            control.bodies.set_pose('table', np.eye(3),
                                    TABLE[:2] + (TABLE[2] + rising * step * dt,))
    if rising is not None:
        control.bodies.add('table', 'box', TABLE[3:], friction=friction)
        place(0)
        control.bodies.commit()
    solver = make_solver(solver_name, model, contact_rounds=contact_rounds,
                         **OPTIONS.get(solver_name, {}), **(extra or {}))
    worst, steps, start = 0.0, int(round(seconds / dt)), time.perf_counter()
    late = []
    for i in range(steps):
        place(i + 1)
        report = solver.step(state, control, dt)
        if not report.ok:
            raise RuntimeError(f'{solver_name}: {report.reason}')
        worst = max(worst, report.max_strain)
        if (i + 1) * dt > seconds - 3.0:
            late.append(report.max_strain)
    seconds = (time.perf_counter() - start) / steps
    points = state.points(levels - 1)
    flap = points[np.abs(points[:, 0]) > 0.45, 2]
    return ((float(flap.min()), float(flap.max())) if flap.size else None, worst,
            (min(late), max(late)), report.max_strain, _most_stretched(model, state), seconds,
            model, state)


def _most_stretched(model, state):
    """
    Where the finest level's most stretched spring starts (m).

    Over the springs the reported strain covers (structural and shear, the stencil's
    directions 0, 2, 4, 6: see ``kernels.strain_stats``).
    """
    k = model.level_count - 1
    q, rest = state.q[k], model.level(k).rest
    best, where = -1.0, None
    for s in range(0, 8, 2):
        strain, first, _ = _strains(q, rest, s)
        i = np.unravel_index(np.argmax(strain), strain.shape)
        if strain[i] > best:
            best, where = strain[i], q[(slice(None),) + first][:, i[0], i[1]]
    return where


def _strains(q, rest, s):
    """
    Strains of a level's springs of stencil direction s.

    Returns them (an array over the springs' first points) and the index slices of their
    first and second points in the level's grid.
    """
    rows, cols = q.shape[1:]
    dr, dc = STENCIL_DR[s], STENCIL_DC[s]
    r0, c0 = max(0, -dr), max(0, -dc)
    r1, c1 = rows - max(0, dr), cols - max(0, dc)
    first = (slice(r0, r1), slice(c0, c1))
    second = (slice(r0 + dr, r1 + dr), slice(c0 + dc, c1 + dc))
    strain = np.linalg.norm(q[(slice(None),) + second] - q[(slice(None),) + first],
                            axis=0) / rest[s] - 1.0
    return strain, first, second


def edge_springs(model, state, first=2):
    """
    Strains of the structural springs across the table's edge, on its top and on its sides.

    For each level from ``first`` up: ``(level, across, top, sides)``, each an array of
    strains at the end. A point is on the top (on a side) when it lies within 1.5 mm of
    the grown box's top face (of a side face, below the top).
    """
    cx, cy, _, hx, hy, hz = TABLE
    top_z = TABLE[2] + hz + MARGIN
    out = []
    for k in range(first, model.level_count):
        q, rest = state.q[k], model.level(k).rest
        top = np.abs(q[2] - top_z) < 0.0015
        side = ((np.abs(np.abs(q[0] - cx) - hx - MARGIN) < 0.0015)
                | (np.abs(np.abs(q[1] - cy) - hy - MARGIN) < 0.0015)) & (q[2] < top_z - 0.0015)
        across, on_top, on_sides = [], [], []
        for s in (0, 2):        # the structural springs along rows and along columns
            strain, a, b = _strains(q, rest, s)
            across.append(strain[(top[a] & side[b]) | (side[a] & top[b])])
            on_top.append(strain[top[a] & top[b]])
            on_sides.append(strain[side[a] & side[b]])
        out.append((k, *(np.concatenate(x) for x in (across, on_top, on_sides))))
    return out


def _summary(strains):
    if not strains.size:
        return 'none'
    return (f'{strains.size} springs, mean {strains.mean():.3f}, '
            f'{strains.min():.3f} .. {strains.max():.3f}')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('solvers', nargs='+')
    parser.add_argument('--levels', type=int, default=2)
    parser.add_argument('--k-bend', type=float, default=100.0, help='N/m')
    parser.add_argument('--contact-rounds', type=int, nargs='+', default=[16],
                        help="the solvers' contact_rounds, each in turn")
    parser.add_argument('--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a solver option (a YAML value) for every solver, repeatable, '
                             'e.g. strain_refine_iterations=30')
    parser.add_argument('--friction', type=float, default=0.5,
                        help="the table's and the ground's friction coefficient")
    parser.add_argument('--contraction', type=float, nargs='+',
                        help="the springs' resistance to compression in [0, 1], one value "
                             'per level, coarsest first (default 1 on every level)')
    parser.add_argument('--rising', type=float,
                        help='the table as a moving body rising at this speed (m/s)')
    parser.add_argument('--edge', action='store_true',
                        help="print the strains of the springs across the table's edge")
    args = parser.parse_args(argv)
    extra = assignments(args.option)
    for rounds in args.contact_rounds:
        for name in args.solvers:
            heights, worst, late, last, spot, seconds, model, state = flaps(
                name, args.levels, args.k_bend, rounds, extra=extra, friction=args.friction,
                contraction=args.contraction, rising=args.rising)
            where = ('no point beyond 0.45 m: the flaps hang inside it' if heights is None
                     else f'flaps at z = {heights[0]:.3f} .. {heights[1]:.3f} m')
            print(f'{name:12s} contact_rounds {rounds:3d}: {where}; largest strain '
                  f'{worst:.3f} over the run, {late[0]:.3f} .. {late[1]:.3f} over the last '
                  f'3 s, {last:.3f} at the end (most stretched spring from '
                  f'{np.round(spot, 3)} m); {seconds * 1e3:.1f} ms a step', flush=True)
            for k, across, on_top, on_sides in (edge_springs(model, state) if args.edge
                                                else ()):
                rows, cols = model.level(k).shape
                print(f'    level {k} ({rows} x {cols}) strain at the end: across the edge '
                      f'{_summary(across)}; on the top {_summary(on_top)}; on the sides '
                      f'{_summary(on_sides)}', flush=True)


if __name__ == '__main__':
    main()
