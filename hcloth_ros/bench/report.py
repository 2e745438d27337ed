"""
Markdown tables of a benchmark's ``results.json`` (the README's tables come from here).

    python -m hcloth_ros.bench.report doc/bench/results.json > doc/bench/summary.md
"""

import json
import sys


def _fmt(value, spec='.3g'):
    return '-' if value is None else format(value, spec)


def _dt(dt):
    return f'1/{1 / dt:.0f}' if dt else '-'


def accuracy_table(results, dt=1 / 60):
    """Every method at one time step (explicit at its most accurate stable step)."""
    rows = results.get('accuracy', [])
    out = ['| scenario | finest | method | dt (s) | status | vertex RMS (m) '
           '| vertex RMS, first second (m) | centre of mass RMS (m) '
           '| energy lost beyond reference (W) | largest strain | wall s per simulated s |',
           '| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |']
    for r in rows:
        chosen = abs(r['dt'] - dt) < 1e-9
        if r['solver'] == 'explicit':
            stable = [x for x in rows
                      if x['method'] == 'explicit' and x['scenario'] == r['scenario']
                      and x['n'] == r['n'] and x['position_rms'] is not None]
            chosen = bool(stable) and r is max(stable, key=lambda x: x['dt'])
        if not chosen:
            continue
        out.append(f'| {r["scenario"]} | {r["n"]} | {r["method"]} | {_dt(r["dt"])} '
                   f'| {r["status"]} '
                   f'| {_fmt(r["position_rms"])} | {_fmt(r.get("position_rms_first_second"))} '
                   f'| {_fmt(r["com_rms"])} '
                   f'| {_fmt(r["energy_loss_rate"])} | {_fmt(r["max_strain"])} '
                   f'| {_fmt(r["wall_per_sim_second"])} |')
    return '\n'.join(out)


def equilibrium_table(results):
    out = ['| finest | method | drop below the pins (m) | energy minimum (m) | difference '
           '| RMS vertex distance (m) | largest speed at the end (m/s) |',
           '| --- | --- | --- | --- | --- | --- | --- |']
    for r in results.get('equilibrium', []):
        out.append(f'| {r["n"]} | {r["method"]} | {r["drop"]:.4f} | {r["minimum_drop"]:.4f} '
                   f'| {100 * r["drop_error"]:+.2f} % | {_fmt(r["position_rms"])} '
                   f'| {_fmt(r["end_speed"])} {r["failed"]}|')
    return '\n'.join(out)


def reference_table(results):
    out = ['| reference | self-check: RMS change when its step is halved (m) |', '| --- | --- |']
    out += [f'| {k} | {v:.2g} |' for k, v in results.get('reference_self_check', {}).items()]
    return '\n'.join(out)


def explicit_check_table(results):
    out = ['| k (N/m) | theory 2/w_max (s) | largest stable step (s) | smallest blown-up step (s) '
           '| agrees |', '| --- | --- | --- | --- | --- |']
    for r in results.get('explicit_limit_check', []):
        agrees = {True: 'yes', False: 'NO', None: 'not bracketed by the ladder'}[r['consistent']]
        out.append(f'| {r["k"]:g} | {r["theory"]:.2e} | {_fmt(r["largest_stable"], ".2e")} '
                   f'| {_fmt(r["smallest_blown_up"], ".2e")} | {agrees} |')
    return '\n'.join(out)


def violent_table(results):
    rows = results.get('violent', [])
    motions = list(dict.fromkeys(r['motion'] for r in rows))
    methods = list(dict.fromkeys(r['method'] for r in rows))
    out = ['| method | ' + ' | '.join(f'{m} ({next(r["what"] for r in rows if r["motion"] == m)})'
                                      for m in motions) + ' |',
           '| --- |' + ' --- |' * len(motions)]
    for method in methods:
        cells = []
        for m in motions:
            r = next(r for r in rows if r['motion'] == m and r['method'] == method)
            cells.append(f'{r["status"]} ({r["max_strain"]:.0%})')
        dt = next(r['dt'] for r in rows if r['method'] == method)
        out.append(f'| {method} (dt {_dt(dt)}) | ' + ' | '.join(cells) + ' |')
    return '\n'.join(out)


def peers_table(results):
    out = ['| simulator | finest | largest plausible dt | plausible | wall s per simulated s '
           '| cost vs hcloth default | largest strain '
           '| centre-of-mass height RMS vs reference (m) |',
           '| --- | --- | --- | --- | --- | --- | --- | --- |']
    for r in results.get('peers', []):
        name = f'{r["simulator"]} {r["version"]}'.strip()
        out.append(f'| {name} | {r["n"]} | {_dt(r["dt"])} | {"yes" if r["plausible"] else "no"} '
                   f'| {_fmt(r["wall_per_sim_second"])} | {r["cost_vs_hcloth_default"]:.1f}x '
                   f'| {_fmt(r["max_strain"])} | {_fmt(r["com_z_rms"])} |')
    return '\n'.join(out)


def paper_tables(results):
    out = ['| Fig. 3/5 run | largest centre-of-mass drop (m) | height at the end (m) |',
           '| --- | --- | --- |']
    for label, r in results.get('fig3_5', {}).items():
        out.append(f'| {label} | {r["com_z_drop_max"]:.3g} | {r["com_z_end"]:.3f} |')
    out += ['', '| Fig. 6 contraction | wrinkle measure (1/m) |', '| --- | --- |']
    out += [f'| {k} | {v:.2f} |' for k, v in results.get('fig6', {}).items()]
    if results.get('fig4'):
        out += ['', '| Fig. 4 grid | points | threads | median step (ms) | p90 (ms) '
                '| real-time factor at 1/60 s |', '| --- | --- | --- | --- | --- | --- |']
        out += [f'| {r["grid"]} | {r["points"]:,} | {r["threads"]} | {r["median_ms"]:.2f} '
                f'| {r["p90_ms"]:.2f} | {r["real_time_factor"]:.0f} |' for r in results['fig4']]
    return '\n'.join(out)


def markdown(results):
    parts = [('Accuracy at dt = 1/60 s (explicit: its largest stable step)', accuracy_table),
             ('References', reference_table),
             ('Rest shape of the hung cloth against the energy minimum', equilibrium_table),
             ('Explicit step limit', explicit_check_table),
             ('Violent grasps', violent_table), ('Peers', peers_table),
             ("The paper's figures", paper_tables)]
    return (_machine(results) + '\n\n'
            + '\n\n'.join(f'## {title}\n\n{fn(results)}' for title, fn in parts) + '\n')


def _machine(results):
    """Describe the machine and its load while each section ran (costs need idle cores)."""
    m = results.get('machine', {})
    loads = '; '.join(f'{sections}: {v.get("start", 0):.2f} -> {v.get("end", 0):.2f}'
                      for sections, v in results.get('load_average', {}).items())
    return (f'Machine: {m.get("cpus")} CPUs ({m.get("processor")}), Python {m.get("python")}, '
            f'numba {m.get("numba")} on {m.get("numba_threads")} thread; load average (1 min) '
            f'at the start and end of each run: {loads or "not recorded"}.')


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    with open(argv[0] if argv else 'doc/bench/results.json') as f:
        print(markdown(json.load(f)), end='')


if __name__ == '__main__':
    main()
