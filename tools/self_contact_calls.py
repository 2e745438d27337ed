"""
Self-contact's kernel calls step by step on the contact bench's folded drop.

    .venv/bin/python tools/self_contact_calls.py [--size 129] [--steps 60] [--every 5] \
        [--contact-strain jacobi] [--solver hierarchical]

The folded cloth of ``hcloth_contact_bench`` (``multigrid`` or ``--solver``, thickness
4 mm, one numba thread) falls onto the ground; each self-contact kernel call of the
finest level is timed and printed with the pairs its first detection found, how many
points it was told had moved and whether it kept the patch boxes of the call before
(and tested the paths from where the step's last clean call ended),
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
"""

import argparse
import time

import numba
import numpy as np


# the kernel's reuse argument (BOXES_NEW, BOXES_KEPT, BOXES_KEPT_NEW_START)
BOXES = ('new', 'kept', 'kept, paths from the last clean call')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--size', type=int, default=129)
    parser.add_argument('--steps', type=int, default=60)
    parser.add_argument('--every', type=int, default=5, help='print every n-th step')
    parser.add_argument('--contact-strain', choices=('tangent', 'jacobi'),
                        help="the contact rounds' strain limiting (default: the solver's)")
    parser.add_argument('--solver', default='multigrid', choices=('multigrid', 'hierarchical'))
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    from hcloth_ros.bench.self_contact import in_contact, scene_setup
    from hcloth_ros.core import make_solver
    from hcloth_ros.core import self_contact as wrapper
    model, state, control = scene_setup(args.size, 'folded')
    options = {} if args.contact_strain is None else {'contact_strain': args.contact_strain}
    solver = make_solver(args.solver, model, thickness=0.004, **options)
    solver.step(state, control, 1 / 60)            # compile or load
    finest = model.level_count - 1
    kit = solver.kernels(finest)
    calls = []

    def timed(*arguments):
        start = time.perf_counter()
        result = kit.self_contact(*arguments)
        # arguments 7 and -2: the moved-points mask and whether boxes are kept (the last
        # one: the crease angle)
        calls[-1].append((time.perf_counter() - start, result[0],
                          int(np.count_nonzero(arguments[7])), arguments[-2]))
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
    for step in range(args.steps):
        calls.append([])
        carries.append((0.0, 0))
        solver.step(state, control, 1 / 60)
        if step % args.every == 0:
            print(f'step {step + 1}: ' + ' | '.join(
                f'{1e3 * t:.2f} ms, {pairs} pairs, {moved} moved, boxes {BOXES[kept]}'
                for t, pairs, moved, kept in calls[-1])
                + f'; carry {1e3 * carries[-1][0]:.2f} ms, {carries[-1][1]} points moved',
                flush=True)
    wrapper.carry = kernel_carry
    totals = [1e3 * (sum(c[0] for c in step) + carried[0])
              for step, carried in zip(calls, carries)]
    later = [1e3 * sum(c[0] for c in step[1:]) for step in calls]
    settled = (f'{np.median(totals[20:]):.2f} ms from step 21 on' if len(totals) > 20
               else 'no steps from step 21 on')
    print(f'kernel a step: median {np.median(totals):.2f} ms over all {len(totals)} steps, '
          f'{settled}; mean {np.mean(totals):.2f} ms, '
          f'90th percentile {np.percentile(totals, 90):.2f} ms, largest {max(totals):.2f} ms; '
          f"the calls after a step's first: median {np.median(later):.2f} ms a step, "
          f'{np.mean([len(step) for step in calls]):.2f} calls a step')
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


if __name__ == '__main__':
    main()
