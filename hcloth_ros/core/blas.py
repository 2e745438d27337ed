"""
numpy's BLAS on one thread, beside numba's threads.

OpenBLAS computes a dot product of more than 10,000 entries (or a large matrix product) on
threads of its own, one per core, which then spin waiting for more work. With numba's
threads on the same cores, a parallel kernel waits for a core such a thread holds: the
node's 257 x 257 scene solved to 65 x 65 on two numba threads stepped in 16 ms at the
median and 122 ms at p99 with OpenBLAS free to start its threads, 9.4 and 24 ms with it
on one (``tools/node_step.py --threads 2 -p cloth.levels=6 -p solver.accurate_level=3``).
The engine's arithmetic is numba's; BLAS only serves small conveniences around it.

``OPENBLAS_NUM_THREADS`` works only if set before numpy is loaded; this sets the count of
the library already loaded, as threadpoolctl does, with no dependency.
"""

import ctypes

# OpenBLAS's setter and getter under the names its builds export: numpy's wheels
# (scipy-openblas, 64-bit integers), then a system OpenBLAS (Debian's numpy)
_SETTERS = ('scipy_openblas_set_num_threads64_', 'scipy_openblas_set_num_threads',
            'openblas_set_num_threads64_', 'openblas_set_num_threads')
_GETTERS = ('scipy_openblas_get_num_threads64_', 'scipy_openblas_get_num_threads',
            'openblas_get_num_threads64_', 'openblas_get_num_threads')


def _loaded_openblas():
    """Paths of the OpenBLAS libraries mapped into this process (Linux; else none)."""
    try:
        with open('/proc/self/maps') as maps:
            fields = [line.split() for line in maps]
    except OSError:
        return []
    paths = {f[5] for f in fields if len(f) >= 6 and 'openblas' in f[5].lower()
             and '.so' in f[5]}
    return sorted(paths)


def _loaded(names):
    """``[(path, function)]``: the first of ``names`` each loaded OpenBLAS exports."""
    out = []
    for path in _loaded_openblas():
        library = ctypes.CDLL(path)
        function = next((getattr(library, n) for n in names if hasattr(library, n)), None)
        if function is not None:
            out.append((path, function))
    return out


def openblas_threads():
    """``{path: threads}`` of every OpenBLAS loaded in this process."""
    return {path: int(getter()) for path, getter in _loaded(_GETTERS)}


def limit_openblas_threads(count=1):
    """
    Set every loaded OpenBLAS to ``count`` threads; return the paths it set.

    Empty when numpy uses another BLAS, or none is loaded yet (``import numpy`` first).
    """
    done = []
    for path, setter in _loaded(_SETTERS):
        setter(int(count))
        done.append(path)
    return done
