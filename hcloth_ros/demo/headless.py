"""
Headless engine demo: simulate a scene from ``config/`` and draw it to PNG.

    hcloth_demo [--scene config/hanging.yaml] [--seconds 3] [--out out/demo]

Writes ``snapshots.png`` (the finest level and level 0 at a few instants) and
``curves.png`` (centre-of-mass height, largest strain and step time over the run), and
prints the step-time figures.
"""

import argparse
import os
import time

from hcloth_ros import params
from hcloth_ros.core import warm_up
from hcloth_ros.core.metrics import centre_of_mass
from hcloth_ros.core.recovery import step_with_retries
import numpy as np


def simulate(values, seconds, snapshot_times, progress=True):
    """Run the scene; returns snapshots, per-step curves and the model."""
    model, solver, state, control = params.build_all(values)
    dt = float(values['solver.dt'])
    steps = int(round(seconds / dt))
    marks = {int(round(t / dt)): t for t in snapshot_times}
    shots, curves = [], {'t': [], 'com_z': [], 'max_strain': [], 'step_ms': []}
    finest = model.level_count - 1
    for i in range(steps + 1):
        if i in marks:
            shots.append((marks[i], state.copy()))
        if i == steps:
            break
        # as the node steps: a refused step again in smaller ones (core.recovery)
        start = time.perf_counter()
        report, taken = step_with_retries(solver, state, control, dt)
        seconds = time.perf_counter() - start
        if taken == 0:
            print(f'[demo] step {i}: {report.reason}')
        elif taken > 1:
            print(f'[demo] step {i}: {report.extra["refused"]}; retried as {taken} steps')
        curves['t'].append(state.time)
        curves['com_z'].append(centre_of_mass(model, state, finest)[2])
        curves['max_strain'].append(report.peak_strain)
        curves['step_ms'].append(seconds * 1e3)
        if progress and (i + 1) % max(1, steps // 10) == 0:
            print(f'[demo] {100 * (i + 1) // steps:3d} %  t = {state.time:5.2f} s  '
                  f'step {seconds * 1e3:6.2f} ms  max strain {report.peak_strain:.3f}',
                  flush=True)
    return model, shots, {k: np.asarray(v) for k, v in curves.items()}


def _draw_mesh(ax, model, state, k, color, alpha):
    p = state.points(k)
    tri = model.grid_triangles(k)
    ax.plot_trisurf(p[:, 0], p[:, 1], p[:, 2], triangles=tri, color=color, alpha=alpha,
                    linewidth=0.1 if k else 0.6, edgecolor='k' if k == 0 else None,
                    shade=True)


def plot_snapshots(model, shots, path, title):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=(4 * len(shots), 4.4))
    allp = np.concatenate([s.points(model.level_count - 1) for _, s in shots])
    lo, hi = allp.min(0), allp.max(0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2 + 0.05
    for i, (t, state) in enumerate(shots):
        ax = fig.add_subplot(1, len(shots), i + 1, projection='3d')
        _draw_mesh(ax, model, state, model.level_count - 1, 'tab:orange', 0.9)
        _draw_mesh(ax, model, state, 0, 'none', 0.0)
        for d, setter in enumerate((ax.set_xlim, ax.set_ylim, ax.set_zlim)):
            setter(centre[d] - half, centre[d] + half)
        ax.view_init(elev=18, azim=-60)
        ax.set_title(f't = {t:.2f} s')
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_curves(curves, path, title):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.5))
    for ax, key, label in zip(axes, ('com_z', 'max_strain', 'step_ms'),
                              ('centre of mass height (m)', 'largest strain (-)',
                               'step time (ms)')):
        ax.plot(curves['t'], curves[key])
        ax.set_xlabel('simulated time (s)')
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scene', default=params.config_path('hanging.yaml'),
                        help='ROS 2 parameter file of the scene')
    parser.add_argument('--seconds', type=float, default=3.0, help='simulated time (s)')
    parser.add_argument('--out', default='out/demo', help='output folder')
    args = parser.parse_args(argv)
    values = params.resolve(params.load_file(args.scene))
    print(f'[demo] scene {args.scene}')
    print('[demo] warming up the numba kernels ...', flush=True)
    print(f'[demo] warm-up took {warm_up():.2f} s')
    times = [0.0, 0.25, 0.5, 1.0, args.seconds]
    start = time.perf_counter()
    model, shots, curves = simulate(values, args.seconds, times)
    wall = time.perf_counter() - start
    os.makedirs(args.out, exist_ok=True)
    name = os.path.splitext(os.path.basename(args.scene))[0]
    lv = model.level(model.level_count - 1)
    title = (f'{name}: {values["solver.name"]} ({values["solver.external"]} gravity), '
             f'{model.level_count} levels, finest {lv.rows}x{lv.cols}, '
             f'dt = {float(values["solver.dt"]) * 1e3:.1f} ms')
    snap, curve = os.path.join(args.out, 'snapshots.png'), os.path.join(args.out, 'curves.png')
    plot_snapshots(model, shots, snap, title)
    plot_curves(curves, curve, title)
    ms = curves['step_ms']
    print(f'[demo] {len(ms)} steps in {wall:.2f} s wall; step median {np.median(ms):.2f} ms, '
          f'p99 {np.percentile(ms, 99):.2f} ms; real-time factor '
          f'{args.seconds / (ms.sum() / 1e3):.1f} (step time only)')
    print(f'[demo] final largest strain {curves["max_strain"][-1]:.3f}, '
          f'centre of mass z {curves["com_z"][-1]:.3f} m')
    print(f'[demo] wrote {snap} and {curve}')


if __name__ == '__main__':
    main()
