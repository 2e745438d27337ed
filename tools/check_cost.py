"""
The blow-up check's cost: every simulated level against the finest alone.

    .venv/bin/python tools/check_cost.py [--calls 300] [-p NAME=VALUE ...]

On the node's scene with every level simulated (default ``-p cloth.levels=6 -p
solver.accurate_level=3``: 257 x 257 solved to 65 x 65; one numba thread, 30 steps in),
times the strain statistics of every level (the check before this release) and the
solver's check (the finest level alone, see ``Solver._check``), alternating, and prints
the medians.
"""

import argparse
import time

import numba
import numpy as np

SCENE = ('cloth.levels=6', 'solver.accurate_level=3')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--calls', type=int, default=300)
    parser.add_argument('-p', '--param', action='append', default=list(SCENE),
                        metavar='NAME=VALUE', help='a parameter override (YAML value)')
    args = parser.parse_args(argv)
    from hcloth_ros import params
    from hcloth_ros.core import warm_up
    numba.set_num_threads(1)
    values = params.resolve(params.overrides(args.param))
    warm_up(solvers=[values['solver.name']], parallel=False, energy=False)
    model, solver, state, control = params.build_all(values)
    solver.set_finest_level(model.level_count - 1, state, control)
    for _ in range(30):
        solver.step(state, control, 1 / 60)
    levels = solver.levels()

    def every_level():
        for k in levels:
            solver.kernels(k).strain_stats(solver._q[k], solver._qd[k], model.level(k).rest)

    def finest():
        solver._check(levels, state)

    times = {every_level: [], finest: []}
    for i in range(args.calls):
        for f in (every_level, finest) if i % 2 else (finest, every_level):
            start = time.perf_counter()
            f()
            times[f].append(time.perf_counter() - start)
    print(f'every level {1e3 * np.median(times[every_level]):.3f} ms, the finest alone '
          f'{1e3 * np.median(times[finest]):.3f} ms (medians of {args.calls} alternating '
          'calls)')


if __name__ == '__main__':
    main()
