"""
The multigrid solver's Newton residual after its fixed count, and what iterating on costs.

    .venv/bin/python tools/newton_residuals.py [--seconds 1]

For free scenes (no contact) that the README's "In the node" quotes, the residual left
after the fixed ``newton_iterations`` (the report's ``fixed_count_residual``, in units of
``newton_tolerance`` times ``beta M g``; above 1 the step iterates on) over ``--seconds``
of simulated time with ``newton_tolerance_steps='all'``, its median, p90 and largest, and
the share of steps that took more iterations; then whether the same scene with
``newton_tolerance_steps='moved'`` (a free cloth takes the fixed count unless its residual
is above ``RUNAWAY`` tolerances) stays stable.
One numba thread.
"""

import argparse

import numba
import numpy as np

# label, scenario, finest side, levels, dt (s), spring stiffness (N/m), solver options
SCENES = (
    ('65 x 65 swing solved on 65 x 65', 'swing', 65, 4, 1 / 60, 1000.0,
     {'accurate_level': None}),
    ('65 x 65 grasp solved on 65 x 65', 'grasp', 65, 4, 1 / 60, 1000.0,
     {'accurate_level': None}),
    ('65 x 65 swing, default', 'swing', 65, 4, 1 / 60, 1000.0, {}),
    ('17 x 17 swing, k = 1e5 N/m, 1/30 s', 'swing', 17, 3, 1 / 30, 1e5, {}),
)


def residuals(scenario, n, levels, dt, k, options, seconds):
    """Return each step's residual after the fixed count and its Newton iterations."""
    from hcloth_ros.bench.scenarios import build_model, prepare
    from hcloth_ros.core import make_solver, State
    model = build_model(n, levels, k=k)
    state = State.at_rest(model)
    setup = prepare(scenario, model, state)
    solver = make_solver('multigrid', model, newton_tolerance_steps='all', **options)
    left, iterations = [], []
    for i in range(int(round(seconds / dt))):
        if setup.drive is not None:
            setup.drive((i + 1) * dt)
        report = solver.step(state, setup.control, dt)
        if not report.ok:
            raise RuntimeError(f'step {i + 1} refused: {report.reason}')
        left.append(report.extra['fixed_count_residual'])
        iterations.append(report.newton_iterations)
    return np.array(left), np.array(iterations)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=1.0)
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    from hcloth_ros.bench import errors
    from hcloth_ros.bench.scenarios import simulate
    for label, scenario, n, levels, dt, k, options in SCENES:
        left, iterations = residuals(scenario, n, levels, dt, k, options, args.seconds)
        moved = simulate(scenario, 'multigrid', n, levels, dt, args.seconds, k=k,
                         options=dict(options, newton_tolerance_steps='moved'))
        print(f'{label}: residual after the fixed count (tolerances) median '
              f'{np.median(left):.2f}, p90 {np.percentile(left, 90):.2f}, most '
              f'{left.max():.1f}; {np.mean(iterations > iterations.min()):.0%} of the steps '
              f'iterated on; with moved: {errors.classify(moved)}', flush=True)


if __name__ == '__main__':
    main()
