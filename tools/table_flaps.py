"""
Drop the tests' cloth on the tests' table and report how far its flaps hang.

The README's table section quotes these figures: after 4 s at 1/60 s (air drag
1 N s/m^3), the height range of the points beyond 0.45 m from the centre along x (the flaps
over the table's x edges; the top is at 0.70 m, a flap is 0.2 m long) and the largest
strain of the last step, for each solver given.

    .venv/bin/python tools/table_flaps.py --levels 2 multigrid implicit hierarchical
    .venv/bin/python tools/table_flaps.py --levels 2 --k-bend 0 multigrid
"""

import argparse

from hcloth_ros.core import ClothBuilder, Control, make_solver, Placement, State
from hcloth_ros.core.scene import make_scene
import numpy as np

TABLE = (0.0, 0.0, 0.35, 0.3, 0.3, 0.35)      # centre xyz, half extents xyz (m)
OPTIONS = {'implicit': {'tolerance': 1e-4, 'strain_limit': None}}


def flaps(solver_name, levels, k_bend, seconds=4.0, dt=1 / 60):
    """Return the flaps' lowest and highest z (m) and the last step's largest strain."""
    scene = make_scene(ground_z=0.0, boxes=[TABLE], friction=0.5, margin=0.002)
    model = ClothBuilder(resolution=(9, 9), level_count=levels, scene=scene, air_drag=1.0,
                         k_bend=k_bend, placement=Placement(origin=(-0.5, -0.5, 1.0))).finalize()
    state, control = State.at_rest(model), Control(model)
    solver = make_solver(solver_name, model, **OPTIONS.get(solver_name, {}))
    for _ in range(int(round(seconds / dt))):
        report = solver.step(state, control, dt)
        if not report.ok:
            raise RuntimeError(f'{solver_name}: {report.reason}')
    points = state.points(levels - 1)
    flap = points[np.abs(points[:, 0]) > 0.45, 2]
    return (float(flap.min()), float(flap.max())) if flap.size else None, report.max_strain


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('solvers', nargs='+')
    parser.add_argument('--levels', type=int, default=2)
    parser.add_argument('--k-bend', type=float, default=100.0, help='N/m')
    args = parser.parse_args(argv)
    for name in args.solvers:
        heights, strain = flaps(name, args.levels, args.k_bend)
        where = ('no point beyond 0.45 m: the flaps hang inside it' if heights is None
                 else f'flaps at z = {heights[0]:.3f} .. {heights[1]:.3f} m')
        print(f'{name:12s} {where}; largest strain {strain:.3f}', flush=True)


if __name__ == '__main__':
    main()
