"""
Start sim_node many times and interrupt each start at a random moment.

Counts clean exits, deaths by signal and hangs (the figures on signal handling in the
notes come from this; about 2.5 s a start).

    AMENT_PREFIX_PATH=$PWD/.venv .venv/bin/python tools/interrupt_stress.py --starts 50

A start that does not exit within 15 s of its signal is a hang: it gets SIGUSR1 (the node
prints every thread's stack) and is killed, and its stderr is printed.
"""

import argparse
import collections
import os
from pathlib import Path
import random
import signal
import subprocess
import time


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--starts', type=int, default=50)
    parser.add_argument('--signals', default='INT,TERM', help='cycled through, e.g. INT')
    parser.add_argument('--earliest', type=float, default=0.3, help='s after launch')
    parser.add_argument('--latest', type=float, default=3.0)
    args = parser.parse_args(argv)
    prefix = os.environ.get('AMENT_PREFIX_PATH', str(Path(__file__).parents[1] / '.venv'))
    node = Path(prefix.split(':')[0]) / 'lib' / 'hcloth_ros' / 'sim_node'
    signals = [getattr(signal, f'SIG{name}') for name in args.signals.split(',')]
    outcomes = collections.Counter()
    for i in range(args.starts):
        sig = signals[i % len(signals)]
        proc = subprocess.Popen([str(node)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        time.sleep(random.uniform(args.earliest, args.latest))
        proc.send_signal(sig)
        try:
            proc.communicate(timeout=15)
            outcomes[f'{sig.name}: exit {proc.returncode}'] += 1
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGUSR1)
            time.sleep(1)
            proc.kill()
            _, err = proc.communicate()
            outcomes[f'{sig.name}: hung'] += 1
            print(f'start {i}: hung after {sig.name}\n{err.decode()[-3000:]}', flush=True)
        print(f'{i + 1}/{args.starts} {dict(outcomes)}', flush=True)


if __name__ == '__main__':
    main()
