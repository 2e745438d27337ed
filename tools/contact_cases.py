"""
The contact cases the README's limits quote, each printed as a few figures.

    .venv/bin/python tools/contact_cases.py inside [--solver multigrid]
    .venv/bin/python tools/contact_cases.py ball [--solver multigrid]
    .venv/bin/python tools/contact_cases.py finger [--solver multigrid]
    .venv/bin/python tools/contact_cases.py far [--solver multigrid] [--jump 2.83]

(``--option NAME=VALUE``, repeatable: a solver option for the first three, e.g.
``contact_relaxation=1.8``.)

``inside``: a 1 m cloth started across a box (169 of its 1089 finest points inside): when
the last point leaves, and the largest strain over the first and the second second.
``ball``: a 0.1 m ball rising at 1 m/s under a falling 1 m cloth: the largest strain and
the refused steps. ``finger``: a capsule pressing a 0.4 m cloth onto the ground and
moving 0.2 m/s along x for 50 steps: how far the points it presses and the whole cloth
moved, and the largest strain. All at dt = 1/60 s, 3 levels (33 x 33 finest). ``far``:
the node's default scene (65 x 65 finest) with self-contact (4 mm), its free corner
grasped and sent ``--jump`` m in one step (a quarter turn round a frame beside it): how
long one try of the step takes and whether it goes through.
"""

import argparse
import time

from hcloth_ros.bench.self_contact import ALONG_Y     # the capsule's axis on y
from hcloth_ros.core import ClothBuilder, Control, make_scene, make_solver, Placement, State
from hcloth_ros.core.recovery import step_with_retries
from hcloth_ros.params import assignments
import numpy as np

DT = 1 / 60


def _model(size, origin, scene=None):
    return ClothBuilder(resolution=(9, 9), level_count=3, width=size, height=size, scene=scene,
                        placement=Placement(origin, (1, 0, 0), (0, 1, 0))).finalize()


def inside(solver_name, options):
    box = np.array([0.0, 0.0, 0.5, 0.2, 0.2, 0.1])
    model = _model(1.0, (-0.5, -0.5, 0.5), make_scene(ground_z=0.0, boxes=[box]))
    state, control = State.at_rest(model), Control(model)
    solver = make_solver(solver_name, model, **options)
    out, strain = None, [0.0, 0.0]
    for i in range(120):
        report, _ = step_with_retries(solver, state, control, DT)
        points = state.points(2)
        if out is None and not np.all(np.abs(points - box[:3]) < box[3:], axis=1).any():
            out = (i + 1) * DT
        strain[i // 60] = max(strain[i // 60], report.peak_strain)
    print(f'{solver_name}: out after {out} s; largest strain {strain[0]:.2f} in the first '
          f'second, {strain[1]:.2f} in the second')


def ball(solver_name, options):
    model = _model(1.0, (-0.5, -0.5, 0.4))
    state, control = State.at_rest(model), Control(model)
    solver = make_solver(solver_name, model, **options)
    control.bodies.add('ball', 'sphere', [0.1], friction=0.5)
    worst, refused = 0.0, 0
    for i in range(60):
        control.bodies.set_pose('ball', np.eye(3), (0.0, 0.0, (i + 1) * DT))
        report = solver.step(state, control, DT)
        refused += not report.ok
        worst = max(worst, report.max_strain)
    print(f'{solver_name}: largest strain {worst:.2f}, {refused} of 60 steps refused')


def finger(solver_name, options):
    model = _model(0.4, (-0.2, -0.2, 0.002), make_scene(ground_z=0.0))
    state, control = State.at_rest(model), Control(model)
    solver = make_solver(solver_name, model, **options)
    control.bodies.add('finger', 'capsule', [0.01, 0.03], friction=0.8)
    x, worst = 0.0, 0.0
    start = state.points(2)
    pressed = (np.abs(start[:, 0]) < 0.005) & (np.abs(start[:, 1]) < 0.03)
    for i in range(60):
        x += 0.2 * DT if i >= 10 else 0.0
        control.bodies.set_pose('finger', ALONG_Y, (x, 0.0, 0.009))      # 3 mm into the cloth
        worst = max(worst, solver.step(state, control, DT).max_strain)
    moved = state.points(2)[:, 0] - start[:, 0]
    print(f'{solver_name}: finger moved {x:.3f} m, the points it pressed first '
          f'{moved[pressed].mean():.3f} m, the whole cloth {moved.mean():.3f} m; largest '
          f'strain {worst:.2f}')


def far(solver_name, jump):
    from hcloth_ros import params
    from hcloth_ros.simulation import Simulation
    sim = Simulation.build(params.resolve({'solver.name': solver_name,
                                           'self_contact.thickness': 0.004}))
    corner = sim.state.points_by_id(sim.model, 3)[80]
    frame = corner - [0.0, jump / np.sqrt(2.0), 0.0]
    sim.apply(['grasp', 'g', [80], np.eye(3).tolist(), frame.tolist()])
    sim.apply(['move', 'g', [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
               frame.tolist()])
    sim.solver.step(sim.state.copy(), sim.control, DT)    # kernels loaded, not timed
    start = time.perf_counter()
    report = sim.solver.step(sim.state, sim.control, DT)
    print(f'far: corner sent {jump:.2f} m in one step: {time.perf_counter() - start:.3f} s, '
          + ('went through' if report.ok else report.reason))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('case', choices=('inside', 'ball', 'finger', 'far'))
    parser.add_argument('--solver', default='multigrid')
    parser.add_argument('--jump', type=float, default=2.83, help='far: metres (default 2.83)')
    parser.add_argument('--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a solver option (YAML value), repeatable')
    args = parser.parse_args(argv)
    if args.case == 'far':
        if args.option:
            parser.error("far takes the node's parameters, not --option")
        far(args.solver, args.jump)
    else:
        {'inside': inside, 'ball': ball, 'finger': finger}[args.case](
            args.solver, assignments(args.option))


if __name__ == '__main__':
    main()
