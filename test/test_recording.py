"""Recording to Rerun: the node writes an .rrd that reads back with the right content."""

import time

from hcloth_ros.node import ClothSimNode
import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rerun.chunk import RrdReader


def _rows(path):
    """Map entity path -> (rows on the sim_time timeline, column names)."""
    out = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        rows, names = out.get(chunk.entity_path, (0, set()))
        out[chunk.entity_path] = (rows + batch.num_rows * ('sim_time' in chunk.timeline_names),
                                  names | set(batch.schema.names))
    return out


def test_node_records_meshes_and_metrics(tmp_path):
    path = str(tmp_path / 'run.rrd')
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        sim = ClothSimNode(context=context, parameter_overrides=[
            Parameter('rerun_path', value=path), Parameter('rerun_finest_every', value=5),
            Parameter('scene.boxes', value=[0.0, 0.0, 0.3, 0.2, 0.2, 0.3])])
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(sim)
        end = time.monotonic() + 10
        while sim.state.time < 30 * sim.dt - 1e-9 and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        ticks = int(round(sim.state.time / sim.dt))
        executor.shutdown()
        sim.destroy_node()          # closes the recording: flush and footer
    finally:
        rclpy.shutdown(context=context)
    assert ticks >= 30
    rows = _rows(path)
    for name in ('step_ms', 'real_time_factor', 'levels', 'max_strain', 'energy'):
        n, cols = rows[f'/metrics/{name}']
        assert n == ticks and 'Scalars:scalars' in cols
    n, cols = rows['/cloth/lod']
    assert n >= ticks and 'Mesh3D:vertex_positions' in cols
    n, cols = rows['/cloth/finest']
    # finest mesh every 5th tick (plus its topology row once), shaded, coloured both sides
    assert abs(n - (ticks + 4) // 5) <= 1
    assert {'Mesh3D:vertex_normals', 'Mesh3D:vertex_colors', 'Mesh3D:face_rendering'} <= cols
    # the scene: the ground and the box, once at start
    for entity, archetype in (('/scene/ground', 'Boxes3D'), ('/scene/boxes', 'Boxes3D'),
                              ('/scene/spheres', 'Ellipsoids3D')):
        n, cols = rows[entity]
        assert n == 1 and f'{archetype}:half_sizes' in cols
    assert '/cloth/pins' in rows
    # the levels series says 4 levels were simulated at every tick
    levels = [c for c in RrdReader(path).stream() if c.entity_path == '/metrics/levels']
    values = np.concatenate([np.concatenate(c.to_record_batch().column('Scalars:scalars')
                                            .to_pylist()) for c in levels])
    assert np.all(values == 4.0)
