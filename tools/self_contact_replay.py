"""
Self-contact's kernel calls of the folded drop captured, then replayed alone: time and result.

    .venv/bin/python tools/self_contact_replay.py [--size 129] [--steps 61:100] \
        [--scene folded|fold] [--repeats 3] [--save FILE | --load FILE] \
        [--edges creases|sharp|all] [--chained] [--per-step]

Runs the contact bench's folded drop (``multigrid``, thickness 4 mm, one numba thread;
``--scene fold``: the fold demo's scene instead, ``tools/fold_jitter.py``'s seed 0 with
``--size`` its finest side, its ticks as the steps: at 129 x 129, ticks 300-329 hold the
layers lying on each other after the fold, each tick a first call finding 700-1,000 pairs
and a second after strain limiting),
keeps a copy of every argument of each finest-level kernel call in the steps asked for
(numbered from 1, both ends included; steps 61-100 at 129 x 129: the layers slide over
each other as the fold opens, every call finding pairs or checking the points strain
limiting moved), then runs each call again ``--repeats`` times on fresh copies and keeps
its fastest. Prints the time of the
calls in all, the median and mean of a step's calls, the same for the steps' first calls
and for their later ones and for the steps whose first call found pairs (as the contact
bench's figure "in contact" takes them; ``--per-step``: each step's calls, their times
and the pairs each found, too), and a digest of what the calls wrote (positions,
velocities, velocity changes) and returned (pair counts, sub-intervals, pairs dropped,
whether it ended clean; until 2026-11-30, session 38, the digest held only what they
wrote): a change to the kernel that gives the same digest gave the same result on every
call. A capture
also prints the digest of the calls as they ran, which the replay's matches. Each call
starts from the cache (boxes, flags, what lies on what) its capture held, so the digest
shows what one call does, not what it leaves to the next; ``--chained`` gives a step's
later calls the cache the replay of its call before left instead (their positions stay
the captured ones), so that what a call keeps for the next counts too. The steps' work
is the same for every version of the kernel, where ``tools/self_contact_calls.py``
follows each version's own motion (a different bit in a chaotic drop changes which steps
are in contact, and so the medians). ``--save``
writes the captured calls (about 3 MB a call at 129 x 129; the kernel's scratch arrays
are not kept, and the replayed calls share one set a level size, as a solver's calls do)
for another version to ``--load``: run the tool with ``PYTHONPATH`` pointing at each
version's tree. The fastest of the repeats leaves out what a call pays only the first time
it runs (until session 47 each call's scratch arrays were mapped afresh and faulted in,
0.5 ms of a sliding call in the bench that the fastest replay did not show): the bench
and ``tools/fold_jitter.py`` time calls as they run.
``--edges`` replays the calls with that setting's crease angle instead of the captured one
(``core.self_contact.CREASE_ANGLES``): what the edge tests cost on the same work.
"""

import argparse
import hashlib
import importlib
import inspect
import math
import pickle
import time

import numba
import numpy as np


def capture(size, first, last, scene='folded'):
    """
    Return the finest level's kernel calls in steps first..last and their results' digest.

    ``[(step, arguments)]``, each argument copied before the call (the kernel writes to
    them), and the digest of what those calls wrote and returned as they ran (as
    :func:`replay` makes it): a replay that gives the same digest did the same work.
    ``scene``: ``'folded'``, the contact bench's folded drop; ``'fold'``, the fold demo's
    scene (see :func:`_capture_fold`).
    """
    if scene == 'fold':
        return _capture_fold(size, first, last)
    from hcloth_ros.bench.self_contact import scene_setup
    from hcloth_ros.core import make_solver
    model, state, control = scene_setup(size, 'folded')
    solver = make_solver('multigrid', model, thickness=0.004)
    calls, now, digest = [], [0], hashlib.sha1()
    _capturing(solver, first, last, calls, now, digest)
    for step in range(1, last + 1):
        now[0] = step
        solver.step(state, control, 1 / 60)
        _progress(step, last, calls)
    print()
    return calls, digest.hexdigest()[:12]


def _capture_fold(size, first, last):
    """
    :func:`capture` on the fold demo's scene, its ticks numbered from 1.

    ``tools/fold_jitter.py``'s run of seed 0 (the demo's client path and timing, through
    the node's gripper logic), the scene's own solver (``hierarchical``) with ``size`` its
    finest side (33 x 33 and its levels up to 65 x 65, the demo's; 129 x 129, issue 10's
    16k points): the layers lie on each other from about tick 180 to the end (479).
    """
    import os
    import sys
    here = os.path.dirname(os.path.abspath(__file__))
    if here not in sys.path:
        sys.path.insert(0, here)
    import fold_jitter  # noqa: I100 (next to this tool)
    levels = {33: 1, 65: 2, 129: 3, 257: 4}.get(size)
    if levels is None:
        raise SystemExit(f'the fold scene runs at 33, 65, 129 or 257, not {size}')
    calls, now, digest = [], [0], hashlib.sha1()

    def prepare(sim):
        _capturing(sim.solver, first, last, calls, now, digest)
        advance = sim.advance

        def counted():
            now[0] += 1
            report = advance()
            _progress(now[0], last, calls)
            return report
        sim.advance = counted

    fold_jitter.run(0, overrides={'cloth.levels': levels}, prepare=prepare)
    print()
    return calls, digest.hexdigest()[:12]


def _capturing(solver, first, last, calls, now, digest):
    """
    Wrap the solver's finest-level kernels: keep the calls made in steps first..last.

    ``now[0]``: the step under way (the caller's); ``calls`` gets ``(step, arguments)``
    copied before each kept call, and ``digest`` what those calls wrote and returned.
    """
    finest = solver.levels()[-1]
    kit = solver.kernels(finest)

    def kept(*arguments):
        if not first <= now[0] <= last:
            return kit.self_contact(*arguments)
        calls.append((now[0], kept_copy(arguments)))
        result = kit.self_contact(*arguments)
        add_to_digest(digest, arguments, result)
        return result

    class Capturing:

        def __getattr__(self, name):
            return kept if name == 'self_contact' else getattr(kit, name)

    solver._kits[finest] = Capturing()


def _progress(step, last, calls):
    """Show how far a capture has come."""
    if step <= last:
        print(f'\rstep {step} of {last}, {len(calls)} calls kept', end='', flush=True)


# Where a call's arguments hold the patch cache (boxes .. the triangles points lie on), in
# it the scratch arrays (kernels.self_contact.Scratch: kept as None, made when a call
# runs; calls captured before 2026-12-02, session 47, have none), and the reuse flag that
# says which of the cache a call may keep (see kernels.self_contact)
CACHE = slice(15, 26)
SCRATCH = 24
REUSE = 26


def replay(calls, repeats, chained=False):
    """
    Run each call ``repeats`` times; return its fastest times, the results' digest and pairs.

    The pairs: what each call returned first (the pairs its first detection found).

    ``chained``: a call that may keep its step's cache (not a step's first) takes the one
    the replay of the call before it left.
    """
    kernel = importlib.import_module('hcloth_ros.core.kernels.self_contact').self_contact
    digest = hashlib.sha1()
    best, found, left = [], [], None
    for _, arguments in calls:
        times = []
        if chained and left is not None and arguments[REUSE]:
            arguments = list(arguments)
            arguments[CACHE] = left
        for _ in range(repeats):
            copies = fresh(arguments)
            start = time.perf_counter()
            result = kernel(*copies)
            times.append(time.perf_counter() - start)
        best.append(min(times))
        found.append(int(result[0]))
        left = copies[CACHE]
        add_to_digest(digest, copies, result)
    return np.array(best), digest.hexdigest()[:12], np.array(found)


def fresh(arguments, scratch=True, module='hcloth_ros.core.kernels.self_contact'):
    """
    Return a call's arguments with every array copied (the kernel writes to them).

    The scratch arrays (whose contents no call reads before it sets them) are one set per
    level's shape and kernel ``module`` (its name: the set its ``scratch`` makes),
    shared by every call as a solver's are; ``scratch`` False: none, for a kernel from
    before they were kept (:func:`takes_scratch`).
    """
    copies = _copied(arguments)
    if not scratch:
        return copies[:SCRATCH] + copies[SCRATCH + 1:]
    if copies[SCRATCH] is None:
        copies[SCRATCH] = _scratch(module, copies[6].shape)
    return copies


_SCRATCH = {}
_SCRATCH_CLASSES = {}


def _scratch(module, shape):
    """
    Return the scratch arrays of a level of ``shape`` (rows, cols), one set a shape.

    Made by ``module``'s ``scratch``, as an instance of the first class of that name and
    those fields' types that was made (:func:`_as_first_class`).
    """
    if (module, shape) not in _SCRATCH:
        made = importlib.import_module(module).scratch(*shape)
        _SCRATCH[module, shape] = _as_first_class(made)
    return _SCRATCH[module, shape]


def _as_first_class(made):
    """
    Return the named tuple ``made`` as an instance of the first class like it.

    Two versions of the kernel each define a class ``Scratch``; where their fields had the
    same types, numba's dispatcher took both classes for one in its fast path and found no
    compiled kernel for the second version, whose every call then went the slow way
    (typing each argument in Python): about 1 ms more a call, so that a version against a
    copy of itself timed B/A 2.7-2.9 in ``tools/self_contact_ab.py`` (session 48). The
    kernels read the fields by name, so one class serves both.
    """
    key = (type(made).__name__, made._fields,
           tuple((f.dtype.str, f.ndim) for f in made))
    first = _SCRATCH_CLASSES.setdefault(key, type(made))
    return made if first is type(made) else first(*made)


def takes_scratch(kernel):
    """Whether a version of the kernel takes the scratch arrays (session 47 on)."""
    return 'scratch' in inspect.signature(getattr(kernel, 'py_func', kernel)).parameters


def kept_copy(arguments):
    """Return a call's arguments copied to be kept, its scratch arrays left out (None)."""
    copies = _copied(arguments)
    copies[SCRATCH] = None
    return copies


def _copied(arguments):
    """Return a call's arguments with every array copied."""
    return [a.copy() if isinstance(a, np.ndarray) else a for a in arguments]


def add_to_digest(digest, copies, result):
    """Add what a call wrote (q, qd, dv: its first three arguments) and returned to ``digest``."""
    for written in copies[:3]:
        digest.update(written.tobytes())
    digest.update(repr(tuple(int(v) for v in result)).encode())


def fitted(arguments):
    """
    Return a captured call's arguments as this tool's calls hold them.

    The last one the kernel's crease angle: calls saved before 2026-11-30 end in
    ``all_edges`` (a bool): False, the creases of then (pi: the thickness's bound
    alone), True every bent edge (0). A place for the scratch arrays (None), which
    calls saved before 2026-12-02 lack.
    """
    last = arguments[-1]
    if isinstance(last, (bool, np.bool_)):
        last = 0.0 if last else math.pi
    arguments = list(arguments[:-1]) + [float(last)]
    if len(arguments) == REUSE + 1:
        arguments.insert(SCRATCH, None)
    return arguments


def later_call(arguments):
    """
    Whether a captured call is one of its step's later calls, not its first.

    By the kernel's reuse flag: BOXES_KEPT or BOXES_KEPT_NEW_START (1 or 2) on a step's
    later calls, BOXES_NEW (0) on its first.
    """
    return arguments[REUSE] != 0


def per_step(calls, seconds, which, steps=None):
    """
    Sum ``seconds`` by step over the calls ``which`` selects (first or later calls).

    ``steps``: only those steps (None: all).
    """
    totals = {}
    for (step, arguments), t in zip(calls, seconds):
        if (which is None or which == later_call(arguments)) and \
                (steps is None or step in steps):
            totals[step] = totals.get(step, 0.0) + t
    return np.array(list(totals.values()))


def steps_in_contact(calls, seconds, found):
    """Return the summed time of each step whose first call found pairs ("in contact")."""
    firsts = {step for (step, arguments), pairs in zip(calls, found)
              if not later_call(arguments) and pairs > 0}
    return per_step(calls, seconds, None, firsts)


def step_lines(calls, seconds, found):
    """Return a line a step: its calls' times (ms), first call first, and the pairs each found."""
    steps = {}
    for (step, arguments), t, pairs in zip(calls, seconds, found):
        steps.setdefault(step, []).append(f"{'later' if later_call(arguments) else 'first'} "
                                          f'{1e3 * t:.2f} ms ({pairs} pairs)')
    return [f'  step {step}: ' + ', '.join(parts) for step, parts in steps.items()]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--size', type=int, default=129)
    parser.add_argument('--scene', choices=('folded', 'fold'), default='folded',
                        help="the contact bench's folded drop, or the fold demo's scene")
    parser.add_argument('--steps', default='61:100', help='first:last, from 1, both included')
    parser.add_argument('--repeats', type=int, default=3)
    store = parser.add_mutually_exclusive_group()
    store.add_argument('--save', help='write the captured calls to this file')
    store.add_argument('--load', help='replay the calls of this file instead of capturing')
    parser.add_argument('--edges', choices=('creases', 'sharp', 'all'),
                        help="replay with this self-contact edges setting's crease angle")
    parser.add_argument('--chained', action='store_true',
                        help="give a step's later calls the cache the call before left")
    parser.add_argument('--per-step', action='store_true',
                        help="print each step's calls, their times and pairs")
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    if args.load:
        with open(args.load, 'rb') as f:
            calls = pickle.load(f)
        calls = [(step, fitted(arguments)) for step, arguments in calls]
    else:
        first, last = (int(v) for v in args.steps.split(':'))
        calls, captured = capture(args.size, first, last, args.scene)
        print(f'digest of the calls as they ran: {captured}')
        if args.save:
            with open(args.save, 'wb') as f:
                pickle.dump(calls, f)
    if not calls:
        raise SystemExit('no kernel calls in those steps')
    if args.edges:
        from hcloth_ros.core.self_contact import CREASE_ANGLES
        calls = [(step, arguments[:-1] + [CREASE_ANGLES[args.edges]])
                 for step, arguments in calls]
    replay(calls[:1], 1)        # compiled or loaded before the timing
    seconds, digest, found = replay(calls, args.repeats, args.chained)
    print(f'{len(calls)} calls in {len(per_step(calls, seconds, None))} steps, '
          f'{1e3 * seconds.sum():.1f} ms in all (fastest of {args.repeats} each); '
          f'digest {digest}')
    if args.per_step:
        print('\n'.join(step_lines(calls, seconds, found)))
    for label, which in (('all calls', None), ('first calls', False), ('later calls', True)):
        totals = 1e3 * per_step(calls, seconds, which)
        if len(totals):
            print(f'  {label}: a step median {np.median(totals):.2f} ms, '
                  f'mean {totals.mean():.2f} ms')
    touching = 1e3 * steps_in_contact(calls, seconds, found)
    if len(touching):
        print(f'  {len(touching)} steps whose first call found pairs: a step median '
              f'{np.median(touching):.2f} ms, mean {touching.mean():.2f} ms')


if __name__ == '__main__':
    main()
