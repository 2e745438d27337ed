"""
Where the contact bench's finger scene spends its step: each kernel's median a step.

    .venv/bin/python tools/finger_profile.py [--size 129] [--steps 60] \
        [--option contact_relaxation=1.0]

The scene of ``hcloth_contact_bench`` (``multigrid``, 16 contact rounds, one numba thread):
the cloth lies on the ground and a capsule 2 mm below its surface drags it along x at 0.2
m/s. Every kernel call is timed and put to the level its arrays belong to
(``hcloth_ros.bench.engine.timed_steps``); prints the step's median, each kernel's median
time a step (0 in a step without a call) and mean calls a step (the 14 largest), and the
Gauss-Seidel sweeps of the finest level's tangent strain limiting calls that found a spring
over its limit (median and largest); and how far the cloth went with the finger (the
finest level's mean move along x) and the largest finest strain of the steps.
"""

import argparse

import numba
import numpy as np


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--size', type=int, default=129)
    parser.add_argument('--steps', type=int, default=60)
    parser.add_argument('--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a solver option (YAML value), repeatable')
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    from hcloth_ros.bench import self_contact as bench
    from hcloth_ros.bench.engine import timed_steps
    from hcloth_ros.core import kernels, make_solver
    from hcloth_ros.params import assignments
    model, state, control = bench.scene_setup(args.size, 'finger')
    solver = make_solver('multigrid', model,
                         **dict(assignments(args.option), contact_rounds=16))
    bench._move_finger(control, 0)
    finest_level = model.level_count - 1
    start = state.q[finest_level][0].copy()
    solver.step(state, control, 1 / 60)        # compile or load
    moves = iter(range(1, args.steps + 1))
    strains = []

    def step():
        bench._move_finger(control, next(moves))
        strains.append(solver.step(state, control, 1 / 60).max_strain)

    timed, totals = timed_steps(model, step, args.steps, kernels.KERNELS)
    keys = set().union(*timed)
    print(f'{args.size} x {args.size}, {args.steps} steps: step median '
          f'{1e3 * np.median(totals):.2f} ms; the finest level moved '
          f'{np.mean(state.q[finest_level][0] - start):.4f} m along x on average, largest '
          f'strain {max(strains):.4f}')

    def per_step(key, what):
        return [current[key][what] if key in current else 0 for current in timed]

    for key in sorted(keys, key=lambda k: -np.median(per_step(k, 0)))[:14]:
        print(f'  {key[0]} on level {key[1]}: {1e3 * np.median(per_step(key, 0)):.3f} ms a '
              f'step, {np.mean(per_step(key, 1)):.1f} calls')
    finest = ('tangent_strain_limit', model.level_count - 1)
    sweeps = [s for current in timed if finest in current for s in current[finest][2] if s]
    if sweeps:
        print(f'finest level tangent strain limiting: {len(sweeps)} calls over the limit, '
              f'sweeps median {np.median(sweeps):.0f}, largest {max(sweeps)}')


if __name__ == '__main__':
    main()
