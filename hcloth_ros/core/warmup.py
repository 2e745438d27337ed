"""
Kernels compiled (first start on a machine) or loaded from the cache before stepping.

:func:`warm_up` runs each requested solver for one step on a tiny cloth, so every kernel
it needs is compiled with the exact argument types the solver passes. On an empty cache
the compilation is spread over several processes first (:func:`compile_share`): numba
compiles one function at a time per process, and a first start on 2 cores halves. The
processes share the work through the cache: each compiles a share of the kernels and
saves them; the warm-up then loads them all.
"""

import os
import subprocess
import sys
import time

from hcloth_ros.core import kernels
from hcloth_ros.core.control import Control
from hcloth_ros.core.model import ClothBuilder
from hcloth_ros.core.scene import make_scene
from hcloth_ros.core.solvers import make_solver, SOLVERS
from hcloth_ros.core.state import State
import numba
import numpy as np


# Seconds a kernel took to compile from an empty cache here (2 cores, numba 0.68; the
# multigrid ones and self_contact with the other core busy): only to balance the shares of
# the processes; unknown kernels count 1. Strain limiting's sparse sweeps made it 1.29x
# (11.5 -> 14.8 s alone, one process): its two figures scaled. settle: after self_contact
# in the same process (their detection compiled once; 28 and 12 s that hour).
COMPILE_SECONDS = {'strain_limit': 9.4, 'strain_limit_parallel': 7.7, 'eq7_level': 2.2,
                   'eq7_level_parallel': 3.0, 'strain_stats': 1.9,
                   'strain_stats_parallel': 2.5, 'eq6_first_sweep': 2.1,
                   'eq6_second_sweep': 1.2, 'contact': 1.6, 'conjugate_gradient': 4.0,
                   'conjugate_gradient_parallel': 3.0, 'system_apply': 1.8,
                   'system_apply_parallel': 2.5, 'system_diagonal': 1.5, 'explicit_step': 1.5,
                   'energy': 1.0, 'multigrid_cg': 13.3, 'assemble_hierarchy': 8.1,
                   'newton_residual': 1.8, 'anchor': 1.8, 'new_positions': 0.4,
                   'start_velocity': 0.3, 'prescribe': 0.3, 'prolong': 0.5, 'inject': 0.1,
                   'points_by_id_f32': 0.3, 'self_contact': 18.8, 'settle': 12.0,
                   'body_contact': 6.3}


# Options a solver runs with to reach all its kernels: the multigrid solver refines by
# eq. 7 only above its accurate level.
EXERCISE_OPTIONS = {'multigrid': ({}, {'accurate_level': 0})}


def _tiny_model():
    """Two levels of 3 x 3 and 5 x 5 points over every kind of obstacle."""
    scene = make_scene(ground_z=0.0, boxes=[(0, 0, -1, 1, 1, 1)], spheres=[(0, 0, -1, 0.5)])
    return ClothBuilder(resolution=(3, 3), level_count=2, scene=scene).finalize()


def _exercise(model, solvers, parallel, energy, self_contact=False, bodies=False,
              tangent_strain=False, builds=None):
    """
    Make every kernel call the configuration makes.

    One step of each solver (and build), with self-contact (then a level dropped and
    brought back), a moving body and the contact rounds' tangent strain limiting if asked,
    the energy, a level restart. ``builds`` maps ``'serial'`` and ``'parallel'`` to the
    kernel sets (default :mod:`kernels`' own).
    """
    builds = builds or {'serial': kernels.SERIAL, 'parallel': kernels.PARALLEL}
    for name in SOLVERS if solvers is None else solvers:
        for build in ('serial', 'parallel') if parallel else ('serial',):
            for options in EXERCISE_OPTIONS.get(name, ({},)):
                if self_contact:
                    options = dict(options, thickness=0.01)
                if tangent_strain:
                    options = dict(options, contact_strain='tangent')
                state = State.at_rest(model)
                control = Control(model)
                control.pin([0])
                control.set_target(2, (1.0, 0.0, 1.0), state)
                if bodies:      # a sphere round the cloth's middle, moving
                    control.bodies.add('warm', 'sphere', [0.3])
                    control.bodies.set_pose('warm', np.eye(3), (0.5, 0.5, 1.0))
                    control.bodies.commit()
                    control.bodies.set_pose('warm', np.eye(3), (0.5, 0.5, 1.1))
                solver = make_solver(name, model, builds=builds[build], **options)
                solver.step(state, control, 1e-3)
                if self_contact and len(solver.levels()) > 1:
                    # a level brought back is pushed out of itself (SelfContact.settle)
                    solver.set_finest_level(0, state, control)
                    solver.set_finest_level(1, state, control)
    if tangent_strain:
        # as Solver._round_strain_limit calls it: a step of the tiny cloth need not reach
        # the contact rounds with a spring over its limit
        state, scene, control = State.at_rest(model), model.scene, Control(model)
        builds['serial'].tangent_strain_limit(
            state.q[1], state.qd[1], np.zeros_like(state.q[1]), model.level(1).rest,
            control.holds(1).kind, scene.planes, scene.boxes, scene.spheres,
            control.bodies.packed(), float(scene.margin), float(scene.friction), 0.1, 10,
            0.005, 1e-3, 1.0, True)
    state = State.at_rest(model)
    lv, kit = model.level(0), builds['serial']
    if energy:
        kit.energy(state.q[0], state.qd[0], lv.mass, lv.rest, lv.stiffness, lv.contraction,
                   model.gravity)
    kit.prolong(state.q[0], state.q[1])     # as prolong_state restarts a level
    fine = model.level(1)                   # as the node packs its cloud
    kit.points_by_id_f32(state.q[1], fine.id_to_grid,
                         np.empty((fine.point_count, 3), dtype=np.float32))


class _Recorder:
    """
    A kernel set that records each call's dispatcher and arguments instead of running it.

    Its results are harmless placeholders the solvers accept.
    """

    RESULTS = {'strain_limit': 0, 'contact': 0, 'body_contact': 0,
               'strain_stats': (0.0, 0.0, True),
               'conjugate_gradient': (1, 0.0), 'multigrid_cg': (1, 0.0), 'energy': (0.0, 0.0, 0.0),
               'self_contact': (0, 0, 0, False)}

    def __init__(self, kit, calls):
        self._kit, self._calls = kit, calls

    def __getattr__(self, name):
        dispatcher = getattr(self._kit, name)

        def record(*args):
            self._calls.append((dispatcher, args))
            return self.RESULTS.get(name)
        return record


def kernel_calls(solvers=None, parallel=None, energy=True, self_contact=False, bodies=False,
                 tangent_strain=False):
    """``[(dispatcher, signature)]`` a warm-up of this configuration compiles, each once."""
    parallel = numba.get_num_threads() > 1 if parallel is None else parallel
    calls = []
    sets = {'serial': _Recorder(kernels.SERIAL, calls),
            'parallel': _Recorder(kernels.PARALLEL, calls)}
    _exercise(_tiny_model(), solvers, parallel, energy, self_contact, bodies, tangent_strain,
              builds=sets)
    unique = {}
    for dispatcher, args in calls:
        signature = tuple(numba.typeof(a) for a in args)
        unique.setdefault((dispatcher.py_func.__name__, signature), (dispatcher, signature))
    return list(unique.values())


def compile_share(solvers, parallel, energy, self_contact, bodies, tangent_strain, index,
                  count):
    """
    Compile share ``index`` of ``count`` of the configuration's kernels into the cache.

    Shares are balanced by :data:`COMPILE_SECONDS`, largest first.
    """
    calls = sorted(kernel_calls(solvers, parallel, energy, self_contact, bodies,
                                tangent_strain),
                   key=lambda c: -COMPILE_SECONDS.get(c[0].py_func.__name__, 1.0))
    load = [0.0] * count
    for dispatcher, signature in calls:
        share = load.index(min(load))
        load[share] += COMPILE_SECONDS.get(dispatcher.py_func.__name__, 1.0)
        if share == index:
            dispatcher.compile(signature)


def _stamp(solvers, parallel, energy, self_contact, bodies, tangent_strain):
    """Return the file that says a configuration's kernels are in the cache (or None)."""
    if kernels.jit.CACHE_DIR is None:
        return None
    import llvmlite.binding
    names = sorted(SOLVERS if solvers is None else solvers)
    key = '-'.join(names + ['parallel' if parallel else 'serial']
                   + (['energy'] if energy else []) + (['contact'] if self_contact else [])
                   + (['bodies'] if bodies else [])
                   + (['tangent'] if tangent_strain else [])
                   + [numba.__version__, llvmlite.binding.get_host_cpu_name()])
    return os.path.join(kernels.jit.CACHE_DIR, f'warm-{key}')


def kernels_cached(solvers=None, parallel=None, energy=True, self_contact=False, bodies=False,
                   tangent_strain=False):
    """
    Tell whether :func:`warm_up` with these arguments ran on this machine before.

    If so it will load, not compile: under a second instead of tens of seconds.
    """
    parallel = numba.get_num_threads() > 1 if parallel is None else parallel
    stamp = _stamp(solvers, parallel, energy, self_contact, bodies, tangent_strain)
    return stamp is not None and os.path.exists(stamp)


def _compile_in_processes(solvers, parallel, energy, self_contact, bodies, tangent_strain,
                          processes):
    """Shares 1 .. processes-1 in child processes, share 0 here, all into the cache."""
    code = ('import sys; from hcloth_ros.core.warmup import compile_share; '
            'compile_share(*eval(sys.argv[1]))')
    package_root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [package_root] + [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p]))
    children = [subprocess.Popen([sys.executable, '-c', code,
                                  repr((solvers, parallel, energy, self_contact, bodies,
                                        tangent_strain, i, processes))], env=env)
                for i in range(1, processes)]
    try:
        compile_share(solvers, parallel, energy, self_contact, bodies, tangent_strain, 0,
                      processes)
    finally:
        for child in children:
            child.wait()


def warm_up(solvers=None, parallel=None, energy=True, self_contact=False, bodies=False,
            tangent_strain=False, processes=None):
    """
    Compile (or load from the cache) the kernels a configuration uses; returns seconds.

    ``solvers``: names (default: all of :data:`SOLVERS`; the gravity mode is a flag of the
    kernels, so either mode compiles both); ``parallel``: also the parallel builds
    (default: when numba runs more than one thread); ``energy``: the energy kernel
    (recordings and metrics); ``self_contact``: the self-contact kernel (off by default:
    18.8 s to compile, ``COMPILE_SECONDS``, for a feature that is opt-in); ``bodies``: the
    moving bodies' kernel (off by default, 6.3 s); ``tangent_strain``: the contact rounds'
    strain limiting along obstacles (``contact_strain='tangent'``); ``processes``:
    how many processes compile on an empty cache (default: the cores, at most 4; 1
    compiles here only). With the on-disk cache this loads machine code in well under a
    second.
    """
    start = time.perf_counter()
    parallel = numba.get_num_threads() > 1 if parallel is None else parallel
    processes = min(os.cpu_count() or 1, 4) if processes is None else int(processes)
    if processes > 1 and kernels.jit.CACHE_DIR is not None \
            and not kernels_cached(solvers, parallel, energy, self_contact, bodies,
                                   tangent_strain):
        _compile_in_processes(solvers, parallel, energy, self_contact, bodies, tangent_strain,
                              processes)
    _exercise(_tiny_model(), solvers, parallel, energy, self_contact, bodies, tangent_strain)
    stamp = _stamp(solvers, parallel, energy, self_contact, bodies, tangent_strain)
    if stamp is not None:
        try:
            with open(stamp, 'w'):
                pass
        except OSError:
            # the cache directory went away meanwhile (a process started on edited kernel
            # sources prunes the caches of earlier ones, kernels.jit): the kernels are
            # compiled all the same, and the next start compiles again
            pass
    return time.perf_counter() - start
