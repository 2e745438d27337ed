"""
The node's own parameters and the checks of runtime changes (ROS-free checks).

The scene parameters (cloth, scene, solver, pins) are :mod:`hcloth_ros.params`; this adds
what only the node has (rate, frames, grippers, recording, threads) and the checks a
change must pass before anything is applied: ranges are rclpy's (from the descriptors),
what depends on the model (level and point counts) is checked here.
"""

from hcloth_ros import params
from hcloth_ros.params import Param
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor


NODE_PARAMS = [
    Param('rate_hz', 60.0, 'timer rate: steps and publications per second (Hz)', 1.0, 1000.0),
    Param('frame_id', 'world', 'frame of every published position'),
    Param('lod_level', 1, 'level published as cloth/lod_marker (0 = coarsest)', 0, 9, False),
    Param('grippers', ['left', 'right'], 'gripper names: each gets '
          'cloth/grippers/<name>/pose and .../close'),
    Param('rerun_path', '', 'record the run to this .rrd file; empty: no recording'),
    Param('rerun_url', '', 'stream to a running Rerun viewer at this url instead '
          '(e.g. rerun+http://127.0.0.1:9876/proxy); empty: none'),
    Param('rerun_finest_every', 1, 'log the finest mesh every N ticks (the LOD mesh '
          'and metrics every tick)', 1, 10000),
    Param('numba_threads', 1, 'threads of the numba kernels (capped at the cores); 1 '
          'gave the lowest tail latency with subscribers on the same 2 cores', 1, 256),
    Param('grasp_radius', 0.03, 'a closing gripper takes the points this close (m)',
          0.0, 1.0, False),
    Param('scene.moving_obstacles', [''], 'moving obstacles, one string each: "<name> '
          '<shape> <sizes> [friction]" with shape box (3 half extents), sphere (radius) or '
          'capsule (radius, half length along its z), in m; each follows '
          'cloth/obstacles/<name>/pose; [""] = none'),
    Param('publish_thread', True, 'send cloth/points and cloth/lod_marker from a thread '
          'of their own while the timer thread steps on (false: send within the tick)'),
    Param('governor', True, 'shed refinement levels while ticks overrun the period '
          '(false: simulate every consumed level, however long a tick takes)',
          read_only=False),
]
ALL_PARAMS = params.PARAMS + NODE_PARAMS


def descriptor(spec):
    """Return a parameter's ``ParameterDescriptor``: description, read-only flag, range."""
    d = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    scalar = spec.default if not isinstance(spec.default, list) else None
    if spec.low is not None and not isinstance(scalar, bool):
        if isinstance(scalar, float):
            d.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                         to_value=float(spec.high), step=0.0)]
        elif isinstance(scalar, int):
            d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high),
                                            step=1)]
    return d


def check_change(name, value, model):
    """Why a runtime change of ``name`` to ``value`` is refused for ``model``, or None."""
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


def unknown_overrides(given, known):
    """
    Names of parameter overrides (params file, ``-p``) that match no parameter.

    rclpy ignores them silently, so a misspelt ``cloth.widht`` would leave the default in
    place unseen. QoS overrides are rclpy's own.
    """
    return sorted(n for n in given if n not in known and not n.startswith('qos_overrides.'))
