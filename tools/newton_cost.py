"""
What the multigrid solver's Newton tolerance costs: the fixed three iterations against it.

    .venv/bin/python tools/newton_cost.py [--repeats 4] [--sizes 33,65]

The benchmark's swing and grasp (dt = 1/60 s, 2 s, one numba thread) with the solver's
default ``accurate_level`` and solved on the finest level, each run ``--repeats`` times
with ``max_newton_iterations=3`` (the fixed count) and with the defaults (more Newton
iterations while the residual is above tolerance), alternating, so that both see the
same machine. Prints the best and the median wall seconds per simulated second of each
and the ratio of the bests.
"""

import argparse
import os

import numba
import numpy as np

LEVELS = {17: 2, 33: 3, 65: 4}
VARIANTS = (('fixed', {'max_newton_iterations': 3}), ('tolerance', {}))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--repeats', type=int, default=4)
    parser.add_argument('--sizes', default='33,65')
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    from hcloth_ros.bench.scenarios import simulate
    print(f'1 numba thread, load average {os.getloadavg()[0]:.2f}', flush=True)
    for n in (int(v) for v in args.sizes.split(',')):
        for where, solved in (('default', {}), ('solved finest', {'accurate_level': None})):
            for scenario in ('swing', 'grasp'):
                costs = {label: [] for label, _ in VARIANTS}
                for _ in range(args.repeats):
                    for label, options in VARIANTS:
                        run = simulate(scenario, 'multigrid', n, LEVELS[n], 1 / 60, 2.0,
                                       options=dict(solved, **options))
                        costs[label].append(run.wall_per_sim_second)
                figures = ' '.join(f'{label} {min(c):.4f} (median {np.median(c):.4f})'
                                   for label, c in costs.items())
                ratio = min(costs['tolerance']) / min(costs['fixed'])
                print(f'{n} x {n} {where:13s} {scenario}: {figures}, ratio {ratio:.2f}',
                      flush=True)


if __name__ == '__main__':
    main()
