"""
The scene parameters: one table for the node, the README and the engine tools.

The node declares the table, the README documents it and the engine tools read it from
the same YAML files in ``config/``.

A parameter file has the ROS 2 layout (``<node name or /**>: ros__parameters: ...``);
nested keys become dotted names (``cloth: {width: 1.0}`` is ``cloth.width``).
"""

import array
from dataclasses import dataclass
import os

from hcloth_ros.core import ClothBuilder, Control, make_scene, make_solver, Placement, State
from hcloth_ros.core.multigrid_solver import TOLERANCE_STEPS
from hcloth_ros.core.solvers import CONTACT_STRAIN, TANGENT_RELAXATION
import numpy as np
import yaml


@dataclass(frozen=True)
class Param:
    """
    One parameter: name, default (its type is the parameter's type), description, range.

    ``low``/``high`` bound a number or every element of a list; ``choices`` lists the
    allowed strings; ``length`` is a list's exact length, ``multiple`` what its length must
    be a multiple of (the ROS-friendly "unset" ``[0.0]`` and ``[-1]`` aside).
    """

    name: str
    default: object
    description: str
    low: float = None
    high: float = None
    read_only: bool = True
    choices: tuple = None
    length: int = None
    multiple: int = None


PARAMS = [
    Param('cloth.width', 1.0, 'cloth size along axis_u (m)', 0.01, 100.0),
    Param('cloth.height', 1.0, 'cloth size along axis_v (m)', 0.01, 100.0),
    Param('cloth.resolution', [9, 9], 'level-0 points along u and v (each >= 2)', 2, 1025,
          length=2),
    Param('cloth.levels', 4, 'number of hierarchy levels (finest has '
          '2^(levels-1) (n0-1)+1 points a side)', 1, 10),
    Param('cloth.mass', 0.2, 'total cloth mass (kg)', 1e-6, 1e3),
    Param('cloth.k_struct', 1000.0, 'structural spring stiffness (N/m)', 1e-3, 1e9),
    Param('cloth.k_shear', 1000.0, 'shear spring stiffness (N/m)', 0.0, 1e9),
    Param('cloth.k_bend', 100.0, 'bending spring stiffness (N/m)', 0.0, 1e9),
    Param('cloth.stiffness_scale', [0.0], 'per-level stiffness factor ([0.0] = all 1)',
          0.0, 1e6),
    Param('cloth.contraction', [0.0], 'per-level contraction resistance in [0, 1] '
          '([0.0] = all 1)', 0.0, 1.0),
    Param('cloth.air_drag', 0.0, 'air drag per unit area: a point moving at v feels '
          '-air_drag * area * v (N s/m^3; multigrid solver)', 0.0, 1e6),
    Param('cloth.spring_damping', 0.0, 'damping of every spring along its length '
          '(N s/m; multigrid solver)', 0.0, 1e6),
    Param('cloth.origin', [-0.5, 0.0, 1.5], 'world position of grid point (0, 0) at t = 0 (m)',
          -1e4, 1e4, length=3),
    Param('cloth.axis_u', [1.0, 0.0, 0.0], 'world direction of the cloth width', -1.0, 1.0,
          length=3),
    Param('cloth.axis_v', [0.0, 1.0, 0.0], 'world direction of the cloth height', -1.0, 1.0,
          length=3),
    Param('scene.ground', True, 'a ground plane at scene.ground_z', read_only=False),
    Param('scene.ground_z', 0.0, 'ground height (m)', -1e4, 1e4, False),
    Param('scene.boxes', [0.0], 'axis-aligned boxes, 6 numbers each: centre xyz, half '
          'extents xyz (m); [0.0] = none', -1e4, 1e4, False, multiple=6),
    Param('scene.spheres', [0.0], 'spheres, 4 numbers each: centre xyz, radius (m); '
          '[0.0] = none', -1e4, 1e4, False, multiple=4),
    Param('scene.friction', 0.5, 'Coulomb friction coefficient with obstacles', 0.0, 10.0,
          False),
    Param('scene.margin', 0.002, 'distance kept from obstacle surfaces (m)', 0.0, 0.1, False),
    Param('solver.name', 'multigrid', 'multigrid, hierarchical, explicit, approx or implicit',
          choices=('multigrid', 'hierarchical', 'explicit', 'approx', 'implicit')),
    Param('solver.accurate_level', 1, 'multigrid: the finest level solved by BDF2 and '
          'multigrid-CG; finer levels follow eq. 7 (clipped to the finest level)', 0, 9),
    Param('solver.solved_strain_limit', 0.0, 'multigrid: strain limiting on the level it '
          'solves (0.1 = 10 %; 0: off, its springs hold the cloth on their own). Where that '
          'level is the finest and touches the ground or itself, contact stretches its '
          'springs with nothing to pull them back (0.72 in the folded drop at 129 x 129)',
          0.0, 9.99),
    Param('solver.integrator', 'bdf2', 'multigrid: bdf2 or backward_euler',
          choices=('bdf2', 'backward_euler')),
    Param('solver.newton_iterations', 3, 'multigrid: Newton iterations every step takes',
          1, 100),
    Param('solver.cg_iterations', 2, 'multigrid: preconditioned CG iterations per Newton '
          'iteration', 1, 1000),
    Param('solver.max_newton_iterations', 12, 'multigrid: most Newton iterations a step '
          'takes while its residual is above solver.newton_tolerance (at least '
          'solver.newton_iterations), on the steps solver.newton_tolerance_steps names',
          1, 100),
    Param('solver.newton_tolerance', 0.3, 'multigrid: residual a step may leave, in units of '
          'the momentum the weight gives the cloth over the step', 1e-6, 1e6),
    Param('solver.newton_tolerance_steps', 'moved', 'multigrid: which steps iterate to '
          'solver.newton_tolerance: moved (those starting from a state something moved '
          'after the last solve: contact, self-contact, an edit, a start; a free cloth takes '
          'the fixed count unless it leaves a residual 10 times the tolerance: a steady '
          'tick for real time) or all (every step: more accurate where a fine level is '
          'solved, at up to twice the cost; the solver class and the benchmark default)',
          choices=TOLERANCE_STEPS),
    Param('solver.external', 'exact', 'gravity outside the filter (exact) or inside it '
          '(literal, the paper as written)', choices=('exact', 'literal')),
    Param('solver.strain_limit', 0.1, 'largest spring stretch kept by strain limiting '
          '(0.1 = 10 %; multigrid: on the eq. 7 levels only); 0 switches it off', 0.0, 10.0,
          False),
    Param('solver.retry_strain', 0.5, 'a step in which self-contact found pairs and a '
          'finest spring stretches beyond this (0.5 = 50 %) from a start where none was is '
          'taken again as 2, then 4, then 8 smaller steps (the last however far they '
          'stretch; grippers and bodies move evenly over them): layers of the cloth meeting '
          'fast; keep it above solver.strain_limit (the node warns otherwise); 0 switches '
          'it off', 0.0, 5.0, False),
    Param('solver.dt', 1 / 60, 'simulated seconds per step (s)', 1e-6, 0.1, False),
    Param('solver.substeps', 1, 'solver steps per timer tick', 1, 100, False),
    Param('solver.contact_rounds', 16, 'most rounds of strain limiting '
          '(solver.contact_sweeps sweeps, every point free) and contact on each refinement '
          'level and on the finest level when it touches an obstacle; the coarser levels '
          'then take the finest state; 0: none',
          0, 1000, False),
    Param('solver.contact_sweeps', 0, 'most strain limiting sweeps of each contact round; '
          "0: the strain limiting's own (tangent 300: it stops once every spring is within "
          'the limit; jacobi 10)', 0, 10000),
    Param('solver.contact_strain', 'tangent', "contact rounds' strain limiting: tangent "
          '(Gauss-Seidel, points lying on an obstacle or a moving body move along its '
          'surface, points a body presses into the ground stay where it holds them: holds '
          "springs across a table edge and round a finger) or jacobi (the levels' own: on "
          'the 129 x 129 table drop 0.77 strain at 1.4x the step, see doc/contact_log.md)',
          choices=CONTACT_STRAIN),
    Param('solver.contact_relaxation', TANGENT_RELAXATION, 'tangent contact strain '
          'limiting moves a spring free to move along itself this many times its correction '
          '(over-relaxation; 1: plain Gauss-Seidel, about 1.8x the step on the 129 x 129 '
          'table drop, see doc/contact_log.md)',
          1.0, 1.95),
    Param('solver.contact_tethers', True, 'tangent contact strain limiting pulls each point '
          'within the strain limit of the nearest held point (grip, pin, point a body '
          'presses into the ground) when its sweeps do not settle in 8: half the step of a '
          'finger dragging a 257 x 257 cloth (see the README)'),
    Param('self_contact.thickness', 0.0, 'self-contact: finest points stay this far from '
          "the cloth's own triangles and never cross one (m); 0 switches it off", 0.0, 0.1),
    Param('self_contact.friction', 0.3, 'self-contact: friction coefficient between layers',
          0.0, 10.0),
    Param('self_contact.iterations', 8, 'self-contact: most rounds of detection and '
          'response a check (then one more moving points alone)', 1, 100),
    Param('self_contact.interval', 1, 'self-contact: check every n-th step (cheaper, but '
          'layers may pass through each other in between)', 1, 1000),
    Param('self_contact.edges', 'auto', 'self-contact: the edges tested against edges '
          'besides the free borders: sharp (creases bent enough for an edge to pass under '
          'them a thickness clear), creases (those and every edge bent past 10 degrees: '
          'layers meeting fast hook edges bent less; 1.2-1.9 times the cost of sharp where '
          'layers touch), all (every bent edge: a cloth crumpled finer than its coarse '
          'levels hooks edges a few rows apart; 1.2-1.3 times the cost of creases) or auto '
          '(all on a level the solver solves whole, creases on eq. 7 refinements)',
          choices=('auto', 'creases', 'sharp', 'all')),
    Param('pinned_points', [0, 8], 'finest-level point ids that hold still (see README '
          'for the numbering); [-1] = none', -1, 2 ** 31 - 1, False),
]
PARAM_BY_NAME = {p.name: p for p in PARAMS}


def config_path(name):
    """Return a file of this package's ``config/``: installed share directory, else the source."""
    try:
        from ament_index_python.packages import get_package_share_directory
        path = os.path.join(get_package_share_directory('hcloth_ros'), 'config', name)
        if os.path.exists(path):
            return path
    except (ImportError, LookupError, ValueError, OSError):
        pass
    return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                        'config', name)


def flatten(tree, prefix=''):
    out = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            out.update(flatten(value, name + '.'))
        else:
            out[name] = value
    return out


def load_file(path):
    """Parameters of a ROS 2 parameter file (first node section), flattened."""
    with open(path) as f:
        doc = yaml.safe_load(f) or {}
    for section in doc.values():
        if isinstance(section, dict) and 'ros__parameters' in section:
            return flatten(section['ros__parameters'])
    raise ValueError(f'{path}: no "ros__parameters" section')


def allowed(spec):
    """Say what values ``spec`` takes, for error messages and descriptors."""
    kind = _kind(spec.default)
    text = {'bool': 'true or false', 'str': 'a string', 'float': 'a number',
            'int': 'an integer', 'float list': 'a list of numbers',
            'int list': 'a list of integers', 'str list': 'a list of strings'}[kind]
    if spec.choices:
        text = 'one of ' + ', '.join(spec.choices)
    elif spec.low is not None:
        text += f' in {spec.low:g} .. {spec.high:g}' if 'list' not in kind else \
            f', each in {spec.low:g} .. {spec.high:g}'
    if spec.length:
        text += f', exactly {spec.length}'
    if spec.multiple:
        text += f', {spec.multiple} per item'
    return text


def _kind(value):
    """Return the parameter kind of a default: 'bool', 'int', 'float', 'str' or '<that> list'."""
    if isinstance(value, list):
        return f'{_kind(value[0])} list'
    for name, kind in (('bool', bool), ('int', int), ('float', float), ('str', str)):
        if isinstance(value, kind):
            return name
    raise TypeError(f'no parameter kind for {value!r}')


def _kind_fits(want, value):
    """Whether ``value`` has the kind ``want`` (integers are numbers too)."""
    if want.endswith(' list') and isinstance(value, array.array):
        # what rclpy hands over from the parameter service: its type code says it all
        codes = {'float list': 'dq', 'int list': 'q'}.get(want, '')
        return len(value) > 0 and value.typecode in codes
    if want.endswith(' list'):
        return (isinstance(value, (list, tuple)) and len(value) > 0
                and all(_kind_fits(want[:-5], v) for v in value))
    if want == 'float':
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return _kind(value) == want if isinstance(value, (bool, int, float, str)) else False


SEQUENCES = (list, tuple, array.array)


def _short(value, shown=8):
    """Return ``repr(value)``, a long list cut to its first items and its length."""
    if isinstance(value, SEQUENCES) and len(value) > shown:
        return f'[{", ".join(repr(v) for v in value[:shown])}, ... ({len(value)} values)]'
    text = repr(list(value) if isinstance(value, array.array) else value)
    return text if len(text) <= 200 else text[:200] + '...'


def check_value(spec, value):
    """
    Why ``value`` is not allowed for parameter ``spec``, or None when it is.

    The one check of a value, at start-up and for runtime changes: kind (an integer is
    accepted where a number is meant), choices, finite and within the range (every
    element of a list), list length.
    """
    kind = _kind(spec.default)
    problem = None
    if not _kind_fits(kind, value):
        problem = 'wrong type'
    elif spec.choices and value not in spec.choices:
        problem = 'unknown value'
    elif spec.low is not None and kind != 'bool':
        arr = np.atleast_1d(np.asarray(value, dtype=float))
        if not np.all(np.isfinite(arr)) or arr.min() < spec.low or arr.max() > spec.high:
            problem = 'out of range'
    if problem is None and isinstance(value, SEQUENCES):
        unset = len(value) == 1 and value[0] in (0.0, -1)
        if spec.length and len(value) != spec.length:
            problem = f'{len(value)} values'
        elif spec.multiple and not unset and len(value) % spec.multiple:
            problem = f'{len(value)} values'
    if problem is None:
        return None
    return f'{spec.name} = {_short(value)}: {problem}; allowed: {allowed(spec)}'


def assignments(pairs):
    """Map ``NAME=VALUE`` strings (command-line overrides) to names and YAML values."""
    out = {}
    for pair in pairs:
        name, sep, value = pair.partition('=')
        if not sep or not name:
            raise ValueError(f'{pair!r}: expected NAME=VALUE')
        out[name] = yaml.safe_load(value)
    return out


def overrides(pairs):
    """
    :func:`assignments` of engine parameters, for the tools' ``-p NAME=VALUE``.

    A name the table does not have is refused: :func:`resolve` leaves such names out (a
    scene file also holds the node's own parameters), so a misspelt one would leave the
    default in place unseen.
    """
    out = assignments(pairs)
    unknown = sorted(name for name in out if name not in PARAM_BY_NAME)
    if unknown:
        raise ValueError(f'unknown parameters: {", ".join(unknown)} (see the README '
                         'parameter table)')
    return out


def resolve(overrides=None):
    """
    Defaults updated by ``overrides``; disallowed values refused.

    Names the table does not have are left out: the node's own parameters (rate, topics,
    grippers) share its parameter files (see :func:`overrides` for the tools).
    """
    values = {p.name: p.default for p in PARAMS}
    for name, value in (overrides or {}).items():
        if name not in PARAM_BY_NAME:
            continue        # node-only parameters (rate, topics, ...) live elsewhere
        reason = check_value(PARAM_BY_NAME[name], value)
        if reason:
            raise ValueError(reason)
        values[name] = value
    return values


def _list_or_none(values, count=None):
    """``[0.0]`` (the ROS-friendly "unset") means None; otherwise a float list."""
    vals = [float(v) for v in values]
    if vals == [0.0]:
        return None
    if count and len(vals) % count:
        raise ValueError(f'expected a multiple of {count} numbers, got {len(vals)}')
    return vals


def pin_ids(values):
    """``[-1]`` (the ROS-friendly "none": an empty YAML list has no type) means no pins."""
    ids = [int(v) for v in values]
    return [] if ids == [-1] else ids


def build_scene(values):
    """Return the static obstacles of resolved values (ValueError if they make none)."""
    return make_scene(
        ground_z=float(values['scene.ground_z']) if values['scene.ground'] else None,
        boxes=np.reshape(_list_or_none(values['scene.boxes'], 6) or [], (-1, 6)),
        spheres=np.reshape(_list_or_none(values['scene.spheres'], 4) or [], (-1, 4)),
        friction=float(values['scene.friction']), margin=float(values['scene.margin']))


def build_model(values):
    scene = build_scene(values)
    placement = Placement(tuple(map(float, values['cloth.origin'])),
                          tuple(map(float, values['cloth.axis_u'])),
                          tuple(map(float, values['cloth.axis_v'])))
    return ClothBuilder(
        width=float(values['cloth.width']), height=float(values['cloth.height']),
        resolution=tuple(int(v) for v in values['cloth.resolution']),
        level_count=int(values['cloth.levels']), total_mass=float(values['cloth.mass']),
        k_struct=float(values['cloth.k_struct']), k_shear=float(values['cloth.k_shear']),
        k_bend=float(values['cloth.k_bend']),
        stiffness_scale=_list_or_none(values['cloth.stiffness_scale']),
        contraction=_list_or_none(values['cloth.contraction']),
        air_drag=float(values['cloth.air_drag']),
        spring_damping=float(values['cloth.spring_damping']),
        placement=placement, scene=scene).finalize()


def build_solver(model, values):
    limit = float(values['solver.strain_limit'])
    limit = limit if limit > 0 else None
    name = values['solver.name']
    options = {}
    if name == 'multigrid':     # its own options (its strain limit is the eq. 7 levels')
        options = {'accurate_level': int(values['solver.accurate_level']),
                   'integrator': values['solver.integrator'],
                   'newton_iterations': int(values['solver.newton_iterations']),
                   'cg_iterations': int(values['solver.cg_iterations']),
                   'max_newton_iterations': int(values['solver.max_newton_iterations']),
                   'newton_tolerance': float(values['solver.newton_tolerance']),
                   'newton_tolerance_steps': values['solver.newton_tolerance_steps']}
        # (a recording started before the parameter existed replays without it, as it ran)
        solved = float(values.get('solver.solved_strain_limit', 0.0))
        options['solved_strain_limit'] = solved if solved > 0 else None
    thickness = float(values['self_contact.thickness'])
    if thickness > 0.0:
        options.update(thickness=thickness,
                       self_friction=float(values['self_contact.friction']),
                       self_contact_iterations=int(values['self_contact.iterations']),
                       self_contact_interval=int(values['self_contact.interval']),
                       # (before it: the creases of then, sharp ones alone)
                       self_contact_edges=values.get('self_contact.edges', 'sharp'))
    # (a recording started before the parameter existed replays without it, as it ran)
    retry = float(values.get('solver.retry_strain', 0.0))
    return make_solver(name, model, external=values['solver.external'], strain_limit=limit,
                       retry_strain=retry if retry > 0 else None,
                       contact_rounds=int(values['solver.contact_rounds']),
                       contact_sweeps=int(values['solver.contact_sweeps']) or None,
                       contact_strain=values['solver.contact_strain'],
                       contact_relaxation=float(values['solver.contact_relaxation']),
                       contact_tethers=bool(values['solver.contact_tethers']), **options)


def build_all(values):
    """``(model, solver, state, control)`` for resolved parameter values."""
    model = build_model(values)
    solver = build_solver(model, values)
    state = State.at_rest(model)
    control = Control(model)
    control.set_pins(pin_ids(values['pinned_points']))
    return model, solver, state, control
