"""
The self-contact tests' thrown fold: one step taken whole and with retries.

    .venv/bin/python tools/thrown_fold.py [--speed 5] [--lifts 0,0.05,0.2]

The 65 x 65 cloth folded in two (levels 9 x 9 to 65 x 65, no ground, the top layer 2 cm
over the bottom one), self-contact 5 mm, ``multigrid``; its top layer is thrown down at
``--speed`` m/s onto the bottom one (8 cm in the 1/60 s step at 5 m/s) and, for each
``--lifts`` value above 0, a corner of the bottom layer is grasped and lifted that far
(m) in the same step. For each case it prints the largest finest strain after the step
taken whole, and as the node takes it (``core.recovery.step_with_retries`` with
``retry_strain`` 0.5): how many steps that took, the largest strain after any of them
(the report's ``peak_strain``) and after the last, and the finest level's edges through
its own triangles after the step (``tools/intersections.py``: a tangle). One numba
thread. ``test_self_contact.py``'s retry tests run this scene (:func:`thrown`).
"""

import argparse

from hcloth_ros.bench.self_contact import folded
from hcloth_ros.core import ClothBuilder, Control, make_solver, State
from hcloth_ros.core.recovery import step_with_retries
import numpy as np

THICKNESS = 0.005   # m
H = 1.0 / 60.0      # s
RETRY_STRAIN = 0.5  # the node's solver.retry_strain


def thrown(speed, retry_strain):
    """Return the folded 65 x 65 cloth, its top layer thrown down at ``speed``, and a solver."""
    model = ClothBuilder(resolution=(9, 9), level_count=4).finalize()
    state = State.at_rest(model)
    for k in range(model.level_count):
        state.q[k] = folded(state.q[k], 1.0)
        m = state.qd[k].shape[1] // 2
        state.qd[k][2, m + 1:] = -speed
    return model, state, make_solver('multigrid', model, thickness=THICKNESS,
                                     retry_strain=retry_strain)


def one_step(speed, lift, retry_strain):
    """
    Take the thrown fold's step (a bottom corner lifted ``lift`` m).

    Returns ``(peak, end, steps, q)``: the largest finest strain after any of the steps
    taken, after the last, how many there were, and the finest level's positions after.
    """
    model, state, solver = thrown(speed, retry_strain)
    control = Control(model)
    if lift > 0.0:
        corner = state.points_by_id(model, model.level_count - 1)[0]
        control.grasp('corner', [0], state, np.eye(3), corner)
        control.move_grasp('corner', np.eye(3), corner + [0.0, 0.0, lift])
    report, taken = step_with_retries(solver, state, control, H)
    if not report.ok:
        raise RuntimeError(f'the step was refused: {report.reason}')
    return report.peak_strain, report.max_strain, taken, state.q[model.level_count - 1]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--speed', type=float, default=5.0, help='m/s, the top layer down')
    parser.add_argument('--lifts', default='0,0.05,0.2',
                        help='m, a bottom corner lifted in the step (0: none)')
    args = parser.parse_args(argv)
    import numba
    from intersections import intersections
    numba.set_num_threads(1)
    for lift in (float(v) for v in args.lifts.split(',')):
        _, whole, _, q_whole = one_step(args.speed, lift, None)
        peak, end, taken, q = one_step(args.speed, lift, RETRY_STRAIN)
        print(f'thrown at {args.speed:g} m/s, corner lifted {lift * 100:g} cm: largest strain '
              f'{whole:.3f} in one step; retried as {taken} steps, {peak:.3f} at the most and '
              f'{end:.3f} after the last; edges through triangles after: '
              f'{intersections(q_whole)[0]} and {intersections(q)[0]}', flush=True)


if __name__ == '__main__':
    main()
