"""
The numba flags of every kernel, and where their machine code is cached.

Flags: ``cache=True``, ``error_model='numpy'``, ``nogil=True`` and no ``fastmath`` (fast
math lets LLVM delete the NaN checks the blow-up detector relies on).

Numba keys a cached kernel on the source of the file that defines it, not on the helpers
it calls from other files. The kernels share helpers across modules, so their cache lives
in a directory named after a digest of every module of this package
(:func:`cache_directory`): editing any kernel source starts an empty cache, and a stale
helper can never be loaded. The directory is the first writable one of
``$NUMBA_CACHE_DIR/hcloth_kernels-<digest>``, ``__pycache__/hcloth_kernels-<digest>``
beside these modules and ``~/.cache/hcloth_ros/hcloth_kernels-<digest>``; with none
writable the kernels are compiled at every start (caching is only an optimisation).
"""

import contextlib
import hashlib
import os
import shutil
import tempfile
import types

import numba

SOURCES = os.path.dirname(os.path.abspath(__file__))
PREFIX = 'hcloth_kernels-'


def source_digest(sources=SOURCES):
    """Digest of every module of the kernel package (names and contents)."""
    digest = hashlib.sha256()
    for name in sorted(os.listdir(sources)):
        if name.endswith('.py'):
            digest.update(name.encode())
            with open(os.path.join(sources, name), 'rb') as f:
                digest.update(f.read())
    return digest.hexdigest()[:16]


def _writable(path):
    try:
        os.makedirs(path, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
    except OSError:
        return False
    return True


def cache_directory():
    """Return the kernels' cache directory (see the module docstring), or None."""
    name = PREFIX + source_digest()
    in_tree = os.path.join(SOURCES, '__pycache__')
    user = os.path.join(os.environ.get('XDG_CACHE_HOME') or os.path.expanduser('~/.cache'),
                        'hcloth_ros')
    for base in (numba.config.CACHE_DIR, in_tree, user):
        if base and _writable(os.path.join(base, name)):
            if base == in_tree:
                _prune(in_tree, name)
            return os.path.join(base, name)
    return None


def _prune(base, keep):
    """Delete caches of earlier sources beside the modules (ours alone to manage)."""
    for entry in os.listdir(base):
        if entry.startswith(PREFIX) and entry != keep:
            shutil.rmtree(os.path.join(base, entry), ignore_errors=True)


CACHE_DIR = cache_directory()
JIT = {'cache': CACHE_DIR is not None, 'error_model': 'numpy', 'nogil': True}
PJIT = {**JIT, 'parallel': True}
# Helpers called once a pair or a point in the innermost loops, with arrays among their
# arguments, inlined in numba's IR. First for the references each call counted (a
# resting 129 x 129 cloth's carried layers 3.1-3.3 -> 2.4 ms, 5,400 points; a sliding
# step's first call 7.1-7.4 -> 6.7-6.9 ms; one-off copies of the kernel timed on captured
# calls, issue 10's note); BORROW now removes those counts, and inlining still pays: with
# the pushes called instead, the replayed drop's landing took 12 % longer (session 39).
# Each costs compilation wherever it is called (the pushes about 15 s in one cold
# compile, session 39): kept to the few that pay.
INLINE = {**JIT, 'inline': 'always'}
# Kernels that only borrow arrays (they allocate none and return none): compiled without
# numba's reference counting (NRT), which would otherwise increment and decrement the
# count of every array a call takes (atomic operations, each a call) on each path LLVM
# cannot prove balanced, and a callee's error status makes most paths so. On the sliding
# folded drop's replayed self-contact calls, those increments and decrements were 29 % of
# the kernel's samples (``perf record``); without them the calls take a fifth less time
# (median 423 against 523 ms over six alternated runs, the same results; the moving
# bodies' kernel half: doc/self_contact_log.md, session 39). Numba refuses to compile
# such a kernel if it allocates or calls one that does (no reference counting, no
# owner), so the flag cannot leak memory. ``_nrt`` is a target option of numba's CPU target
# (``numba.core.cpu``), named with an underscore and used by numba's own tests; a numba
# without it compiles these kernels with reference counting (slower, the same results).
_BORROWS = hasattr(numba.core.cpu.CPUTargetOptions, '_nrt')
BORROW = {**JIT, '_nrt': False} if _BORROWS else JIT
BORROW_INLINE = {**INLINE, '_nrt': False} if _BORROWS else INLINE


def serial_and_parallel(func, parfor=True, **parallel_globals):
    """
    Two builds of one kernel written with ``prange``: ``(serial, parallel)``.

    In the serial build ``prange`` is ``range``; only the parallel build pays numba's
    parfor compilation (about 2 s a kernel here) and a thread start per call, so a
    process that runs one thread (the node's default) compiles and calls serial builds
    only. ``parallel_globals`` replace names the parallel build calls (a serial helper by
    its parallel build); with ``parfor`` False the parallel build is compiled without
    numba's parfor pass (a kernel with no ``prange`` of its own that calls parallel
    ones). The parallel twin has its own name, hence its own cache entry.
    """
    name = func.__name__ + '_parallel'
    twin = types.FunctionType(func.__code__, dict(func.__globals__, **parallel_globals),
                              name, func.__defaults__, func.__closure__)
    twin.__qualname__ = func.__qualname__ + '_parallel'
    twin.__doc__ = func.__doc__
    twin.__module__ = func.__module__
    return numba.njit(**JIT)(func), numba.njit(**(PJIT if parfor else JIT))(twin)


@contextlib.contextmanager
def keyed_cache():
    """
    Point numba's cache at :data:`CACHE_DIR` while the kernel modules are decorated.

    Numba fixes a function's cache location when ``njit(cache=True)`` wraps it, so the
    setting is needed only during the imports and is restored after.
    """
    saved = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = CACHE_DIR or ''
    try:
        yield CACHE_DIR
    finally:
        numba.config.CACHE_DIR = saved
