"""
The node's step without ROS: its scene from the parameter table, stepped as its timer does.

Builds the scene the node builds (``params.build_all`` with the node's defaults and the
given overrides), simulates every level, and times ``step_with_retries`` over ``--steps``
steps after ``--skip`` untimed ones, on ``--threads`` numba threads. Prints the p50 and p99
and the p50 of each window of ``--window`` steps (the step grows as a swing goes on).
The README's figures for "the node's own scene without ROS":

    .venv/bin/python tools/node_step.py --threads 2 -p cloth.levels=6 -p solver.accurate_level=3
    .venv/bin/python tools/node_step.py --threads 1 -p cloth.levels=4 -p solver.accurate_level=3
"""

import argparse
import time

import numba
import numpy as np


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--threads', type=int, default=1)
    parser.add_argument('--steps', type=int, default=400)
    parser.add_argument('--skip', type=int, default=30)
    parser.add_argument('--window', type=int, default=100)
    parser.add_argument('-p', '--param', action='append', default=[], metavar='NAME=VALUE',
                        help='a parameter override (YAML value), repeatable')
    args = parser.parse_args(argv)
    from hcloth_ros import params
    from hcloth_ros.core import warm_up
    from hcloth_ros.core.blas import limit_openblas_threads
    from hcloth_ros.core.recovery import step_with_retries
    numba.set_num_threads(args.threads)
    limit_openblas_threads(1)      # as the node does
    values = params.resolve(params.overrides(args.param))
    warm_up(solvers=[values['solver.name']], parallel=args.threads > 1, energy=False)
    model, solver, state, control = params.build_all(values)
    if hasattr(solver, 'set_finest_level'):
        solver.set_finest_level(model.level_count - 1, state, control)
    dt = float(values['solver.dt'])
    times = []
    for _ in range(args.skip + args.steps):
        start = time.perf_counter()
        step_with_retries(solver, state, control, dt)
        times.append(time.perf_counter() - start)
    ms = np.asarray(times[args.skip:]) * 1e3
    windows = ' '.join(f'{np.median(ms[a:a + args.window]):.1f}'
                       for a in range(0, ms.size, args.window))
    print(f'{model.level_count} levels, {args.threads} thread(s), steps {args.skip}-'
          f'{args.skip + ms.size}: p50 {np.median(ms):.2f} ms, p99 '
          f'{np.percentile(ms, 99):.2f} ms; p50 per {args.window} steps: {windows}')


if __name__ == '__main__':
    main()
