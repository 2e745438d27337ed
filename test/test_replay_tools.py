"""The self-contact kernel's replay tools: ``tools/self_contact_replay.py`` and ``_ab.py``."""

import hashlib
import importlib
import os

from conftest import load_tool
import numpy as np


def test_replayed_calls_do_what_the_captured_ones_did():
    """
    Calls captured from the folded drop, replayed alone, write and return what they did.

    33 x 33, steps 15-30: the layers meet, so some calls find pairs, and some steps call
    the kernel again after strain limiting (a later call keeps its step's cache). The
    replay's digest (positions, velocities, velocity changes and results of every call)
    equals the digest of the calls as they ran in the drop: each call's arguments were
    copied before it wrote to them. Replayed from the cache the call before left
    (``chained``), the calls do the same too (as captured, each call's cache is the
    one the call before it left).
    """
    tool = load_tool('self_contact_replay')
    calls, captured = tool.capture(33, 15, 30)
    assert len({step for step, _ in calls}) == 16 and len(calls) > 16
    seconds, digest, found = tool.replay(calls, 1)
    assert digest == captured and seconds.shape == found.shape == (len(calls),)
    assert tool.replay(calls, 1, chained=True)[1] == captured
    # the calls found pairs (contact work, not only empty checks), as the replay says
    kernel = importlib.import_module('hcloth_ros.core.kernels.self_contact')
    assert list(found) == [kernel.self_contact(*tool.fresh(a))[0] for _, a in calls]
    assert found.sum() > 0


def test_the_fold_scene_is_captured_as_it_ran():
    """
    The fold demo's scene (``--scene fold``): its ticks' calls replayed alone do the same.

    33 x 33 (the scene's coarsest level alone), ticks 200-215: the top layer lies on the
    bottom one, each tick's first call finds pairs and a second one follows strain
    limiting. The replay's digest, also chained, is the one of the calls as they ran.
    """
    tool = load_tool('self_contact_replay')
    calls, captured = tool.capture(33, 200, 215, 'fold')
    assert sorted({tick for tick, _ in calls}) == list(range(200, 216))
    assert tool.replay(calls, 1)[1] == captured
    assert tool.replay(calls, 1, chained=True)[1] == captured
    kernel = importlib.import_module('hcloth_ros.core.kernels.self_contact')
    firsts = [a for _, a in calls if a[tool.REUSE] == 0]
    assert len(firsts) == 16 and len(calls) > 16
    assert all(kernel.self_contact(*tool.fresh(a))[0] > 0 for a in firsts)


def test_the_replay_tells_the_steps_in_contact_and_each_steps_calls():
    """
    A step is in contact if its first call found pairs; its later calls' time counts too.

    Made-up calls (only their step and reuse flag are read): step 1 finds nothing, step 2
    finds 5 pairs at its first call and none at its later one, step 3 finds 2.
    """
    tool = load_tool('self_contact_replay')

    def call(step, later):
        arguments = [None] * (tool.REUSE + 1)
        arguments[tool.REUSE] = 2 if later else 0
        return step, arguments

    calls = [call(1, False), call(1, True), call(2, False), call(2, True), call(3, False)]
    seconds = np.array([1e-3, 2e-3, 3e-3, 4e-3, 5e-3])
    found = np.array([0, 0, 5, 0, 2])
    assert list(tool.steps_in_contact(calls, seconds, found)) == [7e-3, 5e-3]
    assert tool.step_lines(calls, seconds, found) == [
        '  step 1: first 1.00 ms (0 pairs), later 2.00 ms (0 pairs)',
        '  step 2: first 3.00 ms (5 pairs), later 4.00 ms (0 pairs)',
        '  step 3: first 5.00 ms (2 pairs)']


def _fake_kernel(scale):
    """Return a stand-in kernel: it scales q (its first argument) in place, returns a result."""
    def self_contact(q, qd, dv, *rest):
        q *= scale
        return 1, 2, 0, True
    return self_contact


def test_the_ab_tool_times_both_versions_on_every_call_and_tells_their_results_apart(
        monkeypatch, tmp_path):
    """
    ``compare`` runs both versions on fresh copies of every call, and digests each.

    Two stand-in kernels: the same one twice gives equal digests, one that writes other
    positions a different digest; each version has a finite fastest time per call, and
    the calls' arrays are not written to (each run gets copies).
    """
    monkeypatch.setenv('NUMBA_CACHE_DIR', str(tmp_path))   # (the tool sets a default)
    tool = load_tool('self_contact_ab')
    rng = np.random.default_rng(0)

    class Calls(list):
        name = 'fake.pkl'

    calls = Calls([[rng.normal(size=(3, 4, 4)), np.zeros((3, 4, 4)), np.zeros((3, 4, 4)),
                    0.004] for _ in range(3)])
    before = [c[0].copy() for c in calls]
    best, digests = tool.compare([_fake_kernel(1.0), _fake_kernel(1.0)], calls, 2)
    assert best.shape == (2, 3) and np.isfinite(best).all() and digests[0] == digests[1]
    best, digests = tool.compare([_fake_kernel(1.0), _fake_kernel(2.0)], calls, 2)
    assert digests[0] != digests[1]
    assert all(np.array_equal(c[0], b) for c, b in zip(calls, before))


def test_the_ab_tool_loads_a_file_under_a_name_of_its_path(monkeypatch, tmp_path):
    """
    ``load`` returns the file's ``self_contact``, its module named from the file's path.

    The same path gives the same name each time (numba's cache names the module that
    wrote it), another path another name.
    """
    monkeypatch.setenv('NUMBA_CACHE_DIR', str(tmp_path))
    tool = load_tool('self_contact_ab')
    paths = []
    for folder in ('a', 'b'):
        os.mkdir(tmp_path / folder)
        paths.append(tmp_path / folder / 'self_contact.py')
        paths[-1].write_text(f'def self_contact(*arguments):\n    return "{folder}"\n')
    kernels = [tool.load(str(p)) for p in paths + paths[:1]]
    assert [k() for k in kernels] == ['a', 'b', 'a']
    names = [k.__module__ for k in kernels]
    expected = 'self_contact_' + hashlib.sha1(str(paths[0]).encode()).hexdigest()[:12]
    assert names[0] == names[2] == expected and names[1] != names[0]


def test_the_profile_tool_names_the_kernels_compiled_functions(tmp_path):
    """
    ``tools/self_contact_profile.py``: perf's map of freshly compiled code, and its report.

    A function compiled here (not from a cache) is found in its dispatcher's LLVM module:
    the map's line for it starts at its entry and names it as numba mangles it, which the
    tool shortens to the function's own name. A report's compiled-code lines are summed
    by function, as shares of those lines' samples.
    """
    import numba
    tool = load_tool('self_contact_profile')

    def twice_the_sum(values):
        total = 0.0
        for v in values:
            total += v
        return 2.0 * total

    kernel = numba.njit(cache=False)(twice_the_sum)
    assert kernel(np.arange(4.0)) == 12.0
    symbols = tool.jit_symbols(kernel)
    entry = kernel.overloads[kernel.signatures[0]].library.get_pointer_to_function(
        kernel.overloads[kernel.signatures[0]].fndesc.llvm_func_name)
    assert entry in symbols and tool.short_name(symbols[entry]) == 'twice_the_sum'
    path = tmp_path / 'perf.map'
    tool.write_map(symbols, path)
    lines = {int(line.split()[0], 16): line.split() for line in open(path)}
    assert lines[entry][2] == symbols[entry] and int(lines[entry][1], 16) > 0
    report = [
        "# Samples: 2K of event 'cpu-clock:pppH'",
        '# Overhead  Shared Object  Symbol',
        '    30.00%  [JIT] tid 7  [.] _ZN10hcloth_ros4core7kernels12self_contact6_sweepB4v1E',
        '    10.00%  [JIT] tid 7  [.] _ZN10hcloth_ros4core7kernels12self_contact6_sweepB4v2E',
        '    20.00%  [JIT] tid 7  [.] _ZN10hcloth_ros4core7kernels12self_contact5_nearB4v3E',
        '    40.00%  libpython3.11.so.1.0  [.] _PyEval_EvalFrameDefault',
    ]
    rows, compiled, samples = tool.shares(report)
    assert compiled == 60.0 and samples == 2000
    assert [(round(share, 6), name) for share, name in rows] == [
        (round(200.0 / 3.0, 6), '_sweep'), (round(100.0 / 3.0, 6), '_near')]


STAND_IN = """import collections
import numba
import numpy as np

Scratch = collections.namedtuple('Scratch', ('fresh', 'pairs'))


def scratch(rows, cols):
    return Scratch(np.zeros(rows * cols, dtype=np.bool_),
                   np.zeros((rows * cols, 2), dtype=np.int32))


@numba.njit
def self_contact(s):
    return s.fresh.shape[0] + s.pairs.shape[0]
"""


def test_two_versions_scratch_arrays_reach_both_kernels_by_the_fast_path(
        monkeypatch, tmp_path):
    """
    Each version's scratch arrays come as one class, and no call is typed the slow way.

    Two stand-in versions, each with its own ``Scratch`` class of the same fields: given
    its own class's instance, the second version's every call went through the
    dispatcher's slow path (``_compile_for_args``, about 1 ms a call of the real kernel:
    the A/B tool timed a version 2.7-2.9 times a copy of itself); given the replay tool's
    scratch (:func:`_scratch`), none does.
    """
    monkeypatch.setenv('NUMBA_CACHE_DIR', str(tmp_path / 'cache'))
    tool, replay = load_tool('self_contact_ab'), load_tool('self_contact_replay')
    kernels = []
    for folder in ('a', 'b'):
        os.mkdir(tmp_path / folder)
        (tmp_path / folder / 'self_contact.py').write_text(STAND_IN)
        kernels.append(tool.load(str(tmp_path / folder / 'self_contact.py')))
    slow = []
    for kernel in kernels:
        monkeypatch.setattr(kernel, '_compile_for_args',
                            lambda *a, _k=kernel, _f=kernel._compile_for_args, **kw:
                            slow.append(_k) or _f(*a, **kw))

    def slow_calls(scratches):
        for kernel, s in zip(kernels, scratches):
            kernel(s)       # compiled for this class if it was not
        slow.clear()
        for kernel, s in zip(kernels, scratches):
            assert kernel(s) == 32
        return len(slow)

    own = [importlib.import_module(k.__module__).scratch(4, 4) for k in kernels]
    # numba 0.68.1: 1, the second version's (a later numba may have mended it)
    assert slow_calls(own) <= 1
    shared = [replay._scratch(k.__module__, (4, 4)) for k in kernels]
    assert type(shared[0]) is type(shared[1])
    assert shared[1].pairs.dtype == np.int32 and shared[1] is not shared[0]
    assert slow_calls(shared) == 0
