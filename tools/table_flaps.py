"""
Drop the tests' cloth on the tests' table and report how far its flaps hang.

The README's table section quotes these figures: after 4 s at 1/60 s (air drag
1 N s/m^3), the height range of the points beyond 0.45 m from the centre along x (the flaps
over the table's x edges; the top is at 0.70 m, a flap is 0.2 m long), the largest strain
of the finest level over the run and in the last step, and the mean wall time of a step
(with the other core busy or not: see the load), for each solver given.

    .venv/bin/python tools/table_flaps.py --levels 2 multigrid implicit hierarchical
    .venv/bin/python tools/table_flaps.py --levels 2 --k-bend 0 multigrid
    .venv/bin/python tools/table_flaps.py multigrid hierarchical --levels 3 --contact-rounds 0 16
"""

import argparse
import time

from hcloth_ros.core import ClothBuilder, Control, make_solver, Placement, State
from hcloth_ros.core.scene import make_scene
import numpy as np

TABLE = (0.0, 0.0, 0.35, 0.3, 0.3, 0.35)      # centre xyz, half extents xyz (m)
OPTIONS = {'implicit': {'tolerance': 1e-4, 'strain_limit': None}}


def flaps(solver_name, levels, k_bend, contact_rounds=16, seconds=4.0, dt=1 / 60):
    """
    Drop the cloth and measure it.

    Returns the flaps' lowest and highest z (m) or None, the largest strain over the run
    and in the last step, and the mean seconds a step took.
    """
    scene = make_scene(ground_z=0.0, boxes=[TABLE], friction=0.5, margin=0.002)
    model = ClothBuilder(resolution=(9, 9), level_count=levels, scene=scene, air_drag=1.0,
                         k_bend=k_bend, placement=Placement(origin=(-0.5, -0.5, 1.0))).finalize()
    state, control = State.at_rest(model), Control(model)
    solver = make_solver(solver_name, model, contact_rounds=contact_rounds,
                         **OPTIONS.get(solver_name, {}))
    worst, steps, start = 0.0, int(round(seconds / dt)), time.perf_counter()
    for _ in range(steps):
        report = solver.step(state, control, dt)
        if not report.ok:
            raise RuntimeError(f'{solver_name}: {report.reason}')
        worst = max(worst, report.max_strain)
    seconds = (time.perf_counter() - start) / steps
    points = state.points(levels - 1)
    flap = points[np.abs(points[:, 0]) > 0.45, 2]
    return ((float(flap.min()), float(flap.max())) if flap.size else None, worst,
            report.max_strain, seconds)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('solvers', nargs='+')
    parser.add_argument('--levels', type=int, default=2)
    parser.add_argument('--k-bend', type=float, default=100.0, help='N/m')
    parser.add_argument('--contact-rounds', type=int, nargs='+', default=[16],
                        help="the solvers' contact_rounds, each in turn")
    args = parser.parse_args(argv)
    for rounds in args.contact_rounds:
        for name in args.solvers:
            heights, worst, last, seconds = flaps(name, args.levels, args.k_bend, rounds)
            where = ('no point beyond 0.45 m: the flaps hang inside it' if heights is None
                     else f'flaps at z = {heights[0]:.3f} .. {heights[1]:.3f} m')
            print(f'{name:12s} contact_rounds {rounds:3d}: {where}; largest strain '
                  f'{worst:.3f} over the run, {last:.3f} at the end; {seconds * 1e3:.1f} ms '
                  'a step', flush=True)


if __name__ == '__main__':
    main()
