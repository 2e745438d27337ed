"""Recording to Rerun: the node writes an .rrd that reads back with the right content."""

import os
import time
import types

from hcloth_ros import params, recorder
from hcloth_ros.core.control import PINNED
from hcloth_ros.node import ClothSimNode
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rerun.chunk import RrdReader

DT = 1 / 60
FINEST, LOD = 2, 1      # the test scene: 33 x 33 finest, 17 x 17 LOD


def _rows(path):
    """Map entity path -> (rows on the sim_time timeline, column names)."""
    out = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        rows, names = out.get(chunk.entity_path, (0, set()))
        out[chunk.entity_path] = (rows + batch.num_rows * ('sim_time' in chunk.timeline_names),
                                  names | set(batch.schema.names))
    return out


def _logged(path, entity, component):
    """Return ``{step: value}`` of the rows where ``entity`` logged ``component``."""
    out = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path != entity or component not in batch.schema.names:
            continue
        for step, value in zip(batch.column('step').to_pylist(),
                               batch.column(component).to_pylist()):
            if value is not None:
                out[step] = value
    return out


def _latest_at(logged, step):
    """Return what a latest-at query at ``step`` finds (as the viewer does): step, value."""
    at = max(s for s in logged if s <= step)
    return at, logged[at]


def _series(path, name):
    """Return a metric's ``(steps, values)`` in step order."""
    logged = _logged(path, f'/metrics/{name}', 'Scalars:scalars')
    steps = sorted(logged)
    return steps, np.array([logged[s][0] for s in steps])


def _scene():
    """Build the default scene at 3 levels: model, solver, state and control."""
    values = params.resolve({**params.load_file(params.config_path('hanging.yaml')),
                             'cloth.levels': FINEST + 1})
    model, solver, state, control = params.build_all(values)
    solver.set_finest_level(FINEST, state, control)
    return model, solver, state, control


def _record(path, steps, finest_every=1, walls=None, levels=None, before_step=None):
    """
    Step the test scene ``steps`` times, logging each as the node does; return the model.

    ``walls``: the ``wall_seconds`` passed in per step (default 4 ms); ``levels``: the finest
    level per step (default FINEST); ``before_step(i)`` runs before step i's log.
    """
    model, solver, state, control = _scene()
    rec = recorder.Recorder(model, path=path, finest_every=finest_every)
    rec.log_obstacles(model.scene, state.time)
    for i in range(steps):
        report = solver.step(state, control, DT)
        finest = FINEST if levels is None else levels[i]
        kind = control.holds(finest).kind.ravel()
        pins = state.points(finest)[kind == PINNED]
        if before_step is not None:
            before_step(i)
        rec.log_step(state, finest, min(LOD, finest), report,
                     0.004 if walls is None else walls[i], DT, {'pins': pins})
    rec.close()
    return model


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
        while sim.state.time < 30 * sim.sim.dt - 1e-9 and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        ticks = int(round(sim.state.time / sim.sim.dt))
        executor.shutdown()
        sim.destroy_node()          # closes the recording: flush and footer
    finally:
        rclpy.shutdown(context=context)
    assert ticks >= 30
    rows = _rows(path)
    for name in ('step_ms', 'headroom', 'levels', 'max_strain', 'energy'):
        n, cols = rows[f'/metrics/{name}']
        assert n == ticks and 'Scalars:scalars' in cols
    # the first tick has no interval since a previous one: no real-time factor
    n, cols = rows['/metrics/real_time_factor']
    assert n == ticks - 1 and 'Scalars:scalars' in cols
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


def test_what_a_level_fixes_is_logged_once_and_found_by_latest_at(tmp_path):
    path = str(tmp_path / 'run.rrd')
    model = _record(path, 40, finest_every=5)
    fixed = ('Mesh3D:triangle_indices', 'Mesh3D:vertex_colors', 'Mesh3D:face_rendering',
             'Mesh3D:albedo_factor')
    for component in fixed:
        assert list(_logged(path, '/cloth/finest', component)) == [0]
    for component in ('Mesh3D:triangle_indices', 'Mesh3D:albedo_factor'):
        assert list(_logged(path, '/cloth/lod', component)) == [0]
    # what changes, at every step it is logged: the finest every 5th, the LOD every one
    for component in ('Mesh3D:vertex_positions', 'Mesh3D:vertex_normals'):
        assert sorted(_logged(path, '/cloth/finest', component)) == list(range(0, 40, 5))
    assert sorted(_logged(path, '/cloth/lod', 'Mesh3D:vertex_positions')) == list(range(40))
    # the pins hold still: logged once
    assert list(_logged(path, '/cloth/pins', 'Points3D:positions')) == [0]
    # the viewer at the last step draws the finest mesh of step 35 with step 0's triangles
    # and colours: 33 x 33 vertices, 2 x 32 x 32 triangles
    at, positions = _latest_at(_logged(path, '/cloth/finest', 'Mesh3D:vertex_positions'), 39)
    assert at == 35 and len(positions) == 33 * 33
    _, triangles = _latest_at(_logged(path, '/cloth/finest', 'Mesh3D:triangle_indices'), 39)
    assert len(triangles) == 2 * 32 * 32 and max(max(t) for t in triangles) == 33 * 33 - 1
    assert np.array_equal(triangles, model.grid_triangles(FINEST))
    _, colours = _latest_at(_logged(path, '/cloth/finest', 'Mesh3D:vertex_colors'), 39)
    assert len(colours) == 33 * 33
    _, normals = _latest_at(_logged(path, '/cloth/finest', 'Mesh3D:vertex_normals'), 39)
    lengths = np.linalg.norm(np.asarray(normals), axis=1)
    assert len(normals) == 33 * 33 and np.all(np.abs(lengths - 1) < 0.02)


def test_a_new_level_logs_its_topology_on_the_timeline(tmp_path):
    # the governor drops the finest level at step 10: the entity shows level 1 from then
    path = str(tmp_path / 'run.rrd')
    _record(path, 20, levels=[FINEST] * 10 + [FINEST - 1] * 10)
    triangles = _logged(path, '/cloth/finest', 'Mesh3D:triangle_indices')
    assert sorted(triangles) == [0, 10]
    assert len(_latest_at(triangles, 9)[1]) == 2 * 32 * 32     # earlier steps keep level 2's
    assert len(_latest_at(triangles, 19)[1]) == 2 * 16 * 16


@pytest.mark.parametrize('finest_every', [1, 5])
def test_a_step_grows_the_file_by_little_more_than_what_changes(tmp_path, finest_every):
    sizes = []
    for steps in (30, 60):
        path = str(tmp_path / f'{steps}.rrd')
        _record(path, steps, finest_every=finest_every)
        sizes.append(os.path.getsize(path))
    per_step = (sizes[1] - sizes[0]) / 30
    # must change: float32 positions and normals of the finest mesh when it is logged,
    # positions of the LOD mesh; everything else (topology, metrics, rows) within 10 %
    changing = 12 * (2 * 33 * 33 / finest_every + 17 * 17)
    assert per_step < 1.1 * changing, (per_step, changing)


def test_headroom_is_simulated_over_compute_seconds(tmp_path):
    path = str(tmp_path / 'run.rrd')
    _record(path, 4, walls=[0.004, 0.008, 0.0125, 0.05])
    steps, values = _series(path, 'headroom')
    assert steps == [0, 1, 2, 3]
    assert np.allclose(values, [25 / 6, 25 / 12, 4 / 3, 1 / 3], rtol=1e-12)


def test_real_time_factor_is_simulated_over_wall_seconds_between_calls(tmp_path, monkeypatch):
    clock = [100.0]
    monkeypatch.setattr(recorder, 'time', types.SimpleNamespace(monotonic=lambda: clock[0]))
    calls = [100.0, 100.02, 100.0325, 100.0825, 100.0825 + 2 * DT]

    def tick(i):
        clock[0] = calls[i]

    path = str(tmp_path / 'run.rrd')
    _record(path, 5, before_step=tick)
    steps, values = _series(path, 'real_time_factor')
    # nothing at the first call; then DT over 20 ms, 12.5 ms, 50 ms and 2 DT
    assert steps == [1, 2, 3, 4]
    assert np.allclose(values, [5 / 6, 4 / 3, 1 / 3, 1 / 2], rtol=1e-9)
    # the headroom of the same steps: DT over the 4 ms passed in, whatever the wall clock
    assert np.allclose(_series(path, 'headroom')[1], 25 / 6, rtol=1e-12)


def test_a_ticks_largest_strain_and_time_are_recorded_not_its_last_steps(tmp_path):
    """
    ``max_strain`` and ``step_ms`` of a tick of several steps (a retry, substeps).

    Recorded: the largest strain after any of its steps and all of their time; for a tick
    whose last step was refused, the strain that got it refused if larger (a runaway).
    """
    from hcloth_ros.core.solvers import merged, StepReport
    path = str(tmp_path / 'tick.rrd')
    model, solver, state, control = _scene()
    rec = recorder.Recorder(model, path=path)
    ticks = [merged([StepReport(True, max_strain=0.36, seconds=0.002),
                     StepReport(True, max_strain=0.22, seconds=0.003)]),
             merged([StepReport(True, max_strain=0.12, seconds=0.001),
                     StepReport(False, 'runaway strain 11.5', max_strain=11.5,
                                seconds=0.004)])]
    for report in ticks:
        state.time += DT
        rec.log_step(state, FINEST, LOD, report, 0.01, DT)
    rec.close()
    assert ticks[0].max_strain == 0.22 and ticks[0].peak_strain == 0.36
    np.testing.assert_allclose(_series(path, 'max_strain')[1], [0.36, 11.5])
    np.testing.assert_allclose(_series(path, 'step_ms')[1], [5.0, 5.0])
