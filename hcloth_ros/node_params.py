"""
The node's own parameters and the checks of runtime changes (ROS-free checks).

The scene parameters (cloth, scene, solver, pins) are :mod:`hcloth_ros.params`; this adds
what only the node has (rate, frames, grippers, recording, threads) and the checks a
change must pass before anything is applied: ranges are rclpy's (from the descriptors),
what depends on the model (level and point counts) is checked here.
"""

import array
import re

from hcloth_ros import params
from hcloth_ros.params import Param
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
import yaml


NODE_PARAMS = [
    Param('real_time_factor', 1.0, 'simulated seconds per wall-clock second: the timer '
          'ticks every solver.dt x solver.substeps / real_time_factor of steady time; 0: as '
          'fast as possible (no governor)', 0.0, 1000.0, False),
    Param('frame_id', 'world', 'frame of every published position'),
    Param('lod_level', 1, 'level published as cloth/lod_marker (0 = coarsest)', 0, 9, False),
    Param('grippers', ['left', 'right'], 'gripper names: each gets '
          'cloth/grippers/<name>/pose and .../close'),
    Param('rerun_path', '', 'record the run to this .rrd file; empty: no recording'),
    Param('rerun_url', '', 'stream to a running Rerun viewer at this url instead '
          '(e.g. rerun+http://127.0.0.1:9876/proxy); empty: none'),
    Param('rerun_finest_every', 30, 'log the finest mesh every N ticks (the LOD mesh '
          'and metrics every tick); 30 keeps 10 minutes of the default scene near 220 MB',
          1, 10000),
    Param('numba_threads', 1, 'threads of the numba kernels (capped at the cores); 1 '
          'gave the lowest tail latency with subscribers on the same 2 cores', 1, 256),
    Param('grasp_radius', 0.03, 'a closing gripper takes the points this close (m)',
          0.0, 1.0, False),
    Param('grasp_max_speed', 5.0, 'a grasping gripper travels to its newest pose at most '
          'this fast (m/s of simulated time), so a pose far away is reached over several '
          'ticks instead of tearing the cloth there in one step; 0: no limit', 0.0, 1000.0,
          False),
    Param('obstacle_max_speed', 5.0, 'a placed moving obstacle travels to its newest pose '
          'at most this fast (m/s of simulated time), as grippers do; 0: no limit', 0.0,
          1000.0, False),
    Param('scene.moving_obstacles', [''], 'moving obstacles, one string each: "<name> '
          '<shape> <sizes> [friction]" with shape box (3 half extents), sphere (radius) or '
          'capsule (radius, half length along its z), in m; each follows '
          'cloth/obstacles/<name>/pose; [""] = none'),
    Param('publish_thread', True, 'send cloth/points and cloth/lod_marker from a thread '
          'of their own while the timer thread steps on (false: send within the tick)'),
    Param('bag_path', '', "record the node's own topics (cloud, LOD marker, scene, /clock) to "
          'this MCAP file (ros2 bag, Foxglove); empty: no bag'),
    Param('memory_budget_mb', 8000.0, 'refuse to start a scene whose estimated memory '
          '(README, "Memory") exceeds this many MB; 8000: a third of a 24 GB machine',
          100.0, 1e7),
    Param('governor', True, 'shed refinement levels while ticks overrun the period '
          '(false: simulate every consumed level, however long a tick takes)',
          read_only=False),
]
ALL_PARAMS = params.PARAMS + NODE_PARAMS


SPEC_BY_NAME = {spec.name: spec for spec in ALL_PARAMS}


def descriptor(spec):
    """
    Return a parameter's ``ParameterDescriptor``: description, read-only flag, range.

    Lists carry their elements' range too (rclpy checks ranges of scalars only; the node
    checks lists itself, :func:`~hcloth_ros.params.check_value`), and
    ``additional_constraints`` says in words what is allowed.
    """
    d = ParameterDescriptor(description=spec.description, read_only=spec.read_only,
                            additional_constraints=params.allowed(spec))
    element = spec.default[0] if isinstance(spec.default, list) else spec.default
    if spec.low is not None and not isinstance(element, bool):
        if isinstance(element, float):
            d.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                         to_value=float(spec.high), step=0.0)]
        elif isinstance(element, int):
            d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high),
                                            step=1)]
    return d


def ros_type(spec):
    """Return the ROS parameter type of ``spec`` (``double``, ``string[]``, ...)."""
    names = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
    if isinstance(spec.default, list):
        return names[type(spec.default[0])] + '[]'
    return names[type(spec.default)]


def as_declared_type(spec, value):
    """
    Return ``value`` in the type ``spec`` is declared with, where that loses nothing.

    ``cloth.width: 1`` in YAML or ``-p cloth.width:=1`` is an integer; rclpy would refuse
    it for a floating-point parameter. Anything else is returned unchanged.
    """
    default = spec.default
    if isinstance(default, float) and type(value) is int:
        return float(value)
    if not (isinstance(default, list) and isinstance(default[0], float)) or not value:
        return value
    if isinstance(value, array.array):      # from the parameter service
        return array.array('d', value) if value.typecode == 'q' else value
    if isinstance(value, (list, tuple)) and all(type(v) is int for v in value):
        return [float(v) for v in value]
    return value


def check_change(name, value, model):
    """Why a runtime change of ``name`` to ``value`` is refused for ``model``, or None."""
    if name in SPEC_BY_NAME:
        reason = params.check_value(SPEC_BY_NAME[name], value)
        if reason:
            return reason
    if name == 'lod_level' and not 0 <= value < model.level_count:
        return f'lod_level {value} out of range 0..{model.level_count - 1}'
    if name == 'pinned_points':
        bad = [i for i in params.pin_ids(value) if not 0 <= i < model.point_count]
        if bad:
            return f'pinned_points {bad[:5]} out of range 0..{model.point_count - 1}'
    return None


def scene_after(changes, current):
    """
    Return ``(scene, None)``: the static scene after a batch of parameter changes.

    Or ``(None, why)`` if it does not make one. ``changes`` and ``current`` map parameter
    names to values; only ``scene.*`` names of the scene table count.
    """
    values = {n: v for n, v in current.items() if n in params.PARAM_BY_NAME}
    values.update({n: v for n, v in changes.items() if n in params.PARAM_BY_NAME})
    try:
        return params.build_scene(params.resolve(values)), None
    except (ValueError, TypeError) as e:
        return None, f'scene refused, nothing changed: {e}'


def startup_problems(overrides):
    """
    One line per override (params file, ``-p``) the node cannot start with.

    ``overrides`` maps names to values; names of no parameter of the node are reported
    apart (:func:`unknown_overrides`).
    """
    return [reason for name, value in overrides.items() if name in SPEC_BY_NAME
            for reason in [params.check_value(SPEC_BY_NAME[name], value)] if reason]


def _ros_options(argv, flags):
    """Yield the value after each of ``flags`` inside the ``--ros-args`` sections of argv."""
    ros = False
    for i, arg in enumerate(argv):
        if arg == '--ros-args':
            ros = True
        elif arg == '--':
            ros = False
        elif ros and arg in flags and i + 1 < len(argv):
            yield argv[i + 1]


def params_files(argv):
    """Return the ``--params-file`` paths of the ROS arguments in ``argv``."""
    return list(_ros_options(argv, ('--params-file',)))


def overrides_in(argv):
    """Return the ``-p name:=value`` overrides of the ROS arguments in ``argv`` (YAML values)."""
    out = {}
    for rule in _ros_options(argv, ('-p', '--param')):
        name, sep, text = rule.partition(':=')
        if not sep:
            continue
        try:
            out[name] = yaml.safe_load(text)
        except yaml.YAMLError:
            out[name] = text    # rcl reads it as a string
    return out


def mixed_lists(tree, prefix=''):
    """
    Return a line for each list in ``tree`` that mixes integers and decimal numbers.

    rcl refuses such a list (``Sequence should be of same type``) without naming it.
    """
    lines = []
    if isinstance(tree, dict):
        for key, value in tree.items():
            name = key if key == 'ros__parameters' or not prefix else f'{prefix}.{key}'
            lines += mixed_lists(value, '' if key == 'ros__parameters' else name)
    elif isinstance(tree, list):
        kinds = {type(v) for v in tree} & {int, float}
        if len(kinds) == 2:
            fixed = [float(v) if type(v) is int else v for v in tree]
            lines.append(f'{prefix} = {tree}: mixes integers and decimal numbers, which rcl '
                         f'refuses; write them all as decimals: {fixed}')
    return lines


def _key_pattern(key):
    """Return a params file's node key (``/**``, ``/ns/name``, ``name``, ``*``) as a regex."""
    key = key if key.startswith('/') else '/' + key
    pattern = re.escape(key).replace(r'/\*\*/', '/(?:.*/)?')
    return pattern.replace(r'\*\*', '.*').replace(r'\*', '[^/]*')


def sections_for(path, fqn):
    """
    Return the node keys of a params file that apply to the node ``fqn`` (``/ns/name``).

    rcl gives a node the ``ros__parameters`` of every key that matches it and ignores
    the rest in silence: a file keyed to another name leaves the defaults in place.
    """
    with open(path) as f:
        doc = yaml.safe_load(f) or {}
    if not isinstance(doc, dict):
        return []
    return [key for key in doc if isinstance(key, str)
            and re.fullmatch(_key_pattern(key), fqn)]


def unknown_overrides(given, known):
    """
    Names of parameter overrides (params file, ``-p``) that match no parameter.

    rclpy ignores them silently, so a misspelt ``cloth.widht`` would leave the default in
    place unseen. QoS overrides are rclpy's own.
    """
    return sorted(n for n in given if n not in known and not n.startswith('qos_overrides.'))
