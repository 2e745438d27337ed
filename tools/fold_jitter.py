"""
The fold demo in the engine alone, with the node's command timing drawn at random.

    .venv/bin/python tools/fold_jitter.py --runs 8 [--seed 0]
    .venv/bin/python tools/fold_jitter.py --runs 6 --lift 0.38
    .venv/bin/python tools/fold_jitter.py --runs 8 --lift 0.25 --stop-short 0.01 --translate-only
    .venv/bin/python tools/fold_jitter.py --runs 8 -p solver.name=multigrid \
        -p solver.accurate_level=0
    .venv/bin/python tools/fold_jitter.py --runs 8 --shed 180 --restore 270
    NUMBA_NUM_THREADS=1 .venv/bin/python tools/fold_jitter.py --runs 2 --contact-cost \
        -p cloth.levels=3

The demo's client samples its path at 30 Hz on the simulation's clock and its messages
reach the node one or two ticks later, so which tick a command lands on varies from run
to run. This script drives the fold scene (``config/fold.yaml``) through the node's own
gripper logic (:class:`~hcloth_ros.grippers.GripperBank`) with the client's path
(:func:`~hcloth_ros.demo.fold_client.fold_pose`): the client's first tick, its phase
against the node's ticks and each message's delay (1 tick, 2 in a quarter) drawn from the
seed. It prints the fold measures of each run, as the demo does; a failure seen in some
runs of the demo shows here with the seed that reproduces it. ``--lift`` and
``--stop-short`` change the client's path (its ``LIFT`` and ``SHORT``), ``--translate-only``
keeps the grippers from turning (the client before it turned them), ``-p NAME=VALUE``
overrides a parameter of the scene (a YAML value). ``--shed N --restore M`` drop the finest
level at tick N and bring it back at tick M, as the node's governor does when ticks overrun
(the restored level starts from the coarser state, the grippers re-take their points on it).
``--contact-cost`` times self-contact's kernel calls and ``carry`` on the finest level each
tick and prints their median over the ticks whose first check found pairs (the layers in
contact), against the whole tick (``cloth.levels=3``: 129 x 129, issue 10's 16k points).
"""

import argparse
import contextlib
import time

from hcloth_ros import params
from hcloth_ros.bench.self_contact import in_contact, timed_carry, timed_kernel
from hcloth_ros.demo import fold_client
from hcloth_ros.demo.fold_metrics import describe, fold_metrics
from hcloth_ros.grippers import GripperBank, points_within
from hcloth_ros.node_params import SPEC_BY_NAME
from hcloth_ros.simulation import Simulation
import numpy as np

RADIUS = 0.03       # m: the fold scene's grasp_radius
MAX_SPEED = SPEC_BY_NAME['grasp_max_speed'].default     # m/s, as the node
NAMES = ('left', 'right')


def client_messages(t, starts, far_y, turn=True):
    """Return the messages the client sends at t s into its path."""
    out = []
    if 0.3 <= t < 0.4:
        out += [('close', n, True) for n in NAMES]
    end = fold_client.DURATION + 2.0
    if t <= end:
        for n in NAMES:
            offset, quaternion = fold_client.fold_pose(starts[n], far_y, t - 0.5)
            out.append(('pose', n, (starts[n] + offset, quaternion if turn else (0, 0, 0, 1))))
    if fold_client.DURATION + 0.7 < t <= end:
        out += [('close', n, False) for n in NAMES]
    return out


def run(seed, turn=True, overrides=None, shed=None, restore=None, costs=None, prepare=None):
    """
    Fold once with the timing drawn from ``seed``; return the grids before and after.

    ``overrides``: parameter values that replace the fold scene's; ``shed``, ``restore``:
    the ticks at which the finest level is dropped and brought back (None: never).
    ``costs``: a list that gets, for each tick after the first (which compiles or loads
    the kernels), self-contact's time on the finest level (its kernel calls and
    ``carry``, ms), the pairs its first check found and the whole tick's time (ms).
    ``prepare``: called with the simulation before the first tick (the replay tool wraps
    its kernels and its ticks there to capture calls).
    """
    rng = np.random.default_rng(seed)
    values = params.load_file(params.config_path('fold.yaml'))
    values.update(overrides or {})
    values = params.resolve(values)
    sim = Simulation.build(values)
    if prepare is not None:
        prepare(sim)
    k = sim.solver.levels()[-1]
    kernel = [0.0]
    if costs is not None:
        timed_kernel(sim.solver, k, kernel)
    with timed_carry(kernel) if costs is not None else contextlib.nullcontext():
        return _fold(sim, rng, turn, shed, restore, kernel, costs)


def _fold(sim, rng, turn, shed, restore, kernel, costs):
    """Run :func:`run`'s fold on ``sim``; return the grids before and after."""
    k = sim.solver.levels()[-1]
    levels = {} if shed is None else {shed: k - 1}
    if restore is not None:
        levels[restore] = k
    before = [sim.state.points(level).copy() for level in range(k + 1)]
    pts = sim.state.points_by_id(sim.model, k)
    starts = {'left': pts[np.argmin(pts[:, 0] + pts[:, 1])],
              'right': pts[np.argmax(pts[:, 0] - pts[:, 1])]}
    far_y = pts[:, 1].max()
    bank = GripperBank(NAMES)
    first, phase = int(rng.integers(3, 20)), int(rng.integers(0, 2))
    inbox = [(first + 1, 'pose', n, (starts[n], (0, 0, 0, 1))) for n in NAMES]
    for j in range(int((fold_client.DURATION + 4.0) / sim.dt)):
        if j > first and (j - first - phase) % 2 == 0:
            lag = 2 if rng.random() < 0.25 else 1
            sent = client_messages((j - first) * sim.dt, starts, far_y, turn)
            inbox += [(j + lag,) + m for m in sent]
        if j in levels:
            sim.apply(('levels', levels[j]))
        for item in [m for m in inbox if m[0] <= j]:
            inbox.remove(item)
            if item[1] == 'pose':
                bank.set_pose(item[2], 'f', 'f', *item[3])
            else:
                bank.request_close(item[2], item[3])
        bank.apply(sim.apply, lambda p: points_within(
            sim.state.points_by_id(sim.model, sim.solver.levels()[-1]), p, RADIUS),
            MAX_SPEED * sim.dt * sim.substeps)
        kernel[-1] = 0.0
        start = time.perf_counter()
        report = sim.advance()
        if costs is not None and j > 0:
            costs.append((1e3 * kernel[-1], report.extra.get('self_contact_pairs', 0),
                          1e3 * (time.perf_counter() - start)))
    finest = sim.solver.levels()[-1]
    return before[finest], sim.state.points(finest).copy()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=8)
    parser.add_argument('--seed', type=int, default=0, help="the first run's seed")
    parser.add_argument('--lift', type=float, default=fold_client.LIFT,
                        help=f"the path's height, m (default {fold_client.LIFT})")
    parser.add_argument('--stop-short', type=float, default=fold_client.SHORT,
                        help=f'how far short of the far edge the corners stop, m (default '
                             f'{fold_client.SHORT})')
    parser.add_argument('--translate-only', action='store_true',
                        help='the grippers do not turn with the corners')
    parser.add_argument('-p', '--param', action='append', default=[], metavar='NAME=VALUE',
                        help='a parameter override (YAML value), repeatable')
    parser.add_argument('--shed', type=int, help='drop the finest level at this tick')
    parser.add_argument('--restore', type=int, help='bring it back at this tick')
    parser.add_argument('--contact-cost', action='store_true',
                        help="time self-contact's kernel calls and carry each tick")
    args = parser.parse_args(argv)
    fold_client.LIFT, fold_client.SHORT = args.lift, args.stop_short
    overrides = params.overrides(args.param)
    for seed in range(args.seed, args.seed + args.runs):
        start = time.perf_counter()
        costs = [] if args.contact_cost else None
        before, after = run(seed, not args.translate_only, overrides, args.shed, args.restore,
                            costs)
        side = int(round(np.sqrt(before.size / 3)))
        grids = (g.reshape(side, side, 3) for g in (before, after))
        print(f'seed {seed}: {describe(fold_metrics(*grids))} '
              f'({time.perf_counter() - start:.1f} s)', flush=True)
        if costs:
            print('    ' + cost_summary(costs), flush=True)


def cost_summary(costs):
    """Describe :func:`run`'s ``costs``: self-contact's time a tick where layers touch."""
    kernel, pairs, tick = (np.array(c, dtype=float) for c in zip(*costs))
    touching = in_contact(kernel, pairs)
    where = (f'{len(touching)} ticks whose first check found pairs: median '
             f'{np.median(touching):.2f} ms, 90th percentile '
             f'{np.percentile(touching, 90):.2f} ms' if len(touching) else
             'no tick found pairs')
    share = 100 * kernel.sum() / tick.sum()
    return (f'self-contact (kernel calls and carry, one thread) over the {len(kernel)} '
            f'ticks: median {np.median(kernel):.2f} ms; {where}; the whole tick median '
            f'{np.median(tick):.2f} ms, self-contact {share:.0f} % of the time of all ticks')


if __name__ == '__main__':
    main()
