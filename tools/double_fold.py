"""
The contact bench's folded drop folded again across its crease: does the cloth tangle.

    .venv/bin/python tools/double_fold.py [--size 65] [--thickness 0.004] \
        [--solver multigrid] [--fold-steps 72] [--retries] [--seed N [--noise 1e-5]] \
        [--option NAME=VALUE ...]

The folded cloth of ``hcloth_contact_bench`` (``--size`` finest points a side, one numba
thread) lands in 45 steps; a grasp then takes its far 6 cm strip (both layers) and turns
it 180 degrees about a line along y, 1 cm over the cloth's top at the middle, in
``--fold-steps`` steps; it lets go and 60 steps follow. After every step the finest
level's edges through its own triangles are counted (``tools/intersections.py``: a
tangle). Prints the steps with any, the largest finest strain (after any step, a retry's
smaller steps included: the reports' ``peak_strain``) and the
highest point above the ground at the end; every 12 fold steps a progress line.
``--retries`` steps as the node does (``core.recovery.step_with_retries``: a refused step
again in 2, 4 or 8 steps, and the node's ``solver.retry_strain`` unless ``--option`` sets
it) and prints the steps retried (as n steps; 1: taken whole after its retries stretched
further, 0: none went through).
``test_self_contact.py::test_a_cloth_folded_twice_does_not_tangle_where_its_creases_cross``
is this scene at 65 x 65 cut short after the release. ``--thickness none`` runs without
self-contact. ``--seed`` moves every level's points by normal noise of ``--noise`` m at the
start (as ``folded_seeds.py`` does): the scene is chaotic, and a fold that goes through at
one speed may tangle at the next, so seeds give a sample at one speed.
"""

import argparse

import numba


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--size', type=int, default=65, help='finest points a side')
    parser.add_argument('--thickness', default='0.004', help="m, or 'none'")
    parser.add_argument('--solver', default='multigrid')
    parser.add_argument('--fold-steps', type=int, default=72)
    parser.add_argument('--retries', action='store_true',
                        help='step as the node does: refused or overstretched steps retried')
    parser.add_argument('--seed', type=int, default=None,
                        help='perturb the start with this seed (default: none)')
    parser.add_argument('--noise', type=float, default=1e-5, help='m, per coordinate')
    parser.add_argument('--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a solver option (YAML value), repeatable')
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    from hcloth_ros.bench.self_contact import perturb, scene_setup, second_fold
    from hcloth_ros.core import make_solver
    from hcloth_ros.core.recovery import retried as was_retried, step_with_retries
    from hcloth_ros.params import assignments, PARAM_BY_NAME
    from intersections import intersections
    thickness = None if args.thickness == 'none' else float(args.thickness)
    model, state, control = scene_setup(args.size, 'folded')
    if args.seed is not None:
        perturb(state, args.seed, args.noise)
    options = assignments(args.option)
    if args.retries:
        options.setdefault('retry_strain', PARAM_BY_NAME['solver.retry_strain'].default)
    solver = make_solver(args.solver, model, thickness=thickness, **options)
    finest = model.level_count - 1
    tangled, largest, step, retried = {}, 0.0, 0, {}

    def advance(count):
        nonlocal largest, step
        for _ in range(count):
            step += 1
            if args.retries:
                report, taken = step_with_retries(solver, state, control, 1 / 60)
                if was_retried(report, taken):
                    retried[step] = taken   # 1: taken whole after its retries
            else:
                report = solver.step(state, control, 1 / 60)
            if not report.ok:
                print(f'step {step} refused: {report.reason}', flush=True)
                continue
            largest = max(largest, report.peak_strain)
            count_now = intersections(state.q[finest])[0]
            if count_now:
                tangled[step] = count_now

    advance(45)
    move = second_fold(model, state, control, args.fold_steps)
    for m in range(1, args.fold_steps + 1):
        move(m)
        advance(1)
        if m % 12 == 0:
            print(f'fold step {m} of {args.fold_steps}: largest strain so far '
                  f'{largest:.3f}, steps with a tangle {len(tangled)}', flush=True)
    control.release('fold')
    advance(60)
    ground = model.scene.planes[0, 3]
    seed = '' if args.seed is None else f', seed {args.seed}'
    print(f'{args.solver} {args.size} x {args.size}, thickness {thickness}{seed}: edges through '
          f'triangles after steps {tangled or "none"}; largest strain {largest:.3f}; highest '
          f'point {state.q[finest][2].max() - ground:.3f} m above the ground'
          + (f'; steps retried (as n smaller ones) {retried or "none"}' if args.retries
             else ''))


if __name__ == '__main__':
    main()
