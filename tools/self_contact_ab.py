"""
Two versions of the self-contact kernel on the same captured calls, alternated call by call.

    .venv/bin/python tools/self_contact_ab.py A.py B.py CALLS.pkl [CALLS.pkl ...] \
        [--repeats 5]

``A.py`` and ``B.py``: copies of ``hcloth_ros/core/kernels/self_contact.py`` (one of them
may be the tree's own), each loaded as a module of its own in this process. ``CALLS.pkl``:
calls captured by ``tools/self_contact_replay.py --save``. Each call runs ``--repeats``
times for each version on fresh copies of its arguments, the two versions taking turns
(which goes first alternates), and each version keeps its fastest time a call. Prints per
file the two sums, their ratio and each version's digest of what the calls wrote and
returned (as the replay tool's: equal digests, the same result on every call).

Numba caches each version's compiled code under its file's path with the name this tool
loads it as, which differs from the package's own: a cache shared with the package's
normal runs would hand them a module they cannot import. So the tool compiles into a
directory of its own (``hcloth_ros_self_contact_ab`` in the system's temporary
directory) unless ``NUMBA_CACHE_DIR`` names another; do not point that at a cache the
package uses.

Why in one process: the machines these sessions run on drift by up to 2x in speed within
minutes, so two replays run one after the other differed by more than the changes measured
(5 % and less). Taking turns call by call puts both versions under the same drift: the
same comparison repeated within 2 %, and a version against a copy of itself gave
1.004-1.007 (2026-12-01, session 40). Each version's scratch arrays come as an instance of
one class (``self_contact_replay._scratch``): with each module's own ``Scratch``, numba's
dispatcher sent every call of the second version down its slow path, and a version timed
2.7-2.9 times a copy of itself (session 48; with that, 1.02-1.03).
"""

import argparse
import hashlib
import importlib.util
import os
import pickle
import sys
import tempfile
import time

# before numba reads its configuration (see the docstring)
os.environ.setdefault('NUMBA_CACHE_DIR', os.path.join(tempfile.gettempdir(),
                                                      'hcloth_ros_self_contact_ab'))
import numba  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from self_contact_replay import (add_to_digest, fitted, fresh,  # noqa: E402 (next to this)
                                 takes_scratch)


def load(path):
    """
    Return the ``self_contact`` kernel of the module file ``path``, loaded as a module.

    Its name comes from the file's path, the same each run: numba's cache of it refers to
    the module by that name.
    """
    name = 'self_contact_' + hashlib.sha1(os.path.abspath(path).encode()).hexdigest()[:12]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module.self_contact


def compare(kernels, calls, repeats):
    """Return each version's fastest time a call (2, calls) and its results' digest."""
    best = np.full((2, len(calls)), np.inf)
    digests = [hashlib.sha1(), hashlib.sha1()]
    scratch = [takes_scratch(kernel) for kernel in kernels]
    for round_ in range(repeats):
        for c, arguments in enumerate(calls):
            for v in ((0, 1) if (round_ + c) % 2 == 0 else (1, 0)):
                copies = fresh(arguments, scratch[v], kernels[v].__module__)
                start = time.perf_counter()
                result = kernels[v](*copies)
                best[v, c] = min(best[v, c], time.perf_counter() - start)
                if round_ == 0:
                    add_to_digest(digests[v], copies, result)
        print(f'\r{os.path.basename(calls.name)}: round {round_ + 1} of {repeats}', end='',
              flush=True)
    print()
    return best, [d.hexdigest()[:12] for d in digests]


class Calls(list):
    """A file's captured calls' arguments, named by the file."""

    def __init__(self, path):
        with open(path, 'rb') as f:
            super().__init__(fitted(arguments) for _, arguments in pickle.load(f))
        self.name = path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('a', help='version A: a copy of kernels/self_contact.py')
    parser.add_argument('b', help='version B')
    parser.add_argument('calls', nargs='+', help='files of self_contact_replay.py --save')
    parser.add_argument('--repeats', type=int, default=5)
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    kernels = [load(args.a), load(args.b)]
    for path in args.calls:
        calls = Calls(path)
        if not calls:
            raise SystemExit(f'{path}: no calls')
        for kernel in kernels:      # compiled or loaded before the timing
            kernel(*fresh(calls[0], takes_scratch(kernel), kernel.__module__))
        best, digests = compare(kernels, calls, args.repeats)
        a, b = 1e3 * best.sum(axis=1)
        print(f'  A {a:.1f} ms, B {b:.1f} ms, B/A {b / a:.3f}; digests A {digests[0]}, '
              f'B {digests[1]}' + ('' if digests[0] == digests[1] else ' (different)'))


if __name__ == '__main__':
    main()
