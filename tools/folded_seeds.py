"""
The contact bench's folded drop with its start perturbed: how far the finest springs stretch.

    .venv/bin/python tools/folded_seeds.py [--seeds 1,2,3,4,5,6] [--steps 200] \
        [--noise 1e-5] [--retries] [--option NAME=VALUE ...]

The folded 129 x 129 cloth of ``hcloth_contact_bench`` (``multigrid``, thickness 4 mm, one
numba thread), every level's points moved by normal noise of ``--noise`` m (one seed a
run), falls and opens on the ground. Per seed: the largest finest strain of an accepted
step, how many accepted steps were over 0.2 (twice the strain limit) and which steps were
refused (after the fourth refusal the run stops). ``--retries`` steps as the node does
(``core.recovery.step_with_retries``: a refused step again in 2, 4 or 8 steps) and counts
those retried. The unperturbed drop (``--seeds 0 --noise 0``) keeps 0.37 at most; with 10
um of noise seed 2's fold tangles: a point of the bottom layer's edge ends between the two
triangles of a cell of the top layer's corner folded over it, crossed from opposite
sides, and is pushed back and forth by centimetres a step (8.81 before a refusal).
"""

import argparse

import numba
import numpy as np


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', default='1,2,3,4,5,6')
    parser.add_argument('--steps', type=int, default=200)
    parser.add_argument('--noise', type=float, default=1e-5, help='m, per coordinate')
    parser.add_argument('--retries', action='store_true', help='retry refused steps')
    parser.add_argument('--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a multigrid solver option, repeatable')
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    from hcloth_ros.bench.self_contact import scene_setup
    from hcloth_ros.core import make_solver
    from hcloth_ros.core.recovery import step_with_retries
    from hcloth_ros.params import assignments
    options = dict({'thickness': 0.004}, **assignments(args.option))
    for seed in (int(s) for s in args.seeds.split(',')):
        model, state, control = scene_setup(129, 'folded')
        rng = np.random.default_rng(seed)
        for k in range(model.level_count):
            state.q[k] = state.q[k] + rng.normal(0.0, args.noise, state.q[k].shape)
        solver = make_solver('multigrid', model, **options)
        largest, over, refused, retried = 0.0, 0, [], []
        for step in range(1, args.steps + 1):
            if args.retries:
                report, taken = step_with_retries(solver, state, control, 1 / 60)
                if taken > 1:
                    retried.append(step)
            else:
                report = solver.step(state, control, 1 / 60)
            if not report.ok:
                refused.append(step)
                if len(refused) > 3:
                    break
                continue
            largest = max(largest, report.max_strain)
            over += report.max_strain > 0.2
        print(f'seed {seed}: largest accepted strain {largest:.2f}, {over} steps over 0.2, '
              f'refused at steps {refused or "none"}'
              + (f', retried at {retried or "none"}' if args.retries else ''), flush=True)


if __name__ == '__main__':
    main()
