"""
``hcloth_bench`` / ``python -m hcloth_ros.bench``: regenerate every chart and number.

    hcloth_bench --out doc/bench            # full: the README's charts (about 30 min)
    hcloth_bench --quick --out out/bench    # a few minutes
    hcloth_bench --tiny --out /tmp/b        # seconds: the test suite's smoke run

Writes into ``--out``: ``results.json`` (every number, with the plan and the machine),
``summary.md`` (the README's tables), ``accuracy.csv``, ``stability.csv``, ``violent.csv``,
``peers.csv``, ``equilibrium.csv``,
``fig4.csv`` and the charts ``accuracy.png``, ``stability.png``,
``fig3_5.png``, ``fig6.png``. Every run uses one numba thread, as the peers do, so costs
compare like with like.
"""

import argparse
import csv
import json
import os
import platform
import time

from hcloth_ros.bench import accuracy, equilibrium, paper, peers, report, stability, versus
from hcloth_ros.bench.plan import FULL, Plan, PLANS, QUICK, TINY
from hcloth_ros.core import warm_up
import numba
import numpy as np

SECTIONS = ('accuracy', 'equilibrium', 'stability', 'paper', 'peers')


class Progress:
    """A tqdm bar over a known number of runs, or plain lines when tqdm is missing."""

    def __init__(self, total, enabled=True):
        self.bar = None
        if enabled:
            try:
                from tqdm import tqdm
                self.bar = tqdm(total=total, unit='run', dynamic_ncols=True)
            except ImportError:
                pass
        self.enabled = enabled

    def __call__(self, text):
        if self.bar is not None:
            self.bar.set_description_str(text[:60])
            self.bar.update(1)
        elif self.enabled:
            print(text, flush=True)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _write_csv(path, rows):
    if not rows:
        return
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, 'w', newline='') as f:
        writer = csv.DictWriter(f, keys)
        writer.writeheader()
        writer.writerows(rows)


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    return value


def _previous(out, plan):
    """
    Return the results already in ``out`` from the same plan, else nothing.

    So ``--only`` re-runs a section and keeps the others.
    """
    try:
        with open(os.path.join(out, 'results.json')) as f:
            old = json.load(f)
    except (OSError, ValueError):
        return {}
    return old if old.get('plan', {}).get('name') == plan.name else {}


def _estimate(plan, sections):
    """Count the runs of the sections, for the progress bar's total (references count as runs)."""
    total = 0
    if 'accuracy' in sections:
        total += len(accuracy.jobs(plan)) + len(plan.scenarios) * len(plan.sizes)
    if 'equilibrium' in sections:
        total += sum(1 + sum(n <= m.max_n for m in equilibrium.methods(n))
                     for n in plan.equilibrium_sizes)
    if 'stability' in sections:
        total += len(stability.map_jobs(plan)) + 3 * len(stability.violent_methods(9))
    if 'paper' in sections:
        total += 5 + 2 + (4 if plan.fig4 else 0)
    if 'peers' in sections:
        # ours and each peer try up to 8 steps of the ladder on the sizes up to 33
        total += sum(n <= 33 for n in plan.sizes) * (3 + len(peers.PEERS)) * 4
    return total


def run(plan, out, sections=SECTIONS, show_progress=True):
    """
    Run the chosen sections of ``plan`` and write everything into ``out``.

    Returns the results dict (what ``results.json`` holds).
    """
    os.makedirs(out, exist_ok=True)
    numba.set_num_threads(1)
    warm_up()
    started = time.perf_counter()
    results = _previous(out, plan)
    results.update(plan=plan.__dict__, machine={
        'cpus': os.cpu_count(), 'processor': platform.processor() or platform.machine(),
        'python': platform.python_version(), 'numba': numba.__version__, 'numba_threads': 1})
    # the machine is shared: costs are only as good as its idle cores (1-minute averages)
    loads = results.setdefault('load_average', {})
    loads[','.join(sections)] = {'start': os.getloadavg()[0]}
    progress = Progress(_estimate(plan, sections), show_progress)
    try:
        if 'accuracy' in sections:
            rows, checks = accuracy.sweep(plan, progress)
            results['accuracy'] = rows
            results['reference_self_check'] = checks
            _write_csv(os.path.join(out, 'accuracy.csv'), rows)
            accuracy.chart(rows, checks, plan, os.path.join(out, 'accuracy.png'))
        if 'equilibrium' in sections:
            rows = equilibrium.rest_shapes(plan.equilibrium_sizes, progress)
            results['equilibrium'] = rows
            _write_csv(os.path.join(out, 'equilibrium.csv'), rows)
        if 'stability' in sections:
            rows, limits = stability.stability_map(plan, progress)
            results['stability'] = rows
            results['explicit_limit_check'] = stability.explicit_boundary_check(rows, limits)
            _write_csv(os.path.join(out, 'stability.csv'), rows)
            stability.chart_map(rows, limits, plan, os.path.join(out, 'stability.png'))
            violent = stability.violent_control(plan.stability_n, progress)
            results['violent'] = violent
            _write_csv(os.path.join(out, 'violent.csv'), violent)
        if 'paper' in sections:
            n, runs = paper.fig3_runs(plan, progress)
            paper.chart_fig3(n, runs, os.path.join(out, 'fig3_5.png'))
            results['fig3_5'] = {label: {'com_z_end': float(r.com[-1, 2]),
                                         'com_z_drop_max': float(1.5 - r.com[:, 2].min()),
                                         'max_strain': r.max_strain, 'failed': r.failed}
                                 for label, r in runs.items()}
            n, wrinkles = paper.fig6_runs(plan, progress)
            paper.chart_fig6(n, wrinkles, os.path.join(out, 'fig6.png'))
            results['fig6'] = {label: res['wrinkle'] for label, res in wrinkles.items()}
            if plan.fig4:
                fig4 = paper.fig4_timing(progress)
                results['fig4'] = fig4
                _write_csv(os.path.join(out, 'fig4.csv'), fig4)
        if 'peers' in sections:
            rows, missing = versus.compare(plan.sizes, plan.duration, progress)
            results['peers'] = rows
            results['peers_missing'] = missing
            _write_csv(os.path.join(out, 'peers.csv'), rows)
    finally:
        progress.close()
    results.setdefault('wall_seconds', {})[','.join(sections)] = time.perf_counter() - started
    loads[','.join(sections)]['end'] = os.getloadavg()[0]
    results = _jsonable(results)
    with open(os.path.join(out, 'results.json'), 'w') as f:
        json.dump(results, f, indent=1)
    with open(os.path.join(out, 'summary.md'), 'w') as f:
        f.write(report.markdown(results))
    return results


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', default='out/bench', help='folder for charts and data')
    size = parser.add_mutually_exclusive_group()
    size.add_argument('--quick', action='store_true', help=f'{QUICK.name}: a few minutes')
    size.add_argument('--tiny', action='store_true', help=f'{TINY.name}: a smoke run')
    parser.add_argument('--only', nargs='+', choices=SECTIONS, default=list(SECTIONS),
                        help='sections to run (default: all)')
    parser.add_argument('--no-progress', action='store_true')
    parser.add_argument('--replot', action='store_true', help='redraw the accuracy and '
                        'stability charts and summary.md from --out/results.json, no runs')
    args = parser.parse_args(argv)
    if args.replot:
        replot(args.out)
        return
    plan = PLANS['quick' if args.quick else 'tiny' if args.tiny else FULL.name]
    results = run(plan, args.out, tuple(args.only), not args.no_progress)
    print(summary(results))
    print(f'wrote {args.out}/ in {sum(results["wall_seconds"].values()):.0f} s')


def replot(out):
    """Redraw the charts and tables from ``out/results.json`` (after a change of style)."""
    with open(os.path.join(out, 'results.json')) as f:
        results = json.load(f)
    plan = Plan(**{k: tuple(v) if isinstance(v, list) else v
                   for k, v in results['plan'].items()})
    if 'accuracy' in results:
        accuracy.chart(results['accuracy'], results['reference_self_check'], plan,
                       os.path.join(out, 'accuracy.png'))
    if 'stability' in results:
        limits = {row['k']: row['theory'] for row in results['explicit_limit_check']}
        stability.chart_map(results['stability'], limits, plan,
                            os.path.join(out, 'stability.png'))
    with open(os.path.join(out, 'summary.md'), 'w') as f:
        f.write(report.markdown(results))
    print(f'redrew the charts and summary.md in {out}')


def summary(results):
    """Return the headline figures as text."""
    lines = []
    for row in results.get('explicit_limit_check', []):
        lines.append(f'explicit k={row["k"]:g}: theory {row["theory"]:.2e} s, stable up to '
                     f'{row["largest_stable"]:.2e} s, blown up from '
                     f'{row["smallest_blown_up"]:.2e} s: '
                     + {True: 'consistent', False: 'INCONSISTENT', None: 'not bracketed'}[
                         row['consistent']])
    for row in results.get('equilibrium', []):
        lines.append(f'rest shape n={row["n"]:3d} {row["method"]:42s} drop {row["drop"]:.4f} m '
                     f'({100 * row["drop_error"]:+.2f} % from the energy minimum), RMS '
                     f'{row["position_rms"]:.4f} m {row["failed"]}')
    for row in results.get('peers', []):
        lines.append(f'{row["simulator"]:40s} n={row["n"]:3d} dt=1/{1 / row["dt"]:.0f} '
                     f'{row["wall_per_sim_second"]:.3f} s/s (x{row["cost_vs_hcloth_default"]:.2f})'
                     f' strain {row["max_strain"]:.3f} com_z_rms {row["com_z_rms"]:.3f} m'
                     f'{"" if row["plausible"] else " NOT PLAUSIBLE"}')
    if results.get('peers_missing'):
        lines.append(f'peers not installed (pip install .[peers]): {results["peers_missing"]}')
    for label, value in results.get('fig6', {}).items():
        lines.append(f'fig. 6 contraction {label}: wrinkle measure {value:.2f} 1/m')
    for row in results.get('fig4', []):
        lines.append(f'fig. 4 {row["grid"]} ({row["points"]} points), {row["threads"]} thread(s): '
                     f'{row["median_ms"]:.2f} ms a step')
    return '\n'.join(lines)


if __name__ == '__main__':
    main()
