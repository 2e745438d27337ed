"""
Where the contact bench's finger scene spends its step: each kernel's median a step.

    .venv/bin/python tools/finger_profile.py [--size 129] [--steps 60] \
        [--option contact_relaxation=1.0]

The scene of ``hcloth_contact_bench`` (``multigrid``, 16 contact rounds, one numba thread):
the cloth lies on the ground and a capsule 2 mm below its surface drags it along x at 0.2
m/s. Every kernel call is timed and put to the level its arrays belong to; prints the step's
median, each kernel's median time a step and mean calls a step (the 14 largest), and the
Gauss-Seidel sweeps of the finest level's tangent strain limiting calls that found a spring
over its limit (median and largest).
"""

import argparse
from collections import defaultdict
import time

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
    from hcloth_ros.core import make_solver
    from hcloth_ros.params import assignments
    model, state, control = bench.scene_setup(args.size, 'finger')
    solver = make_solver('multigrid', model,
                         **dict(assignments(args.option), contact_rounds=16))
    bench._move_finger(control, 0)
    solver.step(state, control, 1 / 60)        # compile or load
    level_of = {(lv.rows, lv.cols): lv.index for lv in model.levels}
    finest = model.level_count - 1
    spent, calls, sweeps = defaultdict(float), defaultdict(int), []

    def timed(name, kernel):
        def call(*arguments):
            level = max((level_of.get(a.shape[-2:], -1) for a in arguments
                         if isinstance(a, np.ndarray) and a.ndim >= 2), default=-1)
            start = time.perf_counter()
            result = kernel(*arguments)
            spent[name, level] += time.perf_counter() - start
            calls[name, level] += 1
            if name == 'tangent_strain_limit' and level == finest and result:
                sweeps.append(result)
            return result
        return call

    class Timed:

        def __init__(self, kit):
            self.kit = kit

        def __getattr__(self, name):
            kernel = getattr(self.kit, name)
            return timed(name, kernel) if callable(kernel) else kernel

    solver._kits = [Timed(kit) for kit in solver._kits]
    per_step, per_calls, steps = defaultdict(list), defaultdict(list), []
    for i in range(args.steps):
        bench._move_finger(control, i + 1)
        spent.clear()
        calls.clear()
        start = time.perf_counter()
        solver.step(state, control, 1 / 60)
        steps.append(time.perf_counter() - start)
        for key in set(spent) | set(per_step):
            per_step[key].append(spent.get(key, 0.0))
            per_calls[key].append(calls.get(key, 0))
    print(f'{args.size} x {args.size}, {args.steps} steps: step median '
          f'{1e3 * np.median(steps):.2f} ms')
    for key in sorted(per_step, key=lambda k: -np.median(per_step[k]))[:14]:
        print(f'  {key[0]} on level {key[1]}: {1e3 * np.median(per_step[key]):.3f} ms a step, '
              f'{np.mean(per_calls[key]):.1f} calls')
    if sweeps:
        print(f'finest level tangent strain limiting: {len(sweeps)} calls over the limit, '
              f'sweeps median {np.median(sweeps):.0f}, largest {max(sweeps)}')


if __name__ == '__main__':
    main()
