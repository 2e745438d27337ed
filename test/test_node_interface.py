"""
The node's ROS interface from another process.

Sim time, pause and step, QoS overrides, diagnostics, start-up errors, markers deleted on
shutdown.

One ``sim_node`` (as ``ros2 run`` starts it) serves the tests of the module; a client in
this process talks to it over DDS.
"""

import os
import random
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from hcloth_ros import params
from hcloth_ros.ros_msgs import points_from_pointcloud2
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import Marker, MarkerArray

pytestmark = pytest.mark.slow

DT = 1 / 60     # the default scene's step
EXE = os.path.join(sys.prefix, 'bin', 'sim_node')


def _seconds(stamp):
    return stamp.sec + 1e-9 * stamp.nanosec


def _ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class Client:
    """A node in this process, its executor and what it received."""

    def __init__(self, domain):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('client', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.clouds, self.clocks, self.diagnostics, self.markers = [], [], [], []
        self.scenes = []
        # reliable: the node's cloud publisher is overridden to reliable for this module
        self.node.create_subscription(PointCloud2, 'cloth/points', self.clouds.append,
                                      QoSProfile(depth=100))
        self.node.create_subscription(Clock, '/clock', self.clocks.append,
                                      QoSProfile(depth=100))
        self.node.create_subscription(DiagnosticArray, '/diagnostics',
                                      self.diagnostics.append, 10)
        self.node.create_subscription(Marker, 'cloth/lod_marker', self.markers.append, 100)
        self.node.create_subscription(
            MarkerArray, 'cloth/scene', self.scenes.append,
            QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))

    def spin_until(self, predicate, timeout=10.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end and not predicate():
            self.executor.spin_once(timeout_sec=0.02)
        return predicate()

    def call(self, srv_type, name, request, timeout=20.0):
        client = self.node.create_client(srv_type, name)
        assert client.wait_for_service(timeout_sec=timeout), name
        future = client.call_async(request)
        assert self.spin_until(future.done, timeout), f'{name} did not answer'
        self.node.destroy_client(client)
        return future.result()

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@pytest.fixture(scope='module')
def sim():
    domain = random.randint(100, 200)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1')
    proc = subprocess.Popen(
        [EXE, '--ros-args', '-p', 'real_time_factor:=0.5', '-p',
         'qos_overrides./cloth/points.publisher.reliability:=reliable'],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    client = Client(domain)
    # first start may compile the kernels
    started = client.spin_until(lambda: len(client.clouds) >= 3 or proc.poll() is not None,
                                timeout=120)
    assert started and proc.poll() is None, proc.stdout.read()
    yield proc, client
    client.close()
    if proc.poll() is None:
        proc.kill()


def test_clock_advances_by_dt_a_tick_and_stamps_the_cloud(sim):
    _, client = sim
    client.clocks.clear()
    assert client.spin_until(lambda: len(client.clocks) >= 20)
    times = np.array([_seconds(c.clock) for c in client.clocks])
    # one /clock per tick, dt apart, to the nanosecond the stamps are rounded to
    assert np.allclose(np.diff(times), DT, atol=2e-9)
    # every cloud since carries the time of a /clock message
    clock_ns = {_ns(c.clock) for c in client.clocks}
    cloud_ns = [_ns(c.header.stamp) for c in client.clouds
                if _ns(c.header.stamp) >= min(clock_ns)]
    assert len(cloud_ns) >= 10 and set(cloud_ns) <= clock_ns


def test_pause_holds_and_step_advances_one_tick_bit_exactly(sim):
    _, client = sim
    assert client.call(SetBool, 'cloth/pause', SetBool.Request(data=True)).success
    client.spin_until(lambda: False, timeout=0.5)      # what was in flight arrives
    count, last = len(client.clouds), client.clouds[-1]
    client.clocks.clear()
    client.spin_until(lambda: False, timeout=1.0)
    assert len(client.clouds) == count and client.clocks == []     # paused: nothing new
    # a step goes on from where the pause held it: one tick later, the same points moved
    reply = client.call(Trigger, 'cloth/step', Trigger.Request())
    assert reply.success and client.spin_until(lambda: len(client.clouds) == count + 1)
    held = client.clouds[-1]
    assert abs(_ns(held.header.stamp) - _ns(last.header.stamp) - round(DT * 1e9)) <= 1
    assert [_ns(c.clock) for c in client.clocks] == [_ns(held.header.stamp)]
    count += 1
    reply = client.call(Trigger, 'cloth/reset', Trigger.Request())
    assert reply.success and 'paused' in reply.message
    assert client.spin_until(lambda: _ns(client.clocks[-1].clock) == 0)   # time back to 0
    model, solver, state, control = params.build_all(params.resolve())
    for tick in range(1, 6):
        reply = client.call(Trigger, 'cloth/step', Trigger.Request())
        assert reply.success, reply.message
        assert client.spin_until(lambda: len(client.clouds) == count + tick)
        cloud = client.clouds[-1]
        assert _seconds(cloud.header.stamp) == pytest.approx(tick * DT, abs=2e-9)
        # the same steps in this process: the node's cloud is the engine's state
        assert solver.step(state, control, DT).ok
        want = state.points_by_id_f32(model, model.level_count - 1)
        assert np.array_equal(points_from_pointcloud2(cloud), want)
    assert last.header.stamp != cloud.header.stamp
    reply = client.call(SetBool, 'cloth/pause', SetBool.Request(data=False))
    assert reply.success and reply.message == 'running'
    refused = client.call(Trigger, 'cloth/step', Trigger.Request())
    assert not refused.success and 'not paused' in refused.message
    assert client.spin_until(lambda: len(client.clouds) >= count + 10)


def test_qos_override_makes_the_cloud_reliable(sim):
    _, client = sim
    infos = client.node.get_publishers_info_by_topic('/cloth/points')
    assert [i.qos_profile.reliability for i in infos] == [ReliabilityPolicy.RELIABLE]


def test_diagnostics_arrive_with_the_tick_statistics(sim):
    _, client = sim
    client.diagnostics.clear()      # a full second of running after the pause test
    assert client.spin_until(lambda: len(client.diagnostics) >= 2, timeout=5.0)
    status = client.diagnostics[-1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert status.name == 'hcloth_sim: cloth simulation'
    assert values['levels_simulated'] == '4' and values['paused'] == 'false'
    assert 0.0 < float(values['tick_p50_ms']) <= float(values['tick_p99_ms'])
    # running at half real time: the last second's factor is near 0.5
    assert float(values['real_time_factor']) == pytest.approx(0.5, abs=0.15)


def test_shutdown_deletes_the_markers(sim):
    proc, client = sim
    client.markers.clear()
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=10) == 0
    assert client.spin_until(lambda: any(m.action == Marker.DELETE for m in client.markers))
    assert client.spin_until(
        lambda: client.scenes and client.scenes[-1].markers[0].action == Marker.DELETEALL)


@pytest.mark.parametrize('args, names', [
    (['-p', 'cloth.width:=1e5'], ['cloth.width = 100000.0', '0.01 .. 100']),
    (['-p', 'solver.name:=multigird'], ['solver.name', 'one of multigrid']),
    (['-p', 'scene.boxes:=[0.0,0.0,0.5,0.1,0.1]'], ['scene.boxes', '6 per item']),
    (['-p', 'lod_level:=abc'], ['lod_level', 'an integer']),
    (['--params-file', '/nonexistent/scene.yaml'], ['/nonexistent/scene.yaml',
                                                    'No such file']),
    # rcl refuses a list of mixed integers and decimals without naming it
    (['-p', 'scene.boxes:=[0,0,0.5,0.1,0.1,0.1]'], ['scene.boxes', 'as decimals']),
    (['-p', 'rerun_path:=/nonexistent/run.rrd'], ['rerun_path', '/nonexistent/run.rrd']),
    (['-p', 'scene.moving_obstacles:=["finger cube 0.1"]'], ['scene.moving_obstacles']),
    (['-p', 'use_sim_time:=1'], ['use_sim_time', 'BOOL']),    # rclpy's own parameter
    # inside every range, but 3.7e11 points: refused before anything is allocated
    (['-p', 'cloth.resolution:=[1025,1025]', '-p', 'cloth.levels:=10'],
     ['366,505,621,514 points', 'memory_budget_mb 8000']),
])
def test_a_bad_start_up_value_is_one_line_and_exit_code_2(args, names):
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(100, 200)))
    done = subprocess.run([EXE, '--ros-args'] + args, env=env, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2
    lines = (done.stdout + done.stderr).strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('[ERROR] [hcloth_sim]: '), lines
    assert all(name in lines[0] for name in names), lines[0]


def test_an_integer_for_a_float_starts(tmp_path):
    # `cloth.width: 1` in YAML is an integer; rclpy alone refuses it for a float
    path = tmp_path / 'scene.yaml'
    path.write_text('/**:\n  ros__parameters:\n    cloth:\n      width: 1\n'
                    '    scene:\n      boxes: [0, 0, -1, 1, 1, 1]\n')
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(100, 200)))
    proc = subprocess.Popen([EXE, '--ros-args', '--params-file', str(path)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = ''
        end = time.monotonic() + 120
        while 'multigrid cloth' not in line and time.monotonic() < end:
            line = proc.stdout.readline()
            assert line or proc.poll() is None, 'the node ended'
        assert 'multigrid cloth' in line
    finally:
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0


def test_bag_holds_the_node_topics_in_sim_time(tmp_path):
    from mcap_ros2.reader import read_ros2_messages
    bag = tmp_path / 'run.mcap'
    domain = random.randint(100, 200)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1')
    proc = subprocess.Popen([EXE, '--ros-args', '-p', f'bag_path:={bag}'], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    client = Client(domain)
    try:
        # no subscriber needed: the bag wants the cloud and every level
        assert client.spin_until(lambda: len(client.clocks) >= 40, timeout=120)
        reply = client.call(Trigger, 'cloth/reset', Trigger.Request())
        assert reply.success
        client.clocks.clear()
        assert client.spin_until(lambda: len(client.clocks) >= 20)
    finally:
        client.close()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0, proc.stdout.read()
    read = {}
    for m in read_ros2_messages(str(bag)):
        read.setdefault(m.channel.topic, []).append(m)
    assert set(read) == {'/cloth/points', '/cloth/lod_marker', '/cloth/scene', '/clock'}
    clocks = read['/clock']
    log_times = np.array([m.log_time_ns for m in clocks])
    sim_times = np.array([_seconds(m.ros_msg.clock) for m in clocks])
    # one /clock a tick, and one at the reset (time 0, at the bag time of the tick before
    # it); after it the stamps start again while the bag's log time goes on, so `ros2 bag
    # play` replays the run in order
    steps = np.diff(log_times)
    reset = int(np.argmin(np.diff(sim_times))) + 1
    assert sim_times[reset] == 0.0 and sim_times[reset - 1] > 0.5 and steps[reset - 1] == 0
    assert np.allclose(np.delete(steps, reset - 1) * 1e-9, DT, atol=2e-9)
    clouds = read['/cloth/points']
    assert len(clouds) >= len(clocks) - 2      # the last tick's send may not have run
    for m in clouds:
        assert m.log_time_ns in set(log_times.tolist())
    last = clouds[-1]
    pts = np.frombuffer(bytes(last.ros_msg.data), dtype='<f4').reshape(-1, 3)
    assert pts.shape == (65 * 65, 3) and np.all(np.isfinite(pts))
    # the default scene: what was drawn before cleared, then the ground alone
    scene = read['/cloth/scene'][0].ros_msg.markers
    assert [(m.action, m.type) for m in scene[1:]] == [(Marker.ADD, Marker.CUBE)]
    assert scene[0].action == Marker.DELETEALL
