"""
Where self-contact's kernel calls spend their time: captured calls replayed under perf.

    .venv/bin/python tools/self_contact_profile.py CAPTURE [--calls first|later|all] \
        [--repeats 10] [--frequency 4000] [--top 30]

``CAPTURE``: a file of ``tools/self_contact_replay.py --save`` (the fold scene's ticks
300-329 at 129 x 129: ``--scene fold --steps 300:329``). The calls it holds (a step's
first calls, its later ones, or all) are replayed ``--repeats`` times, one numba thread,
in a child process that Linux ``perf record`` samples. Numba's cached machine code
carries no symbols and this llvmlite registers none with perf, so the child compiles the
kernel itself (numba's cache pointed at an empty directory: a minute or two) and writes
perf's map of the compiled functions (``/tmp/perf-PID.map``) from the kernel's LLVM
module before it exits. Prints each kernel function's share of the samples taken in
compiled code (a function LLVM inlined counts in its caller), and its samples, and that
code's share of all samples (the rest: loading the capture, compiling, copying each
call's arguments).
Run it with ``PYTHONPATH`` at another tree to profile that tree's kernel.
"""

import argparse
import importlib
import os
import pickle
import shutil
import subprocess
import sys
import tempfile


def jit_symbols(dispatcher):
    """
    Return ``{address: name}`` of the functions compiled into the dispatcher's overloads.

    Empty for code loaded from numba's cache (its LLVM module is not kept).
    """
    symbols = {}
    for result in dispatcher.overloads.values():
        library = result.library
        for function in library._final_module.functions:
            if function.is_declaration:
                continue
            address = library._codegen._engine.get_function_address(function.name)
            if address:
                symbols[address] = function.name
    return symbols


def write_map(symbols, path):
    """
    Write perf's map of ``symbols`` (``{address: name}``) to ``path``.

    Each function runs to the next one's address (the last one 4 kB): perf needs sizes,
    and LLVM lays a module's functions out one after another.
    """
    addresses = sorted(symbols)
    with open(path, 'w') as out:
        for start, end in zip(addresses, addresses[1:] + [addresses[-1] + 4096]):
            out.write(f'{start:x} {end - start:x} {symbols[start]}\n')


def short_name(symbol):
    """
    Return a numba symbol's function name (``_ZN10hcloth_ros...13_edge_againstB4v1...``).

    The mangled name lists the module path and the function as length-prefixed parts;
    the last is the function. Other names come back as they are.
    """
    if not symbol.startswith('_ZN'):
        return symbol
    rest, parts = symbol[3:], []
    while rest[:1].isdigit():
        digits = len(rest) - len(rest.lstrip('0123456789'))
        size = int(rest[:digits])
        parts.append(rest[digits:digits + size])
        rest = rest[digits + size:]
    return parts[-1] if parts else symbol


def shares(report_lines):
    """
    Return ``([(share, function)], compiled, samples)`` from ``perf report`` lines.

    ``share``: the function's part of the samples in compiled code (percent, most
    first); ``compiled``: that code's part of all samples (percent); ``samples``: all
    samples (the report's ``# Samples:`` line, 0 without one), so that two runs of the
    same calls compare in samples (two versions of the kernel: the samples a function
    lost or gained).
    """
    by_name, compiled, samples = {}, 0.0, 0
    for line in report_lines:
        if line.startswith('# Samples:'):
            count = line.split()[2]
            scale = {'K': 1e3, 'M': 1e6}.get(count[-1], 1.0)
            samples = int(round(float(count.rstrip('KM')) * scale))
        if line.startswith('#') or '%' not in line or '[JIT]' not in line:
            continue
        percent = float(line.split('%')[0])
        name = short_name(line.split()[-1])
        by_name[name] = by_name.get(name, 0.0) + percent
        compiled += percent
    rows = sorted(((100.0 * p / compiled, name) for name, p in by_name.items()), reverse=True)
    return rows, compiled, samples


def child(capture, which, repeats):
    """Replay the chosen calls of ``capture`` ``repeats`` times, then write perf's map."""
    import numba
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path.insert(0, here)
    from self_contact_replay import fitted, fresh, later_call  # noqa: I100 (beside)
    numba.set_num_threads(1)
    with open(capture, 'rb') as f:
        calls = [fitted(arguments) for _, arguments in pickle.load(f)]
    calls = [a for a in calls if which == 'all' or later_call(a) == (which == 'later')]
    if not calls:
        raise SystemExit(f'no {which} calls in {capture}')
    kernel = importlib.import_module('hcloth_ros.core.kernels.self_contact').self_contact
    kernel(*fresh(calls[0]))        # compiled here: its symbols are known
    for done in range(repeats):
        for arguments in calls:
            kernel(*fresh(arguments))
        print(f'\rreplayed {done + 1} of {repeats} times', end='', file=sys.stderr,
              flush=True)
    print(file=sys.stderr)
    symbols = jit_symbols(kernel)
    if not symbols:
        raise SystemExit('the kernel came from a cache: no symbols (NUMBA_CACHE_DIR?)')
    write_map(symbols, f'/tmp/perf-{os.getpid()}.map')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('capture', help='a file of tools/self_contact_replay.py --save')
    parser.add_argument('--calls', choices=('first', 'later', 'all'), default='first')
    parser.add_argument('--repeats', type=int, default=10)
    parser.add_argument('--frequency', type=int, default=4000, help='samples a second')
    parser.add_argument('--top', type=int, default=30)
    parser.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        child(args.capture, args.calls, args.repeats)
        return
    if shutil.which('perf') is None:
        raise SystemExit('needs Linux perf (perf record, perf report) on the PATH')
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, 'perf.data')
        env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(tmp, 'numba'),
                   NUMBA_NUM_THREADS='1')
        subprocess.run(['perf', 'record', '-q', '-F', str(args.frequency), '-o', data, '--',
                        sys.executable, os.path.abspath(__file__), args.capture, '--child',
                        '--calls', args.calls, '--repeats', str(args.repeats)],
                       check=True, env=env)
        report = subprocess.run(['perf', 'report', '-i', data, '--no-children', '--sort',
                                 'dso,sym', '--stdio'], check=True, capture_output=True,
                                text=True).stdout
    rows, compiled, samples = shares(report.splitlines())
    in_code = compiled * samples / 100.0
    print(f'{args.calls} calls of {args.capture}, {args.repeats} times: compiled code '
          f'{compiled:.1f} % of all {samples} samples ({in_code:.0f}); of its samples:')
    for share, name in rows[:args.top]:
        print(f'  {share:5.1f} %  {share * in_code / 100.0:8.0f}  {name}')


if __name__ == '__main__':
    main()
