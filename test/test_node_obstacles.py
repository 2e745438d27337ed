"""The node's obstacles: moving ones on pose topics, runtime static ones, the scene markers."""

import time

from geometry_msgs.msg import PoseStamped
from hcloth_ros.node import ClothSimNode
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from visualization_msgs.msg import Marker, MarkerArray

MARGIN = 0.002


@pytest.fixture
def start_node():
    """Start a node with parameter overrides and a probe node; tear both down after."""
    made = []

    def start(**overrides):
        context = rclpy.Context()
        rclpy.init(context=context)
        sim = ClothSimNode(context=context, parameter_overrides=[
            Parameter(name, value=value) for name, value in overrides.items()])
        probe = rclpy.create_node('probe', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(sim)
        executor.add_node(probe)
        made.append((context, executor, sim, probe))

        def spin_until(predicate, timeout=20.0, each=None):
            end = time.monotonic() + timeout
            while time.monotonic() < end and not predicate():
                if each:
                    each()
                executor.spin_once(timeout_sec=0.01)
            return predicate()
        return sim, probe, spin_until
    yield start
    for context, executor, sim, probe in made:
        executor.shutdown()
        sim.destroy_node()
        probe.destroy_node()
        rclpy.shutdown(context=context)


def _pose(xyz, frame='world'):
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, xyz)
    msg.pose.orientation.w = 1.0
    return msg


def test_a_ball_on_its_pose_topic_lifts_the_cloth_and_bad_poses_are_dropped(start_node):
    """The cloth falls onto a ball that rises at 1 m/s and rides on it, never inside it."""
    sim, probe, spin_until = start_node(**{
        'cloth.width': 0.4, 'cloth.height': 0.4, 'cloth.levels': 3,
        'cloth.origin': [-0.2, -0.2, 0.4], 'pinned_points': [-1], 'scene.ground': False,
        'scene.moving_obstacles': ['ball sphere 0.15 0.5']})
    assert sim.obstacles.names() == ['ball']
    poses = probe.create_publisher(PoseStamped, 'cloth/obstacles/ball/pose', 10)
    # bad poses first: a wrong frame and a non-finite position leave the ball unplaced
    poses.publish(_pose((0, 0, 0), frame='map'))
    poses.publish(_pose((0, 0, np.nan)))
    spin_until(lambda: sim.state.time > 0.1)
    assert sim.control.bodies.pose('ball') is None

    closest = []

    def rise():     # where the ball is at the end of the next tick; how near the cloth is
        pose = sim.control.bodies.pose('ball')
        if pose is not None:
            points = sim.state.points(sim.solver.levels()[-1])
            closest.append(np.linalg.norm(points - pose[1], axis=1).min())
        poses.publish(_pose((0.0, 0.0, sim.state.time + sim.sim.dt)))
    assert spin_until(lambda: sim.state.time >= 1.0, each=rise)
    # checked between ticks too: the ball a pose ahead can be nearer than the margin to the
    # cloth the last tick left, never inside its radius
    assert min(closest) > 0.15 - 1e-9
    rotation, centre = sim.control.bodies.pose('ball')
    finest = sim.solver.levels()[-1]
    points = sim.state.points(finest)
    assert np.linalg.norm(points - centre, axis=1).min() >= 0.15 + MARGIN - 1e-9
    top = points[np.argmax(points[:, 2])]
    # the cloth's highest point rests on the ball's top (within a tick of its rise)
    assert top[2] == pytest.approx(centre[2] + 0.15 + MARGIN, abs=0.02)
    assert np.hypot(top[0], top[1]) < 0.05


def _scene(probe, spin_until):
    """Subscribe late (transient local) and return the scene MarkerArray received."""
    got = []
    probe.create_subscription(MarkerArray, 'cloth/scene', got.append, QoSProfile(
        depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    assert spin_until(lambda: got)
    return got[-1]


def test_scene_markers_reach_a_late_viewer_and_follow_changes(start_node):
    sim, probe, spin_until = start_node(**{
        'cloth.levels': 2, 'scene.moving_obstacles': ['finger capsule 0.01 0.04 0.9']})
    spin_until(lambda: sim.state.time > 0.2)
    markers = _scene(probe, spin_until).markers
    assert markers[0].action == Marker.DELETEALL
    ground = [m for m in markers[1:] if m.type == Marker.CUBE]
    assert len(markers) == 2 and ground[0].scale.z == pytest.approx(0.001)
    # a box added at runtime: in the solver's scene and drawn at its size
    assert sim.set_parameters([Parameter('scene.boxes', value=[0.0, 1.0, 0.5, 0.2, 0.3, 0.1])])[
        0].successful
    assert sim.model.scene.boxes.tolist() == [[0.0, 1.0, 0.5, 0.2, 0.3, 0.1]]
    markers = _scene(probe, spin_until).markers
    box = [m for m in markers if m.type == Marker.CUBE and m.scale.x == pytest.approx(0.4)]
    assert len(box) == 1 and (box[0].scale.y, box[0].scale.z) == pytest.approx((0.6, 0.2))
    # a malformed box is refused with the reason and changes nothing
    bad = sim.set_parameters([Parameter('scene.boxes', value=[0.0, 1.0, 0.5, 0.2, 0.3])])[0]
    assert not bad.successful and '6 per item' in bad.reason
    bad = sim.set_parameters([Parameter('scene.boxes', value=[0.0, 1.0, 0.5, 0.2, 0.3, -1.0])])[0]
    assert not bad.successful and 'positive' in bad.reason
    assert sim.model.scene.boxes.tolist() == [[0.0, 1.0, 0.5, 0.2, 0.3, 0.1]]
    # the finger, once placed, is a cylinder and two caps
    pub = probe.create_publisher(PoseStamped, 'cloth/obstacles/finger/pose', 10)
    pub.publish(_pose((0.3, 0.0, 2.0)))
    assert spin_until(lambda: sim.control.bodies.pose('finger') is not None)
    markers = _scene(probe, spin_until).markers
    kinds = sorted(m.type for m in markers if m.pose.position.x == pytest.approx(0.3))
    assert kinds == [Marker.SPHERE, Marker.SPHERE, Marker.CYLINDER]


def test_a_box_set_inside_the_hanging_cloth_pushes_it_out(start_node):
    """ros2 param set of a box across the hanging cloth: out within 1 s, never frozen."""
    sim, _, spin_until = start_node(**{'cloth.levels': 3})
    spin_until(lambda: sim.state.time > 1.5)
    box = np.array([0.0, 0.0, 1.0, 0.3, 0.3, 0.15])
    finest = sim.solver.levels()[-1]

    def inside():
        points = sim.state.points(sim.solver.levels()[-1])
        return int(np.all(np.abs(points - box[:3]) < box[3:], axis=1).sum())
    assert sim.set_parameters([Parameter('scene.boxes', value=box.tolist())])[0].successful
    assert inside() > 20
    t0 = sim.state.time
    assert spin_until(lambda: inside() == 0 or sim.state.time > t0 + 1.0)
    assert inside() == 0 and sim.state.time <= t0 + 1.0
    assert sim.solver.levels()[-1] == finest
