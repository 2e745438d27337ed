"""
Engine benchmark: milliseconds per step of every solver at three cloth sizes.

Run ``hcloth_engine_bench`` (or ``python -m hcloth_ros.bench.engine``). Scene: a 1 m x 1 m
cloth pinned at its two level-0 corners ``(0, 0)`` and ``(0, cols-1)``, ``dt = 1/60``,
default solver options (strain limiting on, exact gravity), no obstacles.

Sizes (finest level, rows x cols = ``2**(L-1) * (n0 - 1) + 1`` a side):

=========  ==========  ======  =================
name       level 0     levels  finest points
=========  ==========  ======  =================
``8k``     12 x 12     4       89 x 89 = 7,921 (the paper's scale, Fig. 4: 8,192)
``16k``    9 x 9       5       129 x 129 = 16,641
``65k``    9 x 9       6       257 x 257 = 66,049
=========  ==========  ======  =================

For each size: ``explicit`` and ``approx`` on the finest level, ``hierarchical`` and
``multigrid`` (the node's default: level 1 solved, eq. 7 above) over all levels, and
``implicit`` (backward Euler, slow) on the smallest size only, from rest, with few steps.
Each configuration first runs ``--warmup`` untimed steps, then ``--steps`` timed steps
(fewer if they would exceed ``--budget`` seconds); median and p90 of the wall time of
``solver.step`` are reported, with steps per second, refused steps
(a refused step did all its work, then kept the old state: at dt = 1/60 the explicit
and single-level solvers exceed the blow-up strain here) and the mean number of
strain-limiting sweeps per level. On the largest size two variants of the hierarchical
step show what strain limiting costs: without it, and with 100 sweeps allowed on every
refinement level instead of the default 4; three of ``multigrid`` what solving more
levels costs: up to 65 x 65 (``accurate_level`` 3, the node's 257 x 257 target), the same
with one strain-limiting sweep on the refined levels, and every level. Kernel-by-kernel
breakdowns of the hierarchical step and of the multigrid step solved up to 65 x 65 are
taken on the largest size by timing every kernel call the solver makes.

Cold start: a fresh interpreter with an empty ``NUMBA_CACHE_DIR`` (a temporary directory)
imports the engine and runs :func:`hcloth_ros.core.warm_up` for the node's default
configuration and for every kernel, each in one process and over the default number of
processes (:data:`COLD_CONFIGS`); a second fresh interpreter with the now-filled cache
does the same (loads the machine code).

Timings on a shared machine are only as good as its idle cores: the load average is
printed before and after. Numba's thread count and threading layer go with every figure.
"""

import argparse
from collections import defaultdict
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np

SIZES = {
    '8k': {'resolution': 12, 'levels': 4},
    '16k': {'resolution': 9, 'levels': 5},
    '65k': {'resolution': 9, 'levels': 6},
}
DT = 1.0 / 60.0


def _side(resolution, levels):
    return 2 ** (levels - 1) * (resolution - 1) + 1


def _scene(size):
    """Model, rest state and control of a benchmark size (pinned at two corners)."""
    from hcloth_ros.core import ClothBuilder, Control, State
    spec = SIZES[size]
    model = ClothBuilder(width=1.0, height=1.0, resolution=(spec['resolution'],) * 2,
                         level_count=spec['levels']).finalize()
    control = Control(model)
    lv0 = model.level(0)
    control.pin([0, lv0.cols - 1])   # ids 0 and cols-1: the two corners of the first row
    return model, State.at_rest(model), control


def _percentile(values, p):
    return float(np.percentile(np.asarray(values), p)) if len(values) else float('nan')


def run_config(size, solver_name, steps, warmup, budget, options=None, label=None):
    """Time ``steps`` warm steps of one solver on one size; returns a dict of figures."""
    from hcloth_ros.core import make_solver
    model, state, control = _scene(size)
    solver = make_solver(solver_name, model, **(options or {}))
    newton, cg = [], []
    t_start = time.perf_counter()
    for _ in range(warmup):
        solver.step(state, control, DT)
    times, refused = [], 0
    sweeps = defaultdict(list)
    deadline = time.perf_counter() + budget
    for i in range(steps):
        t0 = time.perf_counter()
        report = solver.step(state, control, DT)
        times.append(time.perf_counter() - t0)
        refused += not report.ok
        newton.append(report.newton_iterations)
        cg.append(report.cg_iterations)
        for key, value in report.extra.items():
            if key.startswith('strain_sweeps_'):
                sweeps[int(key.rsplit('_', 1)[1])].append(value)
        if time.perf_counter() > deadline and i + 1 >= min(steps, 5 if warmup else 1):
            break
    ms = np.asarray(times) * 1e3
    lv = model.level(model.level_count - 1)
    result = {
        'size': size, 'solver': solver_name, 'label': label or solver_name,
        'options': dict(options or {}), 'resolution0': SIZES[size]['resolution'],
        'levels': model.level_count, 'finest': f'{lv.rows}x{lv.cols}',
        'points': lv.rows * lv.cols, 'simulated_levels': list(solver.levels()),
        'warmup': warmup, 'steps': len(times), 'refused': int(refused),
        'median_ms': float(np.median(ms)), 'p90_ms': _percentile(ms, 90),
        'mean_ms': float(ms.mean()), 'min_ms': float(ms.min()),
        'steps_per_second': float(1e3 / np.median(ms)),
        'strain_sweeps_mean': {k: float(np.mean(v)) for k, v in sorted(sweeps.items())},
        'wall_seconds': time.perf_counter() - t_start}
    if solver_name in ('implicit', 'multigrid'):
        result.update(newton_iterations_mean=float(np.mean(newton)),
                      cg_iterations_mean=float(np.mean(cg)))
    return result


def timed_steps(model, step, steps, names):
    """
    Call ``step()`` ``steps`` times with the named kernels timed; return what each step ran.

    The solver's calls go through the kernel sets ``kernels.SERIAL`` and
    ``kernels.PARALLEL``, whose attributes are wrapped with a timer while this runs; a
    call's level is the finest of ``model``'s levels among its array arguments (prolong and
    eq7_level also take the coarser level's arrays). Returns ``(timed, totals)``:
    ``timed[i]`` maps ``(kernel, level)`` to ``(seconds, calls, results)`` of step i (the
    kernels it called), ``totals[i]`` is the step's wall time (s). The times include numba's
    dispatch overhead.
    """
    from hcloth_ros.core import kernels
    level_of = {(lv.rows, lv.cols): lv.index for lv in model.levels}
    kits = (kernels.SERIAL, kernels.PARALLEL)
    originals = {(i, n): getattr(kit, n) for i, kit in enumerate(kits) for n in names}
    current = {}

    def wrap(name, fn):
        def timed(*args):
            level = max((level_of.get(a.shape[-2:], -1) for a in args
                         if isinstance(a, np.ndarray) and a.ndim >= 2), default=-1)
            t0 = time.perf_counter()
            out = fn(*args)
            entry = current.setdefault((name, level), [0.0, 0, []])
            entry[0] += time.perf_counter() - t0
            entry[1] += 1
            entry[2].append(out)
            return out
        return timed

    timed, totals = [], []
    try:
        for n in names:
            for i, kit in enumerate(kits):
                setattr(kit, n, wrap(n, originals[i, n]))
        for _ in range(steps):
            current = {}
            t0 = time.perf_counter()
            step()
            totals.append(time.perf_counter() - t0)
            timed.append(current)
    finally:
        for n in names:
            for i, kit in enumerate(kits):
                setattr(kit, n, originals[i, n])
    return timed, totals


def breakdown(size, steps, warmup, solver_name='hierarchical', options=None):
    """
    Time every kernel call of one solver's step (per kernel and level).

    Timed by :func:`timed_steps`. Each figure is the median over the steps that called a
    kernel on a level of its time in that step (all its calls there), including numba's
    dispatch overhead. ``python_overhead`` is the step time not spent in any kernel.
    """
    from hcloth_ros.core import make_solver
    model, state, control = _scene(size)
    solver = make_solver(solver_name, model, **(options or {}))
    for _ in range(warmup):
        solver.step(state, control, DT)
    names = ['prescribe', 'eq6_first_sweep', 'eq6_second_sweep', 'prolong', 'eq7_level',
             'strain_limit', 'contact', 'strain_stats', 'anchor', 'start_velocity',
             'newton_residual', 'assemble_hierarchy', 'multigrid_cg', 'new_positions',
             'inject']
    timed, totals = timed_steps(model, lambda: solver.step(state, control, DT), steps, names)
    per_step, sweeps = defaultdict(list), defaultdict(list)
    for current, total in zip(timed, totals):
        for (name, k), (seconds, _, results) in current.items():
            per_step[name, k].append(seconds)
            if name == 'strain_limit':
                sweeps[k].append(results[-1])
        kernel_sum = sum(seconds for seconds, _, _ in current.values())
        per_step[('python_overhead', -1)].append(total - kernel_sum)
    rows = []
    for (name, k), values in sorted(per_step.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        entry = {'kernel': name, 'level': k, 'median_ms': float(np.median(values) * 1e3),
                 'p90_ms': _percentile(np.asarray(values) * 1e3, 90)}
        if name == 'strain_limit' and sweeps.get(k):
            entry['sweeps_mean'] = float(np.mean(sweeps[k]))
            entry['ms_per_sweep'] = entry['median_ms'] / max(np.median(sweeps[k]), 1.0)
        rows.append(entry)
    return {'size': size, 'solver': solver_name, 'options': dict(options or {}),
            'steps': len(totals),
            'step_median_ms': float(np.median(totals) * 1e3), 'kernels': rows}


_COLD_CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
c0 = time.process_time()
import numba
from hcloth_ros.core import warm_up
t1 = time.perf_counter()
warm = warm_up(**json.loads(sys.argv[1]))
print(json.dumps(dict(import_s=t1 - t0, warm_up_s=warm, total_s=time.perf_counter() - t0,
                      process_cpu_s=time.process_time() - c0,
                      threading_layer=numba.threading_layer(),
                      threads=numba.get_num_threads())))
"""

# Variants timed on the largest size: what hierarchical's step costs besides strain
# limiting and with more sweeps allowed; what solving more levels costs multigrid (up to
# 65 x 65, the node's 257 x 257 target, and all of them).
VARIANTS = {
    'hierarchical': (('hierarchical, no strain lim', {'strain_limit': None}),
                     ('hierarchical, 100 refine sw.', {'strain_refine_iterations': 100})),
    'multigrid': (('multigrid, to level 3', {'accurate_level': 3}),
                  ('multigrid, to 3, 1 refine sw.', {'accurate_level': 3,
                                                     'strain_refine_iterations': 1}),
                  ('multigrid, every level', {'accurate_level': None})),
}

# Steps broken down kernel by kernel on the largest size: the paper's, and multigrid solved
# up to 65 x 65 (the node's 257 x 257 target).
BREAKDOWNS = (('hierarchical', {}), ('multigrid', {'accurate_level': 3}))

# What a cold start compiles: the node's default (multigrid, one thread, no recording)
# and everything (every solver, serial and parallel builds, the energy), each in one
# process and spread over the default number of processes.
COLD_CONFIGS = {
    'node default, 1 process': {'solvers': ['multigrid'], 'parallel': False,
                                'energy': False, 'processes': 1},
    'node default': {'solvers': ['multigrid'], 'parallel': False, 'energy': False},
    'every kernel, 1 process': {'parallel': True, 'processes': 1},
    'every kernel': {'parallel': True},
}


def cold_start():
    """
    Measure the JIT cost for each of :data:`COLD_CONFIGS`.

    Runs warm_up() in a fresh interpreter with an empty, then a filled cache.
    """
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    out = {}
    for name, config in COLD_CONFIGS.items():
        out[name] = {}
        with tempfile.TemporaryDirectory(prefix='hcloth_numba_cache_') as cache:
            env = dict(os.environ, NUMBA_CACHE_DIR=cache,
                       PYTHONPATH=os.pathsep.join([root] + [p for p in os.environ.get(
                           'PYTHONPATH', '').split(os.pathsep) if p]))
            for label in ('cold', 'warm_cache'):
                t0 = time.perf_counter()
                proc = subprocess.run([sys.executable, '-c', _COLD_CHILD, json.dumps(config)],
                                      env=env, capture_output=True, text=True, timeout=900)
                wall = time.perf_counter() - t0
                if proc.returncode != 0:
                    result = {'error': proc.stderr.strip().splitlines()[-1:]}
                else:
                    result = json.loads(proc.stdout.strip().splitlines()[-1])
                    result['process_wall_s'] = wall
                out[name][label] = result
                print(f'  {name:24s} {label:10s} ' + (
                    f"import {result['import_s']:.2f} s, warm_up {result['warm_up_s']:.2f} s "
                    f"(this process's cpu {result['process_cpu_s']:.1f} s), process "
                    f'{wall:.2f} s' if 'error' not in result
                    else f"FAILED: {result['error']}"), flush=True)
    return out


def _fmt(r):
    sweeps = ' '.join(f'{v:.0f}' for v in r['strain_sweeps_mean'].values())
    extra = ''
    if 'cg_iterations_mean' in r:
        extra = (f" Newton {r['newton_iterations_mean']:.0f}, CG {r['cg_iterations_mean']:.0f}"
                 ' iterations a step')
    return (f"  {r['size']:>4s} {r['finest']:>9s} {r['label']:26s} "
            f"median {r['median_ms']:9.3f} ms  p90 {r['p90_ms']:9.3f} ms  "
            f"{r['steps_per_second']:8.1f} steps/s  n={r['steps']:<4d} "
            f"refused {r['refused']:<3d} sweeps/level [{sweeps}]{extra}")


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog='hcloth_engine_bench',
        description='Milliseconds per step of the cloth solvers (see module docstring).')
    parser.add_argument('--sizes', default=','.join(SIZES),
                        help=f'comma-separated subset of {list(SIZES)} (default: all)')
    parser.add_argument('--solvers', default='explicit,approx,hierarchical,multigrid,implicit',
                        help='comma-separated solvers (implicit runs on the smallest '
                             'size only)')
    parser.add_argument('--steps', type=int, default=200, help='timed steps per config')
    parser.add_argument('--warmup', type=int, default=20, help='untimed steps first')
    parser.add_argument('--budget', type=float, default=10.0,
                        help='seconds of timed steps per configuration at most')
    parser.add_argument('--implicit-steps', type=int, default=2,
                        help='timed implicit steps (smallest size, from rest, no warm-up)')
    parser.add_argument('--implicit-budget', type=float, default=30.0,
                        help='seconds of implicit steps at most (at least one step runs)')
    parser.add_argument('--breakdown-steps', type=int, default=50)
    parser.add_argument('--no-cold', action='store_true', help='skip the cold-start runs')
    parser.add_argument('--no-breakdown', action='store_true')
    parser.add_argument('--no-variants', action='store_true',
                        help='skip the hierarchical runs without strain limiting and with '
                             '100 refinement sweeps (largest size)')
    parser.add_argument('--json', metavar='PATH', help='write every figure to PATH')
    args = parser.parse_args(argv)
    sizes = [s.strip() for s in args.sizes.split(',') if s.strip()]
    for s in sizes:
        if s not in SIZES:
            parser.error(f'unknown size {s!r}; choose from {list(SIZES)}')
    solver_names = [s.strip() for s in args.solvers.split(',') if s.strip()]

    import numba

    from hcloth_ros.core import SOLVERS, warm_up
    for s in solver_names:
        if s not in SOLVERS:
            parser.error(f'unknown solver {s!r}; choose from {sorted(SOLVERS)}')
    t_all = time.perf_counter()
    results = {'python': sys.version.split()[0], 'numba': numba.__version__,
               'numpy': np.__version__, 'machine': platform.machine(),
               'processor': platform.processor(), 'cpu_count': os.cpu_count(),
               'load_before': list(os.getloadavg()), 'dt': DT,
               'sizes': {s: dict(SIZES[s], finest_side=_side(**SIZES[s])) for s in sizes}}
    print(f'hcloth engine benchmark: dt = 1/60 s, pinned at two corners, default options; '
          f'load average {results["load_before"][0]:.2f} on {os.cpu_count()} CPUs', flush=True)
    t0 = time.perf_counter()
    results['warm_up_s'] = warm_up()
    results['threads'] = numba.get_num_threads()
    results['threading_layer'] = numba.threading_layer()
    print(f'numba {numba.__version__}: {results["threads"]} threads, threading layer '
          f'{results["threading_layer"]!r}; warm_up() in this process '
          f'{results["warm_up_s"]:.2f} s ({time.perf_counter() - t0:.2f} s)', flush=True)
    for s in sizes:
        spec = SIZES[s]
        n = _side(**spec)
        print(f'size {s}: level 0 {spec["resolution"]}x{spec["resolution"]}, '
              f'{spec["levels"]} levels, finest {n}x{n} = {n * n} points', flush=True)

    configs = []
    print('per configuration (warm steps):', flush=True)
    smallest = min(sizes, key=lambda s: _side(**SIZES[s])) if sizes else None
    for s in sizes:
        for name in solver_names:
            if name == 'implicit':
                if s != smallest:
                    continue
                # kernels are compiled already (warm_up); a step takes seconds
                r = run_config(s, name, args.implicit_steps, 0, args.implicit_budget)
            else:
                r = run_config(s, name, args.steps, args.warmup, args.budget)
            r['threads'] = numba.get_num_threads()
            r['threading_layer'] = numba.threading_layer()
            configs.append(r)
            print(_fmt(r), flush=True)
    for name, variants in VARIANTS.items():
        if name in solver_names and sizes and not args.no_variants:
            largest = max(sizes, key=lambda s: _side(**SIZES[s]))
            for label, options in variants:
                r = run_config(largest, name, args.steps, args.warmup, args.budget, options,
                               label)
                r['threads'] = numba.get_num_threads()
                r['threading_layer'] = numba.threading_layer()
                configs.append(r)
                print(_fmt(r), flush=True)
    results['configs'] = configs

    results['breakdown'] = []
    for name, options in BREAKDOWNS:
        if args.no_breakdown or not sizes or name not in solver_names:
            continue
        largest = max(sizes, key=lambda s: _side(**SIZES[s]))
        print(f'{name} {options or ""} step breakdown at {largest} '
              f'(median ms per step, each kernel timed around its call):', flush=True)
        b = breakdown(largest, args.breakdown_steps, args.warmup, name, options)
        for row in b['kernels']:
            extra = ''
            if 'sweeps_mean' in row:
                extra = (f"  sweeps {row['sweeps_mean']:.1f}, "
                         f"{row['ms_per_sweep'] * 1e3:.1f} us/sweep")
            level = 'all' if row['level'] < 0 else f"L{row['level']}"
            print(f"  {row['kernel']:18s} {level:>4s} {row['median_ms']:9.3f} ms"
                  f" (p90 {row['p90_ms']:.3f}){extra}", flush=True)
        print(f"  step total          {b['step_median_ms']:9.3f} ms over {b['steps']} steps",
              flush=True)
        results['breakdown'].append(b)

    if not args.no_cold:
        print('cold start (fresh interpreter, import + warm_up()):', flush=True)
        results['cold_start'] = cold_start()

    results['load_after'] = list(os.getloadavg())
    results['total_seconds'] = time.perf_counter() - t_all
    print(f'load average after: {results["load_after"][0]:.2f}; '
          f'total {results["total_seconds"]:.1f} s', flush=True)
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=2)
        print(f'wrote {args.json}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
