"""
A running simulation and the commands that change it, kept in the order applied.

Everything that changes a running cloth between two ticks goes through
:meth:`Simulation.apply` as a command: a short list of strings and plain numbers, which JSON
keeps exactly (a float's repr reads back as the same float). The node turns its inputs
into commands; its recorder writes each tick's commands with the tick
(``replay/commands``), and :mod:`hcloth_ros.replay` builds the same simulation from the
recording's start (:meth:`Simulation.start_record`) and applies them before the same
ticks, which re-simulates the run bit for bit. ``R`` is a rotation matrix (three rows),
``p`` a translation (m), ids are point ids of the finest simulated level:

* ``['grasp', name, ids, R, p]``: hold ``ids`` rigidly in a frame at pose ``(R, p)``;
* ``['move', name, R, p]``: move a held frame; ``['release', name]``: let go;
* ``['pins', ids]``: the pinned points, all of them;
* ``['levels', finest]``: simulate levels 0..finest;
* ``['body', name, R, p]``: place a moving obstacle for the next step;
* ``['scene', values]``: the static obstacles from the ``scene.*`` parameters' values;
* ``['set', name, value]``: one of :data:`SETTINGS`;
* ``['reset']``: the initial state and time 0, nothing held, obstacles at rest.
"""

import functools
import hashlib
from importlib import metadata
import pathlib
import platform

from hcloth_ros import params
from hcloth_ros.core.recovery import retried, step_with_retries
from hcloth_ros.core.solvers import merged
from hcloth_ros.obstacles import ObstacleBank
import numpy as np

FORMAT = 1      # of the start record and the commands; a change breaks old recordings
KINDS = ('grasp', 'move', 'release', 'pins', 'levels', 'body', 'scene', 'set', 'reset')
SETTINGS = ('solver.dt', 'solver.substeps', 'solver.contact_rounds', 'solver.strain_limit',
            'solver.retry_strain')


# The package's sources a replay runs (the core, and what turns commands and parameters
# into its calls), relative to the package: a change to one of them may change the motion,
# which the package's version number does not say (it stays while the code changes).
ENGINE_SOURCES = ('core', 'simulation.py', 'params.py', 'obstacles.py', 'grippers.py')
# The libraries whose versions may change the motion's last bits.
ENGINE_LIBRARIES = ('numpy', 'numba')


def version():
    """Return the installed version of hcloth_ros ('unknown' outside an install)."""
    try:
        return metadata.version('hcloth_ros')
    except metadata.PackageNotFoundError:
        return 'unknown'


def source_digest(package):
    """
    Return the first 12 hex digits of a SHA-256 of the ``ENGINE_SOURCES`` under ``package``.

    Over each ``.py`` file's path (relative to ``package``, in sorted order) and bytes, so a
    file's edit, a new file or a renamed one changes it; compiled caches do not.
    """
    root = pathlib.Path(package)
    files = []
    for name in ENGINE_SOURCES:
        path = root / name
        files.extend(sorted(path.rglob('*.py')) if path.is_dir() else [path])
    digest = hashlib.sha256()
    for path in files:
        digest.update(path.relative_to(root).as_posix().encode() + b'\0')
        digest.update(path.read_bytes() + b'\0')
    return digest.hexdigest()[:12]


@functools.lru_cache(maxsize=1)
def engine():
    """
    Return what besides the parameters and commands decides a run's motion, as a dict.

    ``source``: :func:`source_digest` of this installed package; the Python, numpy and
    numba versions. A recording keeps it (:meth:`Simulation.start_record`) so that a
    replay can say which of them changed since (:func:`engine_changes`).
    """
    out = {'source': source_digest(pathlib.Path(__file__).parent),
           'python': platform.python_version()}
    for name in ENGINE_LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = 'unknown'
    return out


def engine_changes(recorded):
    """
    Return how this engine differs from a recording's (:func:`engine`), one text a change.

    ``recorded`` None (a recording made before recordings kept it): one text saying so.
    """
    if recorded is None:
        return ['the recording does not say which engine made it (made before recordings '
                'kept the source digest)']
    now = engine()
    return [f'{name} {recorded.get(name, "unknown")} -> {value}'
            for name, value in now.items() if recorded.get(name) != value]


def plain(value):
    """Return a parameter value JSON can write (arrays and numpy numbers as lists, floats)."""
    return value.tolist() if hasattr(value, 'tolist') else value


class Simulation:
    """
    The engine (model, solver, state, control) with the tick's settings and a journal.

    Made by :meth:`build` from parameter values (what the node and a replay do), or from
    parts (``values``: what :meth:`start_record` reports; the friction of moving
    obstacles comes from it). No moving obstacles until :meth:`add_moving_obstacles`.
    """

    def __init__(self, model, solver, state, control, dt, substeps, values=None):
        self.model, self.solver, self.state, self.control = model, solver, state, control
        self.values = {name: plain(v) for name, v in (values or {}).items()}
        self.moving_obstacles = []
        self.obstacles = ObstacleBank([], control.bodies, 0.0)
        self.initial = state.copy()
        self.dt, self.substeps = float(dt), int(substeps)
        self._journal = []

    @classmethod
    def build(cls, values):
        """
        Build the simulation of resolved parameter values (:func:`params.resolve`).

        Raises ValueError for a scene that cannot be built.
        """
        return cls(*params.build_all(values), values['solver.dt'], values['solver.substeps'],
                   values)

    def add_moving_obstacles(self, specs):
        """Add the moving obstacles of ``scene.moving_obstacles`` strings (ValueError if bad)."""
        self.obstacles = ObstacleBank(specs, self.control.bodies, self.values['scene.friction'])
        self.moving_obstacles = [str(s) for s in specs if str(s).strip()]

    def start_record(self):
        """Return what :mod:`hcloth_ros.replay` needs to build this simulation again."""
        return {'format': FORMAT, 'version': version(), 'engine': engine(),
                'values': self.values,
                'moving_obstacles': self.moving_obstacles}

    def apply(self, command):
        """Apply one command (module docstring) and keep it for :meth:`take_commands`."""
        kind, args = command[0], command[1:]
        if kind not in KINDS:
            raise ValueError(f'unknown command {kind!r} (have {KINDS})')
        getattr(self, '_' + kind)(*args)
        self._journal.append(command)

    def take_commands(self):
        """Return the commands applied since the last call, in order, and forget them."""
        taken, self._journal = self._journal, []
        return taken

    def advance(self, on_retry=None):
        """
        Run one tick: ``substeps`` steps of ``dt``, each retried in smaller steps if refused.

        ``on_retry(report, steps)`` hears of a step that needed retries (``steps`` 1: taken
        whole after all, see ``core.recovery.step_with_retries``); the tick stops at
        a step no retry got through. Grasp and body poses set before the tick are reached
        at its end, evenly over its steps (``Control.follow``). Returns the last step's
        report, merged over the tick's steps (``core.solvers.merged``: ``peak_strain`` the
        largest strain after any of them, ``seconds`` their compute, retries included).
        """
        plan = self.control.plan() if self.substeps > 1 else None
        reports = []
        for i in range(1, self.substeps + 1):
            if plan is not None:
                self.control.follow(plan, i / self.substeps)
            report, steps = step_with_retries(self.solver, self.state, self.control, self.dt)
            reports.append(report)
            if retried(report, steps) and on_retry is not None:
                on_retry(report, steps)
            if not report.ok:
                break
        if plan is not None:
            self.control.follow(plan, 1.0)    # a stopped tick: the poses asked stay asked
        return merged(reports)

    # --- the commands -------------------------------------------------------------------
    def _grasp(self, name, ids, rotation, translation):
        self.control.grasp(name, ids, self.state, np.array(rotation), np.array(translation))

    def _move(self, name, rotation, translation):
        self.control.move_grasp(name, np.array(rotation), np.array(translation))

    def _release(self, name):
        self.control.release(name)

    def _pins(self, ids):
        self.control.set_pins(ids)

    def _levels(self, finest):
        self.solver.set_finest_level(finest, self.state, self.control)

    def _body(self, name, rotation, translation):
        self.control.bodies.set_pose(name, np.array(rotation), np.array(translation))

    def _scene(self, values):
        self.model.scene = params.build_scene(values)

    def _set(self, name, value):
        if name == 'solver.dt':
            self.dt = float(value)
        elif name == 'solver.substeps':
            self.substeps = int(value)
        elif name == 'solver.contact_rounds':
            self.solver.contact_rounds = int(value)
        elif name == 'solver.strain_limit':
            self.solver.strain_limit = float(value) if value > 0 else None
        elif name == 'solver.retry_strain':
            self.solver.retry_strain = float(value) if value > 0 else None
        else:
            raise ValueError(f'no setting {name!r} (have {SETTINGS})')

    def _reset(self):
        self.state.assign(self.initial)
        self.control.release_all()
        self.control.bodies.commit()    # obstacles stay where they are, at rest
