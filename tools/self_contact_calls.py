"""
Self-contact's kernel calls step by step on the contact bench's folded drop.

    .venv/bin/python tools/self_contact_calls.py [--size 129] [--steps 60] [--every 5] \
        [--contact-strain jacobi] [--solver hierarchical] [--edges auto,sharp,...] \
        [--repeats 1] [--plot FILE.png] [--option NAME=VALUE ...]

The folded cloth of ``hcloth_contact_bench`` (``multigrid`` or ``--solver``, thickness
4 mm, one numba thread) falls onto the ground; each self-contact kernel call of the
finest level is timed and printed with the pairs its first detection found, how many
points it was told had moved, whether it kept the patch boxes of the call before
(and tested the paths from where the step's last clean call ended) and the minor page
faults the process took during the call (memory touched for the first time since the
system mapped it: 2.8 us each on session 47's machine; until then each call that pushed
mapped its scratch arrays afresh, about 200 faults),
and the step's ``carry`` (the layers lying on each other kept on them before the
detection, every step) with the points it moved. Last, the median of a
step's kernel time (a step makes one call or more: the step's own, the ones after its
strain limiting, and the one after the ground's rounds of strain limiting and contact)
over all steps and over the steps from 21 on, its mean, 90th percentile and largest, and
the median of the time a step spends in the calls after its first; then the median, mean
and 90th percentile over the steps whose first detection found pairs, the layers in
contact, and the median of the pairs those detections found (at 129 x 129 they touch at
steps 3-5, land at steps 26-33, lie apart until step 48 and slide over each other until
step 120 as the folded cloth opens, its bending springs resting flat; the medians over all
steps hold the steps they are apart); then
where the middle column's edges are. ``--contact-strain`` picks the contact rounds'
strain limiting (the solver's ``contact_strain``, default its own). The kernel time of a
step counts its calls and its ``carry``; the median of ``carry`` alone comes last.

``--edges`` runs the drop with each of self-contact's ``edges`` settings in turn (one run
each, ``--repeats`` rounds of them alternated, so that the machine's hour weighs on all
alike); each run follows its own motion, the drop being chaotic. ``--plot`` charts every
run's kernel time a step against issue 10's target (1.5 ms at 129 x 129): the README's
``doc/self_contact_cost.png`` is ``--steps 150 --every 1000 --edges creases,sharp,all
--repeats 2 --plot doc/self_contact_cost.png``. ``--option`` passes a solver option (a
YAML value), as ``tools/double_fold.py`` does: ``--option accurate_level=9 --option
solved_strain_limit=0.1`` has ``multigrid`` solve the finest level itself.
"""

import argparse
import os
import resource
import time

import numba
import numpy as np


# the kernel's reuse argument (BOXES_NEW, BOXES_KEPT, BOXES_KEPT_NEW_START)
BOXES = ('new', 'kept', 'kept, paths from the last clean call')


def run(size, steps, every, edges, options, solver_name):
    """
    Run the folded drop once with self-contact's ``edges``; return its per-step figures.

    Prints every ``every``-th step's calls and the run's summary; returns the kernel's time
    a step (ms, its calls and ``carry``) and the pairs each step's first detection found.
    """
    from hcloth_ros.bench.self_contact import in_contact, scene_setup
    from hcloth_ros.core import make_solver
    from hcloth_ros.core import self_contact as wrapper
    model, state, control = scene_setup(size, 'folded')
    solver = make_solver(solver_name, model, thickness=0.004, self_contact_edges=edges,
                         **options)
    solver.step(state, control, 1 / 60)            # compile or load
    finest = model.level_count - 1
    kit = solver.kernels(finest)
    calls = []

    def timed(*arguments):
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        start = time.perf_counter()
        result = kit.self_contact(*arguments)
        seconds = time.perf_counter() - start
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults
        # arguments 7 and -2: the moved-points mask and whether boxes are kept (the last
        # one: the crease angle)
        calls[-1].append((seconds, result[0], int(np.count_nonzero(arguments[7])),
                          arguments[-2], faults))
        return result

    class Timed:

        def __getattr__(self, name):
            return timed if name == 'self_contact' else getattr(kit, name)

    solver._kits[finest] = Timed()
    kernel_carry, carries = wrapper.carry, []

    def carry(*arguments):
        start = time.perf_counter()
        moved = kernel_carry(*arguments)
        carries[-1] = (time.perf_counter() - start, moved)
        return moved

    wrapper.carry = carry
    try:
        for step in range(steps):
            calls.append([])
            carries.append((0.0, 0))
            solver.step(state, control, 1 / 60)
            if step % every == 0:
                print(f'step {step + 1}: ' + ' | '.join(
                    f'{1e3 * t:.2f} ms, {pairs} pairs, {moved} moved, boxes {BOXES[kept]}, '
                    f'{faults} page faults' for t, pairs, moved, kept, faults in calls[-1])
                    + f'; carry {1e3 * carries[-1][0]:.2f} ms, {carries[-1][1]} points moved',
                    flush=True)
    finally:
        wrapper.carry = kernel_carry
    totals = [1e3 * (sum(c[0] for c in step) + carried[0])
              for step, carried in zip(calls, carries)]
    later = [1e3 * sum(c[0] for c in step[1:]) for step in calls]
    settled = (f'{np.median(totals[20:]):.2f} ms from step 21 on' if len(totals) > 20
               else 'no steps from step 21 on')
    print(f'edges {edges}: kernel a step: median {np.median(totals):.2f} ms over all '
          f'{len(totals)} steps, {settled}; mean {np.mean(totals):.2f} ms, '
          f'90th percentile {np.percentile(totals, 90):.2f} ms, largest {max(totals):.2f} ms; '
          f"the calls after a step's first: median {np.median(later):.2f} ms a step, "
          f'{np.mean([len(step) for step in calls]):.2f} calls a step, '
          f'{sum(c[4] for step in calls for c in step)} page faults in the calls')
    # the steps with layers in contact: those whose first detection found a pair (the
    # medians above also hold the steps where the layers are apart: falling, or opened)
    first = [step[0][1] if step else 0 for step in calls]
    touching = in_contact(totals, first)
    if len(touching):
        print(f'the {len(touching)} steps whose first detection found pairs: kernel a step '
              f'median {np.median(touching):.2f} ms, mean {np.mean(touching):.2f} ms, '
              f'90th percentile {np.percentile(touching, 90):.2f} ms; pairs found first '
              f'median {np.median([f for f in first if f > 0]):.0f}')
    print(f'carry: median {1e3 * np.median([c[0] for c in carries]):.3f} ms a step, '
          f'{np.median([c[1] for c in carries]):.0f} points moved')
    # whether the cloth is still folded: the fold starts with its far edge over its near one
    q, ground = state.q[finest], model.scene.planes[0, 3]
    middle = q[:, :, q.shape[2] // 2]
    print(f'at the end, along the middle column: near edge y {middle[1, 0]:.3f} m, far edge '
          f'y {middle[1, -1]:.3f} m, highest point {middle[2].max() - ground:.3f} m above '
          'the ground')
    return totals, first


def plot(runs, size, path):
    """
    Chart each run's kernel time a step against the step, with issue 10's target.

    ``runs``: ``[(edges, totals, first)]``; each run is a line, and the steps whose first
    detection found pairs (layers in contact) are dots on it.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    colours = {'auto': 'tab:blue', 'creases': 'tab:blue', 'sharp': 'tab:green',
               'all': 'tab:red'}
    fig, ax = plt.subplots(figsize=(9, 4.5))
    labelled = set()
    for edges, totals, first in runs:
        steps = np.arange(1, len(totals) + 1)
        touching = np.asarray(first[:len(totals)]) > 0
        colour = colours.get(edges, 'black')
        label = None if edges in labelled else f'edges: {edges}'
        labelled.add(edges)
        ax.plot(steps, totals, color=colour, lw=0.6, alpha=0.6)
        ax.plot(steps[touching], np.asarray(totals)[touching], 'o', ms=2.5, color=colour,
                label=label)
    ax.axhline(1.5, color='black', ls='--', lw=1, label='target, 1.5 ms')
    ax.set_yscale('log')
    ax.set_xlabel('step (1/60 s)')
    ax.set_ylabel('self-contact a step (ms, one thread)')
    ax.set_title(f'Folded drop {size} x {size}: self-contact kernel and carry a step '
                 '(dots: layers in contact)')
    ax.legend(loc='upper left', fontsize=8)
    ax.grid(True, which='both', alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f'wrote {path}')


def main(argv=None):
    """Run the drop for each ``--edges`` setting, ``--repeats`` rounds; chart them if asked."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--size', type=int, default=129)
    parser.add_argument('--steps', type=int, default=60)
    parser.add_argument('--every', type=int, default=5, help='print every n-th step')
    parser.add_argument('--contact-strain', choices=('tangent', 'jacobi'),
                        help="the contact rounds' strain limiting (default: the solver's)")
    parser.add_argument('--solver', default='multigrid', choices=('multigrid', 'hierarchical'))
    parser.add_argument('--edges', default='auto',
                        help="self-contact's edges, comma-separated: each run in turn")
    parser.add_argument('--repeats', type=int, default=1,
                        help='runs of each --edges value, alternated')
    parser.add_argument('--plot', help='chart every run to this PNG file')
    parser.add_argument('--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a solver option (YAML value), repeatable')
    args = parser.parse_args(argv)
    from hcloth_ros.core.self_contact import EDGES
    from hcloth_ros.params import assignments
    choices = args.edges.split(',')
    for edges in choices:
        if edges not in EDGES:
            parser.error(f'--edges: {edges!r} is not one of {EDGES}')
    if args.repeats < 1:
        parser.error('--repeats must be 1 or more')
    numba.set_num_threads(1)
    try:
        options = assignments(args.option)
    except ValueError as error:
        parser.error(f'--option: {error}')
    if args.contact_strain is not None:
        options['contact_strain'] = args.contact_strain
    if 'self_contact_edges' in options:
        parser.error('--option: self_contact_edges is set by --edges')
    runs = []
    for repeat in range(args.repeats):
        for edges in choices:
            print(f'== edges {edges}, run {repeat + 1} of {args.repeats}, '
                  f'load {os.getloadavg()[0]:.2f}', flush=True)
            totals, first = run(args.size, args.steps, args.every, edges, options,
                                args.solver)
            runs.append((edges, totals, first))
    if args.plot:
        plot(runs, args.size, args.plot)


if __name__ == '__main__':
    main()
