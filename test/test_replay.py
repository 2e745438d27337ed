"""Exact replay: a recording holds every command with its step; hcloth_replay re-simulates it."""

import json
import pathlib
import shutil
import time

from geometry_msgs.msg import PoseStamped
from hcloth_ros import params, replay, simulation
from hcloth_ros.core.poses import pose_fields
from hcloth_ros.node import ClothSimNode
from hcloth_ros.recorder import Recorder
from hcloth_ros.simulation import Simulation
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

QUARTER = pose_fields(np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
                      [0, 0, 0])     # a quarter turn about z


def _pose(xyz, quat=(0.0, 0.0, 0.0, 1.0)):
    msg = PoseStamped()
    msg.header.frame_id = 'world'
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, xyz)
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = map(float, quat)
    return msg


def _kinds(path):
    _, commands = replay.read_commands(path)
    return {c[0] for step in commands.values() for c in step}


def test_a_node_run_with_every_kind_of_command_replays_bit_for_bit(tmp_path):
    """
    Grippers, a moving obstacle, parameters and a reset sent at whatever ticks they land on.

    The replay applies them before the recorded steps and every one of the run's finest
    meshes comes back exactly (0 m, float32 as recorded). With the structural stiffness
    doubled the same commands move the cloth elsewhere: the comparison can fail.
    """
    path = str(tmp_path / 'run.rrd')
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        sim = ClothSimNode(context=context, parameter_overrides=[
            Parameter('rerun_path', value=path), Parameter('rerun_finest_every', value=1),
            Parameter('scene.moving_obstacles', value=['ball sphere 0.1 0.5'])])
        probe = rclpy.create_node('probe', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(sim)
        executor.add_node(probe)

        def spin_for(ticks):
            end, stop = time.monotonic() + 20, sim.stats.count + ticks
            while sim.stats.count < stop and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)

        pose = probe.create_publisher(PoseStamped, 'cloth/grippers/left/pose', 10)
        close = probe.create_publisher(Bool, 'cloth/grippers/left/close', 10)
        ball = probe.create_publisher(PoseStamped, 'cloth/obstacles/ball/pose', 10)
        spin_for(5)
        corner = sim.state.points_by_id(sim.model, 3)[80]
        pose.publish(_pose(corner))
        close.publish(Bool(data=True))
        spin_for(5)
        s = np.sqrt(0.5)
        for z in np.linspace(0.0, 0.2, 10):
            pose.publish(_pose(corner + [0.0, 0.0, z], (0.0, 0.0, s * z, 1.0)))
            ball.publish(_pose((0.0, 0.2 - z, 0.6)))
            spin_for(2)
        sim.set_parameters([Parameter('pinned_points', value=[0])])
        sim.set_parameters([Parameter('solver.dt', value=0.01)])
        sim.set_parameters([Parameter('scene.spheres', value=[0.0, 0.3, 0.5, 0.1])])
        spin_for(10)
        close.publish(Bool(data=False))
        spin_for(5)
        client = probe.create_client(Trigger, 'cloth/reset')
        future = client.call_async(Trigger.Request())
        end = time.monotonic() + 10
        while not future.done() and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        assert future.result().success
        spin_for(10)
        ticks = sim.stats.count
        executor.shutdown()
        sim.destroy_node()      # finishes the recording
        probe.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert _kinds(path) >= {'grasp', 'move', 'release', 'body', 'pins', 'set', 'scene',
                            'reset'}
    outcome = replay.compare(path, progress=False)
    assert outcome['meshes'] == outcome['steps'] == ticks
    assert outcome['largest'] == 0.0
    stiffer = replay.compare(path, {'cloth.k_struct': 2000.0}, progress=False)
    assert stiffer['largest'] > 1e-3


def test_levels_commands_replay_and_a_lost_command_shows(tmp_path):
    """
    The engine with the recorder, as the node drives them: levels shed and restored.

    A recording missing one gripper move differs from its replay from that step on.
    """
    path = str(tmp_path / 'levels.rrd')
    values = params.resolve({'pinned_points': [0, 8]})
    sim = Simulation.build(values)
    recorder = Recorder(sim.model, path=path, finest_every=3)
    recorder.log_start(sim.start_record(), 1)
    reports = []
    for step in range(60):
        if step == 10:
            sim.apply(['levels', 1])
        if step == 25:
            sim.apply(['levels', 3])
        if step == 30:
            corner = sim.state.points_by_id(sim.model, 3)[80]
            sim.apply(['grasp', 'g', [80], *pose_fields(np.eye(3), corner)])
        if step > 30:
            to = corner + np.array([0.0, -0.01, 0.01]) * (step - 30)
            sim.apply(['move', 'g', QUARTER[0], to.tolist()])
        commands = sim.take_commands()
        report = sim.advance()
        reports.append(report.ok)
        finest = sim.solver.levels()[-1]
        recorder.log_step(sim.state, finest, 1, report, 0.001, sim.dt, commands=commands)
    recorder.close()
    assert all(reports)
    outcome = replay.compare(path, progress=False)
    assert outcome['largest'] == 0.0 and outcome['meshes'] == 20
    # drop the move before step 45 from what the replay applies
    start, commands = replay.read_commands(path)
    del commands[45]
    lost = replay.Replay(start, commands)
    lost.advance_to(48)
    recorded = dict(replay.recorded_meshes(path))[48]
    assert np.abs(lost.finest_points() - recorded).max() > 1e-6


def test_unknown_commands_are_refused():
    sim = Simulation.build(params.resolve())
    with pytest.raises(ValueError, match='unknown command'):
        sim.apply(['teleport', 1.0])
    assert sim.take_commands() == []


def test_a_recording_without_commands_is_refused_in_one_line(tmp_path, capsys):
    path = str(tmp_path / 'old.rrd')
    sim = Simulation.build(params.resolve())
    recorder = Recorder(sim.model, path=path)
    recorder.log_step(sim.state, 3, 1, sim.advance(), 0.001, sim.dt)
    recorder.close()
    assert replay.main([path]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'no replay/start' in err[0]
    assert replay.main([path, '--set', 'cloth.k_struct=-1']) == 2
    assert 'out of range' in capsys.readouterr().err


def test_the_source_digest_follows_the_engine_sources_and_only_them(tmp_path):
    """
    A copy of the package digests as the installed one.

    An edit to a kernel or a new core file changes the digest, an edit to a benchmark
    (not run by a replay) does not.
    """
    package = pathlib.Path(simulation.__file__).parent
    copy = tmp_path / 'hcloth_ros'
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns('__pycache__'))
    same = simulation.source_digest(copy)
    assert same == simulation.engine()['source'] and len(same) == 12
    kernel = copy / 'core' / 'kernels' / 'self_contact.py'
    text = kernel.read_text()
    kernel.write_text(text.replace('RING = 2', 'RING = 3'))
    assert simulation.source_digest(copy) != same
    kernel.write_text(text)
    assert simulation.source_digest(copy) == same
    (copy / 'bench' / 'report.py').write_text('# edited\n')
    assert simulation.source_digest(copy) == same
    (copy / 'core' / 'extra.py').write_text('\n')
    assert simulation.source_digest(copy) != same


def _short_recording(path, engine):
    """Record 6 steps of the default scene with ``engine`` as the start record's (None: none)."""
    sim = Simulation.build(params.resolve())
    record = sim.start_record()
    if engine is None:
        del record['engine']
    else:
        record['engine'] = engine
    recorder = Recorder(sim.model, path=path, finest_every=2)
    recorder.log_start(record, 1)
    for _ in range(6):
        commands = sim.take_commands()
        report = sim.advance()
        recorder.log_step(sim.state, sim.solver.levels()[-1], 1, report, 0.001, sim.dt,
                          commands=commands)
    recorder.close()


def test_a_replay_says_which_part_of_the_engine_changed_since_the_recording(tmp_path, capsys):
    """
    The start record keeps the engine (sources' digest, Python, numpy and numba versions).

    Replayed by the same engine: nothing said. A recording whose start says another source
    digest and numba: one line on stderr naming both, the recorded and the present values.
    One made before recordings kept it: one line saying the engine is unknown.
    """
    now = simulation.engine()
    assert set(now) == {'source', 'python', 'numpy', 'numba'}
    assert Simulation.build(params.resolve()).start_record()['engine'] == now
    cases = {'same': now, 'other': {**now, 'source': '0123456789ab', 'numba': '0.0'},
             'none': None}
    said = {}
    for name, engine in cases.items():
        path = str(tmp_path / f'{name}.rrd')
        _short_recording(path, engine)
        assert replay.main([path]) == 0     # the same motion: the same code ran it
        said[name] = [line for line in capsys.readouterr().err.splitlines()
                      if 'engine' in line]
    assert said['same'] == []
    assert len(said['other']) == 1
    assert f"source 0123456789ab -> {now['source']}" in said['other'][0]
    assert f"numba 0.0 -> {now['numba']}" in said['other'][0]
    assert 'python' not in said['other'][0] and 'numpy' not in said['other'][0]
    assert len(said['none']) == 1 and 'does not say which engine' in said['none'][0]


def test_start_record_reads_back_as_the_same_values(tmp_path):
    values = params.resolve({'cloth.origin': [-0.5, 0.0, 1.5], 'solver.dt': 1 / 60})
    record = Simulation.build(values).start_record()
    again = json.loads(json.dumps(record))
    assert again['values'] == {k: (list(v) if isinstance(v, tuple) else v)
                               for k, v in values.items()}


@pytest.mark.parametrize('solver', ['multigrid', 'hierarchical'])
def test_the_thread_count_does_not_change_the_result(solver):
    """A recording made on two threads replays on one: the same state bit for bit."""
    import numba
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip('one thread only on this machine')
    states = []
    before = numba.get_num_threads()
    try:
        for threads in (1, 2):
            numba.set_num_threads(threads)
            sim = Simulation.build(params.resolve({'solver.name': solver,
                                                   'self_contact.thickness': 0.004}))
            corner = sim.state.points_by_id(sim.model, 3)[80]
            sim.apply(['grasp', 'g', [80], *pose_fields(np.eye(3), corner)])
            for step in range(40):
                to = corner + np.array([0.0, -0.02, 0.0]) * step
                sim.apply(['move', 'g', QUARTER[0], to.tolist()])
                assert sim.advance().ok
            states.append(sim.state.q[sim.solver.levels()[-1]].copy())
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(states[0], states[1])
