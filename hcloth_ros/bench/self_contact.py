"""
What contact costs a step: self-contact, and a moving finger on a cloth on the ground.

    hcloth_contact_bench [--sizes 129,257] [--steps 60] [--thickness 0.004]
                         [--intervals 1,4] [--rounds 0,16] [--json FILE]
                         [--option NAME=VALUE ...]

For each finest size the ``multigrid`` solver (default options but those given with
``--option``, level 0 9 x 9) runs two scenes, with self-contact off and on every n-th step
for each ``--intervals`` n:

* ``swing``: the benchmark's cloth pinned at two corners swings from horizontal: nothing
  of it comes near itself, the cost of checking;
* ``folded``: the cloth folded in two (2 cm between the layers) falls 10 cm onto the
  ground, the top layer onto the bottom one: the cost of contact over the whole sheet;
* ``finger``: the cloth lies on the ground and a capsule (radius 1 cm, 40 cm long,
  friction 0.8) reaching 2 mm below it drags it along x at 0.2 m/s, self-contact off, for
  each ``--rounds`` value of the solver's ``contact_rounds``: the moving body's kernel
  (the kernel's time is that of ``body_contact`` on the finest level) and the rounds of
  strain limiting and contact.

Prints, per scene and setting, the median and p90 over the steps of the self-contact
kernel's time in a step (its calls summed, 0 on steps without a check), the whole step's
median, the most pairs one check found and the largest finest strain of the run, and the
kernel's median over the steps whose check found pairs (the layers in contact: at 129 x
129 the folded drop's layers touch at steps 3-5, land at 26-33 and slide over each other
from 48 on, and lie apart in between), with the thread count and the load average. The
kernel is serial: one thread whatever ``NUMBA_NUM_THREADS`` says; the rest of the step
follows it.
"""

import argparse
import contextlib
import json
import os
import time

from hcloth_ros.bench.scenarios import build_model, prepare
from hcloth_ros.core import Control, make_scene, make_solver, State
from hcloth_ros.core import self_contact as self_contact_wrapper
from hcloth_ros.core.self_contact import thickness_warning
from hcloth_ros.params import assignments
import numba
import numpy as np

GAP = 0.02


def folded(q, height, gap=GAP):
    """
    Fold a flat level ``(3, rows, cols)`` (lying along +y) in two at its middle, unstretched.

    The bottom half lies at ``height``, the fold is a half circle of diameter ``gap``, the
    top half lies ``gap`` above the bottom one, going back: every row keeps its distance
    along the cloth.
    """
    radius = gap / 2
    arc = np.pi * radius
    v = q[1, :, 0] - q[1, 0, 0]
    start = v[-1] / 2 - arc / 2            # where the fold begins along the cloth
    out = q.copy()
    for r, s in enumerate(v - start):
        if s < 0.0:
            y, z = v[r], 0.0
        elif s <= arc:
            y, z = start + radius * np.sin(s / radius), radius * (1.0 - np.cos(s / radius))
        else:
            y, z = start - (s - arc), gap
        out[1, r] = q[1, 0, 0] + y
        out[2, r] = height + z
    return out


def timed_kernel(solver, level, times, kernel='self_contact'):
    """Wrap one of a level's kernels (by name) to add its time to ``times[-1]``."""
    kit = solver.kernels(level)
    inner = getattr(kit, kernel)

    def timed(*args):
        start = time.perf_counter()
        result = inner(*args)
        times[-1] += time.perf_counter() - start
        return result

    class Timed:

        def __getattr__(self, name):
            return timed if name == kernel else getattr(kit, name)

    solver._kits[level] = Timed()


@contextlib.contextmanager
def timed_carry(times):
    """Add the time of self-contact's ``carry`` (each step, before its checks) to ``times[-1]``."""
    inner = self_contact_wrapper.carry

    def timed(*args):
        start = time.perf_counter()
        try:
            return inner(*args)
        finally:
            times[-1] += time.perf_counter() - start

    self_contact_wrapper.carry = timed
    try:
        yield
    finally:
        self_contact_wrapper.carry = inner


def scene_setup(n, scene):
    """Return ``(model, state, control)`` of a scene at finest side n."""
    levels = int(round(np.log2((n - 1) / 8))) + 1
    if scene == 'swing':
        model = build_model(n, levels)
        state = State.at_rest(model)
        return model, state, prepare('swing', model, state).control
    if scene == 'finger':       # lying on the ground, the margin above it
        model = build_model(n, levels, scene=make_scene(ground_z=1.5 - 0.002, friction=0.5))
        control = Control(model)
        control.bodies.add('finger', 'capsule', [0.01, 0.2], friction=0.8)
        return model, State.at_rest(model), control
    model = build_model(n, levels, scene=make_scene(ground_z=1.4))
    state = State.at_rest(model)
    for k in range(model.level_count):
        state.q[k] = folded(state.q[k], 1.5)
    return model, state, Control(model)


def perturb(state, seed, noise):
    """Move every level's points by normal noise of ``noise`` m (a chaotic scene's sample)."""
    rng = np.random.default_rng(seed)
    for k in range(len(state.q)):
        state.q[k] = state.q[k] + rng.normal(0.0, noise, state.q[k].shape)


# the finger's axis along y: the body's z turned onto y
ALONG_Y = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _move_finger(control, i):
    """Place the finger for step i: 2 mm below the cloth at its middle, 0.2 m/s along x."""
    control.bodies.set_pose('finger', ALONG_Y, (0.2 * i / 60, 0.5, 1.5 + 0.011 - 0.003))


def second_fold(model, state, control, steps):
    """
    Grasp the folded drop's far 6 cm strip (both layers) for a second fold; return its mover.

    The returned function, called with m = 1 .. ``steps`` before each step, turns the
    grasp 180 degrees in all about a line along y, 1 cm over the cloth's top at its
    middle (``tools/double_fold.py``, ``test_self_contact.py``'s double fold). The grasp
    is named ``'fold'``.
    """
    points = state.points_by_id(model, model.level_count - 1)
    x = points[:, 0]
    ids = np.flatnonzero(x > x.max() - 0.06)
    held = points[ids].mean(axis=0)
    axis = np.array([0.5 * (x.min() + x.max()), held[1], points[:, 2].max() + 0.01])
    control.grasp('fold', ids, state, np.eye(3), held)

    def move(m):
        angle = -np.pi * m / steps
        c, s = np.cos(angle), np.sin(angle)
        turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])   # about y
        control.move_grasp('fold', turn, axis + turn @ (held - axis))
    return move


def run(n, scene, steps, thickness, interval, rounds=16, extra=None):
    """
    Time ``steps`` steps of one scene.

    ``interval`` None: self-contact off; ``rounds``: the solver's ``contact_rounds``;
    ``extra``: more solver options.
    """
    model, state, control = scene_setup(n, scene)
    options = dict(extra or {}, contact_rounds=rounds)
    if interval is not None:
        options.update(thickness=thickness, self_contact_interval=interval)
    solver = make_solver('multigrid', model, **options)
    finest = model.level_count - 1
    finger = scene == 'finger'
    if finger:
        _move_finger(control, 0)
    solver.step(state, control, 1 / 60)        # compile or load, first allocations
    kernel, totals, pairs, strain, refused = [], [], [0], 0.0, None
    if interval is not None or finger:
        timed_kernel(solver, finest, kernel, 'body_contact' if finger else 'self_contact')
    for i in range(steps):
        if finger:
            _move_finger(control, i + 1)
        kernel.append(0.0)
        start = time.perf_counter()
        report = solver.step(state, control, 1 / 60)
        totals.append(time.perf_counter() - start)
        if not report.ok:
            refused = f'step {len(totals)} refused: {report.reason}'
            break
        pairs.append(report.extra.get('self_contact_pairs', 0))
        strain = max(strain, report.max_strain)
    ms = np.array(kernel) * 1e3
    touching = in_contact(ms, pairs[1:])
    return {'n': n, 'scene': scene, 'interval': interval, 'contact_rounds': rounds,
            'kernel_median_ms': float(np.median(ms)),
            'kernel_p90_ms': float(np.percentile(ms, 90)),
            'touching_steps': len(touching),
            'kernel_touching_median_ms': float(np.median(touching)) if len(touching) else None,
            'step_median_ms': float(np.median(totals) * 1e3), 'pairs_max': int(max(pairs)),
            'max_strain': float(strain), 'refused': refused}


def in_contact(kernel_ms, pairs):
    """
    Return the kernel's times of the steps whose check found pairs.

    ``kernel_ms`` and ``pairs``: per step (a refused last step has a time and no pairs).
    The steps with pairs are those with the layers in contact: the medians over all steps
    hold the steps where they lie apart, most of the folded drop's.
    """
    found = np.asarray(pairs[:len(kernel_ms)]) > 0
    return np.asarray(kernel_ms, dtype=float)[:len(found)][found]


def _line(r):
    setting = 'off' if r['interval'] is None else (
        'every step' if r['interval'] == 1 else f"every {r['interval']}th")
    finger = r['scene'] == 'finger'
    if finger:
        setting = f"rounds {r['contact_rounds']}"
    kernel = '' if r['interval'] is None and not finger else (
        f"kernel median {r['kernel_median_ms']:6.2f} ms, p90 {r['kernel_p90_ms']:6.2f} ms; ")
    touching = '' if r['kernel_touching_median_ms'] is None else (
        f"; in contact ({r['touching_steps']} steps) kernel median "
        f"{r['kernel_touching_median_ms']:.2f} ms")
    return (f"  {r['n']:4d} x {r['n']:<4d} {r['scene']:7s} {setting:11s} {kernel:40s}"
            f"step median {r['step_median_ms']:6.2f} ms, most pairs {r['pairs_max']:5d}, "
            f"max strain {r['max_strain']:.2f}" + touching
            + (f"; {r['refused']}" if r['refused'] else ''))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--sizes', default='129,257', help='finest sides, comma-separated')
    parser.add_argument('--steps', type=int, default=60)
    parser.add_argument('--thickness', type=float, default=0.004)
    parser.add_argument('--intervals', default='1,4',
                        help='self_contact_interval values to run, comma-separated')
    parser.add_argument('--rounds', default='0,16',
                        help='contact_rounds values for the finger scene, comma-separated')
    parser.add_argument('--json', help='also write the figures to this file')
    parser.add_argument('--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a multigrid solver option (a YAML value), repeatable, '
                             'e.g. max_newton_iterations=3')
    args = parser.parse_args(argv)
    extra = assignments(args.option)
    print(f'contact cost: self-contact thickness {args.thickness * 1e3:g} mm, multigrid '
          f'{extra or ""}, '
          f'{numba.get_num_threads()} numba thread(s), load average '
          f'{os.getloadavg()[0]:.2f}', flush=True)
    settings = [None] + [int(s) for s in args.intervals.split(',')]
    results = []
    for n in (int(s) for s in args.sizes.split(',')):
        # the 257 x 257 rows' 4 mm is about their spacing: said above their figures
        warning = thickness_warning(scene_setup(n, 'swing')[0], args.thickness)
        if warning:
            print(f'{n} x {n}: {warning}', flush=True)
        for scene in ('swing', 'folded'):
            for interval in settings:
                results.append(run(n, scene, args.steps, args.thickness, interval,
                                   extra=extra))
                print(_line(results[-1]), flush=True)
        for rounds in (int(s) for s in args.rounds.split(',')):
            results.append(run(n, 'finger', args.steps, args.thickness, None, rounds,
                               extra))
            print(_line(results[-1]), flush=True)
    print(f'load average after: {os.getloadavg()[0]:.2f}')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=1)


if __name__ == '__main__':
    main()
