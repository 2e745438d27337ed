"""
The contact bench's folded drop with its start perturbed: how far the finest springs stretch.

    .venv/bin/python tools/folded_seeds.py [--seeds 1,2,3,4,5,6] [--steps 200] \
        [--noise 1e-5] [--size 129] [--retries] [--intersections] \
        [--option NAME=VALUE ...]

The folded cloth of ``hcloth_contact_bench`` (129 x 129 by default, ``multigrid``, thickness
4 mm, one numba thread), every level's points moved by normal noise of ``--noise`` m (one
seed a run), falls and opens on the ground. Per seed: the largest finest strain of an
accepted step, how many accepted steps were over 0.2 (twice the strain limit) and which
steps were refused (after the fourth refusal the run stops). ``--retries`` steps as the node
does (``core.recovery.step_with_retries``: a refused step again in 2, 4 or 8 steps, and
the node's ``solver.retry_strain`` unless ``--option`` sets it) and counts those retried.
``--intersections`` counts after every accepted step the finest level's edges through its
own triangles (``tools/intersections.py``: a tangle, which self-contact's pairs may not
see) and prints the steps with any. Seed 2 tangled with the release before the free edges
were tested against edges (8.81 before a refusal, edges through triangles after steps 7-11
and 84-89); now its largest strain is 0.24 with no edge through a triangle
(doc/self_contact_log.md).
"""

import argparse

import numba


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', default='1,2,3,4,5,6')
    parser.add_argument('--steps', type=int, default=200)
    parser.add_argument('--noise', type=float, default=1e-5, help='m, per coordinate')
    parser.add_argument('--size', type=int, default=129, help='finest points a side')
    parser.add_argument('--retries', action='store_true', help='retry refused steps')
    parser.add_argument('--intersections', action='store_true',
                        help='count edges through triangles after every accepted step')
    parser.add_argument('--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a multigrid solver option, repeatable')
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    from hcloth_ros.bench.self_contact import perturb, scene_setup
    from hcloth_ros.core import make_solver
    from hcloth_ros.core.recovery import retried as was_retried, step_with_retries
    from hcloth_ros.params import assignments, PARAM_BY_NAME
    from intersections import intersections
    options = dict({'thickness': 0.004}, **assignments(args.option))
    if args.retries:
        options.setdefault('retry_strain', PARAM_BY_NAME['solver.retry_strain'].default)
    for seed in (int(s) for s in args.seeds.split(',')):
        model, state, control = scene_setup(args.size, 'folded')
        perturb(state, seed, args.noise)
        solver = make_solver('multigrid', model, **options)
        largest, over, refused, retried, tangled = 0.0, 0, [], [], {}
        for step in range(1, args.steps + 1):
            if args.retries:
                report, taken = step_with_retries(solver, state, control, 1 / 60)
                if taken and was_retried(report, taken):   # (0: refused, listed there)
                    retried.append(step)
            else:
                report = solver.step(state, control, 1 / 60)
            if not report.ok:
                refused.append(step)
                if len(refused) > 3:
                    break
                continue
            largest = max(largest, report.peak_strain)    # a retry's smaller steps too
            over += report.peak_strain > 0.2
            if args.intersections:
                count = intersections(state.q[-1])[0]
                if count:
                    tangled[step] = count
        print(f'seed {seed}: largest accepted strain {largest:.2f}, {over} steps over 0.2, '
              f'refused at steps {refused or "none"}'
              + (f', retried at {retried or "none"}' if args.retries else '')
              + (f', edges through triangles after steps {tangled or "none"}'
                 if args.intersections else ''), flush=True)


if __name__ == '__main__':
    main()
