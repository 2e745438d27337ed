"""
The node's units without a ROS graph: governor, grippers, publisher, parameter checks.

Made-up tick times drive the governor; grippers act on a real engine Control; the
publisher gets fake publishers that count what they are given.
"""

import threading

from builtin_interfaces.msg import Time
from hcloth_ros import params
from hcloth_ros.core import ClothBuilder, Control, State
from hcloth_ros.governor import finest_to_simulate, Governor
from hcloth_ros.grippers import GripperBank, points_within
from hcloth_ros.node_params import check_change, descriptor, NODE_PARAMS, unknown_overrides
from hcloth_ros.publishing import ClothPublisher, PublishThread
from hcloth_ros.ros_msgs import points_from_pointcloud2
from hcloth_ros.simulation import Simulation
from hcloth_ros.tick_stats import TickStats
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from visualization_msgs.msg import Marker


PERIOD = 1.0 / 60.0


def governor(**options):
    return Governor(PERIOD, top_level=4, floor=1, grace_ticks=0, **options)


def test_governor_drops_a_level_after_three_overruns_in_a_row():
    g = governor()
    assert [g.judge(2 * PERIOD) for _ in range(2)] == [None, None]
    g.judge(0.5 * PERIOD)                       # a tick that fits: the count starts again
    assert [g.judge(2 * PERIOD) for _ in range(3)] == [None, None, 'drop']
    assert g.cap == 3


def test_governor_never_drops_below_its_floor():
    g = governor()
    for _ in range(100):
        g.judge(10 * PERIOD)
    assert g.cap == g.floor == 1


def test_governor_restores_after_sixty_ticks_of_headroom():
    g = governor()
    g.cap = 2
    quick = 0.1 * PERIOD                        # 2.5x the work still fits in 80 %
    assert [g.judge(quick) for _ in range(59)] == [None] * 59
    assert g.judge(quick) == 'restore' and g.cap == 3
    # a tick with 2.5x the work over 80 % of the period is no headroom
    assert all(g.judge(0.5 * PERIOD) is None for _ in range(200)) and g.cap == 3
    for _ in range(120):
        g.judge(quick)
    assert g.cap == 4                          # and never above the top level
    assert all(g.judge(quick) is None for _ in range(100)) and g.cap == 4


def test_governor_does_not_judge_during_its_grace_ticks():
    g = Governor(PERIOD, top_level=4, grace_ticks=5)
    assert all(g.judge(10 * PERIOD) is None for _ in range(5 + 2))
    assert g.judge(10 * PERIOD) == 'drop'
    g.restart_grace()
    assert all(g.judge(10 * PERIOD) is None for _ in range(5 + 2)) and g.cap == 3


def test_governor_switched_off_judges_nothing_and_back_on_starts_afresh():
    g = governor()
    assert [g.judge(2 * PERIOD) for _ in range(3)] == [None, None, 'drop']
    assert [g.judge(2 * PERIOD) for _ in range(2)] == [None, None]
    g.set_enabled(False)
    assert g.cap == 4
    assert all(g.judge(10 * PERIOD) is None for _ in range(100)) and g.cap == 4
    g.set_enabled(True)
    # two overruns were counted before: after switching back on three in a row are needed
    assert [g.judge(2 * PERIOD) for _ in range(3)] == [None, None, 'drop']


@pytest.mark.parametrize('consumed_all,lod,cap,expected', [
    (True, 1, 4, 4), (False, 1, 4, 1), (True, 1, 2, 2), (True, 3, 2, 3), (False, 0, 4, 0)])
def test_finest_to_simulate(consumed_all, lod, cap, expected):
    assert finest_to_simulate(consumed_all, lod, cap, 4) == expected


@pytest.fixture
def cloth():
    model = ClothBuilder(resolution=(3, 3), level_count=3).finalize()
    return model, State.at_rest(model), Control(model)


def near(model, state):
    def points_near(position):
        return points_within(state.points_by_id(model, model.level_count - 1), position, 0.05)
    return points_near


def test_gripper_names_empty_repeated_or_with_a_slash_are_refused():
    bank = GripperBank(['a', '', 'a', 'b/c', 'd'])
    assert bank.names() == ['a', 'd'] and bank.refused == ['', 'a', 'b/c']


@pytest.mark.parametrize('frame,position,orientation,severity', [
    ('map', (0, 0, 1), (0, 0, 0, 1), 'warning'),
    ('world', (0, float('nan'), 1), (0, 0, 0, 1), 'error'),
    ('world', (0, 0, float('inf')), (0, 0, 0, 1), 'error'),
    ('world', (0, 0, 1), (0, 0, 0, 0), 'error'),
    ('world', (0, 0, 1), (0, float('nan'), 0, 1), 'error')])
def test_bad_poses_are_dropped_with_a_reason(frame, position, orientation, severity):
    bank = GripperBank(['left'])
    dropped = bank.set_pose('left', frame, 'world', position, orientation)
    assert dropped[0] == severity and 'left' in dropped[1]
    assert bank['left'].translation is None and not bank['left'].pose_pending


def test_close_before_any_pose_is_ignored(cloth):
    model, state, control = cloth
    bank = GripperBank(['left'])
    bank.request_close('left', True)
    log = bank.apply(Simulation(model, None, state, control, 0.01, 1).apply, near(model, state))
    assert log == [('warning', 'gripper left: close before any pose: ignored')]
    assert control.grasp_names == [] and bank['left'].close_request is None


def test_grasp_follows_the_newest_pose_and_releases(cloth):
    model, state, control = cloth
    bank = GripperBank(['left'])
    corner = state.points_by_id(model, 2)[0]
    assert bank.set_pose('left', 'world', 'world', corner, (0, 0, 0, 1)) is None
    bank.request_close('left', True)
    log = bank.apply(Simulation(model, None, state, control, 0.01, 1).apply, near(model, state))
    assert log == [('info', 'gripper left: grasped 1 points')]
    assert bank['left'].grasping and control.grasp_names == ['left']
    # a flood: only the newest pose counts at the next tick
    for z in np.linspace(0.0, 0.3, 50):
        bank.set_pose('left', 'world', 'world', corner + [0.0, 0.0, z], (0, 0, 0, 1))
    apply = Simulation(model, None, state, control, 0.01, 1).apply
    assert bank.apply(apply, near(model, state)) == []
    assert np.allclose(control._grasps['left'].translation, corner + [0.0, 0.0, 0.3])
    bank.request_close('left', False)
    bank.apply(Simulation(model, None, state, control, 0.01, 1).apply, near(model, state))
    assert not bank['left'].grasping and control.grasp_names == []


def test_a_pose_far_away_is_travelled_to_at_most_max_step_a_tick(cloth):
    """
    ``grasp_max_speed``: 0.58 m and a quarter turn away at 0.1 m a tick take six ticks.

    Each tick's frame is 0.1 m further along the straight line, turned in proportion
    (slerp), the last one exactly the pose asked; one warning says how many ticks. A pose
    within a tick's travel goes at once; a new pose while travelling is headed for from
    where the frame is.
    """
    model, state, control = cloth
    bank = GripperBank(['left'])
    corner = state.points_by_id(model, 2)[0]
    bank.set_pose('left', 'world', 'world', corner, (0, 0, 0, 1))
    bank.request_close('left', True)
    apply = Simulation(model, None, state, control, 0.01, 1).apply
    bank.apply(apply, near(model, state), 0.1)
    far = corner + [0.0, -0.58, 0.0]
    half = np.sqrt(0.5)
    bank.set_pose('left', 'world', 'world', far, (0, 0, half, half))
    logs, frames = [], []
    for _ in range(7):
        logs += bank.apply(apply, near(model, state), 0.1)
        g = control._grasps['left']
        frames.append((g.rotation.copy(), g.translation.copy()))
    assert logs == [('warning', 'gripper left: pose 0.58 m away, more than 0.1 m a tick '
                                '(grasp_max_speed): reached over 6 ticks')]
    for i, (rotation, translation) in enumerate(frames[:5]):
        np.testing.assert_allclose(translation, corner + [0.0, -0.1 * (i + 1), 0.0],
                                   atol=1e-12)
        angle = np.arctan2(rotation[1, 0], rotation[0, 0])
        assert angle == pytest.approx(np.pi / 2 * 0.1 * (i + 1) / 0.58, abs=1e-9)
    assert frames[5][1].tolist() == far.tolist() and frames[6][1].tolist() == far.tolist()
    assert not bank['left'].travelling and not bank['left'].pose_pending
    bank.set_pose('left', 'world', 'world', far + [0.05, 0.0, 0.0], (0, 0, half, half))
    assert bank.apply(apply, near(model, state), 0.1) == []
    assert control._grasps['left'].translation.tolist() == (far + [0.05, 0, 0]).tolist()
    bank.set_pose('left', 'world', 'world', corner, (0, 0, 0, 1))     # on its way back...
    assert len(bank.apply(apply, near(model, state), 0.1)) == 1
    there = control._grasps['left'].translation.copy()
    bank.set_pose('left', 'world', 'world', far, (0, 0, half, half))   # ...sent back again
    bank.apply(apply, near(model, state), 0.1)
    moved = control._grasps['left'].translation - there
    np.testing.assert_allclose(moved, 0.1 * (far - there) / np.linalg.norm(far - there),
                               atol=1e-12)


def test_an_obstacle_placed_at_once_then_travels_to_a_far_pose(cloth):
    """``obstacle_max_speed``: the first pose places the body; 0.35 m away takes 4 ticks."""
    from hcloth_ros.obstacles import ObstacleBank
    model, state, control = cloth
    bank = ObstacleBank(['ball sphere 0.05'], control.bodies, 0.5)
    apply = Simulation(model, None, state, control, 0.01, 1).apply
    bank.set_pose('ball', 'world', 'world', (2.0, 0.0, 0.0), (0, 0, 0, 1))
    assert bank.apply(apply, 0.1) == (True, [])
    assert control.bodies.pose('ball')[1].tolist() == [2.0, 0.0, 0.0]
    bank.set_pose('ball', 'world', 'world', (2.0, 0.35, 0.0), (0, 0, 0, 1))
    moved, log = bank.apply(apply, 0.1)
    assert moved and log == [('warning', 'obstacle ball: pose 0.35 m away, more than 0.1 m '
                                         'a tick (obstacle_max_speed): reached over 4 ticks')]
    ys = [control.bodies.pose('ball')[1][1]]
    for _ in range(4):
        moved, log = bank.apply(apply, 0.1)
        assert log == []
        ys.append(control.bodies.pose('ball')[1][1])
    assert ys == pytest.approx([0.1, 0.2, 0.3, 0.35, 0.35], abs=1e-12) and not moved


def test_forget_grasps_keeps_poses_and_drops_commands():
    bank = GripperBank(['left'])
    bank.set_pose('left', 'world', 'world', (0, 0, 1), (0, 0, 0, 1))
    bank.request_close('left', True)
    bank['left'].grasping = True
    bank.forget_grasps()
    g = bank['left']
    assert (g.grasping, g.close_request, g.pose_pending) == (False, None, False)
    assert np.allclose(g.translation, [0, 0, 1])


def test_points_within_a_radius_or_the_nearest():
    pts = np.array([[0.0, 0, 0], [0.02, 0, 0], [1.0, 0, 0]])
    assert points_within(pts, np.zeros(3), 0.03).tolist() == [0, 1]
    assert points_within(pts, np.array([0.8, 0, 0]), 0.03).tolist() == [2]


class FakePublisher:
    """Counts what it is given; reports a settable number of subscribers."""

    def __init__(self, subscribers=0):
        self.subscribers = subscribers
        self.published = []

    def get_subscription_count(self):
        return self.subscribers

    def publish(self, msg):
        self.published.append(msg)


def test_publisher_packs_the_cloud_only_for_subscribers_and_reuses_markers(cloth):
    model, state, _ = cloth
    clouds, markers = FakePublisher(), FakePublisher()
    out = ClothPublisher(model, 'world', clouds, markers)
    stamp = Time(sec=2, nanosec=7)
    cloud, marker = out.pack(state, 2, 1, stamp)
    assert cloud is None
    out.publish(cloud, marker)
    assert clouds.published == [] and markers.published == [marker]
    clouds.subscribers = 1
    cloud, again = out.pack(state, 2, 1, stamp)
    assert again == marker                      # the same level's marker, the same bytes
    msg = deserialize_message(again, Marker)
    assert len(msg.points) == 3 * 2 * 4 * 4     # level 1: 5 x 5 points
    assert np.allclose(points_from_pointcloud2(cloud), state.points_by_id(model, 2),
                       atol=1e-6)
    assert cloud.header.frame_id == msg.header.frame_id == 'world'
    assert cloud.header.stamp == msg.header.stamp == stamp
    assert list(out._markers) == [1]            # one marker per level, built on first use
    coarse = deserialize_message(out.pack(state, 2, 0, stamp)[1], Marker)
    assert len(coarse.points) == 3 * 2 * 2 * 2 and list(out._markers) == [1, 0]


def test_publish_thread_sends_every_tick_in_order_from_its_own_thread():
    sent, threads = [], []

    def send(cloud, marker):
        threads.append(threading.get_ident())
        sent.append((cloud, marker))

    sender = PublishThread(send)
    try:
        for tick in range(50):
            assert sender.wait(timeout=5.0)
            sender.submit(f'cloud {tick}', f'marker {tick}')
        assert sender.wait(timeout=5.0)
    finally:
        sender.close()
    assert sent == [(f'cloud {t}', f'marker {t}') for t in range(50)]
    assert set(threads) != {threading.get_ident()} and len(set(threads)) == 1
    assert sender.sent == 50 and sender.last_seconds >= 0.0


def test_publish_thread_reports_errors_goes_on_and_sends_what_is_pending_on_close():
    errors, sent, release = [], [], threading.Event()

    def send(cloud, marker):
        if cloud == 'bad':
            raise RuntimeError('middleware says no')
        release.wait(5.0)
        sent.append(cloud)

    sender = PublishThread(send, on_error=errors.append)
    assert sender.submit('bad', None)
    assert sender.wait(timeout=5.0)
    assert [str(e) for e in errors] == ['middleware says no']
    assert sender.submit('slow', None)
    assert not sender.wait(timeout=0.05)    # still sending: the tick would wait
    assert not sender.submit('meanwhile', None)     # refused, not queued over 'slow'
    release.set()
    assert sender.wait(timeout=5.0) and sent == ['slow']
    assert sender.submit('last', None)
    sender.close()
    assert sent == ['slow', 'last'] and sender.sent == 3
    assert not sender.submit('after close', None)
    assert sent == ['slow', 'last']


def test_publish_thread_outlives_a_failing_error_handler_and_any_exception():
    sent = []

    def send(cloud, marker):
        if cloud == 'interrupt':
            raise KeyboardInterrupt
        if cloud == 'bad':
            raise RuntimeError('middleware says no')
        sent.append(cloud)

    def on_error(error):
        raise RuntimeError('the logger is gone')     # e.g. after the context shut down

    sender = PublishThread(send, on_error=on_error)
    try:
        for cloud in ('bad', 'interrupt', 'good'):
            assert sender.wait(timeout=5.0)
            assert sender.submit(cloud, None)
        assert sender.wait(timeout=5.0)
    finally:
        sender.close()
    assert sent == ['good'] and sender.sent == 3


def test_runtime_changes_are_checked_against_the_model(cloth):
    model, _, _ = cloth
    assert check_change('lod_level', 2, model) is None
    assert 'out of range 0..2' in check_change('lod_level', 3, model)
    assert check_change('pinned_points', [-1], model) is None
    assert check_change('pinned_points', [0, model.point_count - 1], model) is None
    assert check_change('pinned_points', [0, 81], model) == \
        'pinned_points [81] out of range 0..80'
    assert check_change('solver.dt', 0.01, model) is None


def test_unknown_overrides_are_named_and_qos_overrides_are_not():
    known = {p.name for p in params.PARAMS + NODE_PARAMS}
    given = ['cloth.widht', 'cloth.width', 'qos_overrides./cloth/points.publisher.depth']
    assert unknown_overrides(given, known) == ['cloth.widht']


def test_descriptors_carry_ranges_of_scalars_and_lists():
    spec = {p.name: p for p in params.PARAMS + NODE_PARAMS}
    rate = descriptor(spec['real_time_factor'])
    assert rate.floating_point_range[0].to_value == 1000.0 and not rate.read_only
    boxes = descriptor(spec['scene.boxes'])
    assert boxes.floating_point_range[0].from_value == -1e4
    assert boxes.additional_constraints == 'a list of numbers, each in -10000 .. 10000, 6 per item'
    resolution = descriptor(spec['cloth.resolution'])
    assert resolution.integer_range[0].to_value == 1025
    assert resolution.additional_constraints.endswith('exactly 2')
    lod = descriptor(spec['lod_level'])
    assert lod.integer_range[0].to_value == 9 and not lod.read_only
    assert not descriptor(spec['scene.ground']).floating_point_range


def test_tick_stats_summary_from_made_up_ticks():
    stats = TickStats(window=100)
    for i in range(200):
        t = (i % 100 + 1) * 1e-4
        stats.add(step=t, pack=t, publish=t, send=t, record=0.0, tick=t, levels=3 + i % 2,
                  sim_time=i / 60)
    out = stats.summary()
    assert out['ticks'] == 200 and (out['levels_min'], out['levels_max']) == (3, 4)
    assert out['tick']['p50'] == pytest.approx(5.05, abs=0.01)    # ms, last 100 ticks
    assert out['tick']['p99'] == pytest.approx(9.9, abs=0.02)
    # the ticks at 4 levels are the odd ones: 0.2, 0.4 .. 10 ms
    top = out['top_levels']
    assert top['ticks'] == 50 and top['tick']['p50'] == pytest.approx(5.1, abs=0.01)


def test_tick_stats_keep_their_memory_and_the_last_window():
    stats = TickStats(window=100)
    for i in range(250):
        t = (i + 1) * 1e-4
        stats.add(step=t, pack=t, publish=t, send=t, record=t, tick=t, levels=4, sim_time=i)
        if i == 0:
            buffers = dict(stats.samples)
    # the rings made at the first tick are the ones in use: nothing grows
    assert all(stats.samples[name] is ring for name, ring in buffers.items())
    assert np.array_equal(stats.series('tick'), (np.arange(150, 250) + 1) * 1e-4)
    assert np.array_equal(stats.series('tick', 3), np.array([248, 249, 250]) * 1e-4)
    assert stats.recent(3)['tick']['p50'] == pytest.approx(24.9)     # ms


def test_a_tick_retries_an_overstretched_step_and_names_why():
    """
    ``solver.retry_strain`` as the node runs it: a retry is heard, with the first reason.

    The 65 x 65 cloth folded in two, its top layer thrown at 10 m/s onto the bottom one
    (``test_self_contact.py``'s scene, built from parameters, twice as fast: at 5 m/s one
    step ends at 0.44 since creases from 10 degrees are tested against edges, 0.53 before):
    at 0.5 the step is retried as two (0.57 in one step); ``set`` to 0, or without
    self-contact, nothing is retried, though the default cloth's first step from rest
    stretches past 1e-4 (a gripper's pose far away stretches as much in smaller steps).
    """
    from hcloth_ros.bench.self_contact import folded
    heard = []

    def hear(report, steps):
        heard.append((report, steps))

    def thrown(retry):
        sim = Simulation.build(params.resolve({
            'cloth.resolution': [9, 9], 'cloth.levels': 4, 'pinned_points': [-1],
            'scene.ground': False, 'self_contact.thickness': 0.005,
            'solver.retry_strain': retry}))
        for k in range(sim.model.level_count):
            sim.state.q[k] = folded(sim.state.q[k], 1.0)
            m = sim.state.qd[k].shape[1] // 2
            sim.state.qd[k][2, m + 1:] = -10.0
        return sim

    report = thrown(0.5).advance(on_retry=hear)
    assert report.ok and report.max_strain <= 0.5
    assert len(heard) == 1 and heard[0][1] == 2
    assert heard[0][0].extra['refused'].startswith('strain ')
    sim = thrown(0.5)
    sim.apply(['set', 'solver.retry_strain', 0.0])
    report = sim.advance(on_retry=hear)
    assert report.ok and report.max_strain > 0.5 and sim.solver.retry_strain is None
    sim.apply(['set', 'solver.retry_strain', 0.4])
    assert sim.solver.retry_strain == 0.4
    report = Simulation.build(params.resolve({'solver.retry_strain': 1e-4})).advance(
        on_retry=hear)
    assert report.ok and report.max_strain > 1e-4 and len(heard) == 1


def test_a_tick_of_substeps_reaches_the_poses_asked_evenly_and_a_stopped_tick_keeps_them():
    """
    ``solver.substeps`` 4: the poses set before a tick are reached at its end, evenly.

    A gripper pose and a body pose move a quarter of the way a step (not all of it in the
    first step, then rest: the README's known limit until 2026-11-29). A tick stopped by
    a refused step leaves the poses asked as they were asked, from where the last
    committed step left them.
    """
    from hcloth_ros.core.kernels.bodies import T_END, T_START
    from hcloth_ros.core.solvers import StepReport

    def run(refuse_after):
        sim = Simulation.build(params.resolve({'cloth.resolution': [9, 9], 'cloth.levels': 2,
                                               'pinned_points': [-1],
                                               'solver.substeps': 4}))
        sim.control.bodies.add('ball', 'sphere', [0.05])
        sim.apply(['body', 'ball', np.eye(3).tolist(), [3.0, 0.0, 0.0]])
        sim.apply(['grasp', 'g', [0], np.eye(3).tolist(), [0.0, 0.0, 0.0]])
        sim.advance()
        sim.apply(['move', 'g', np.eye(3).tolist(), [0.0, 0.0, 0.08]])
        sim.apply(['body', 'ball', np.eye(3).tolist(), [3.0, 0.4, 0.0]])
        asked, step = [], sim.solver.step

        def recording_step(state, control, dt):
            if len(asked) >= refuse_after:
                return StepReport(False, 'refused by the test')
            k = sim.solver.levels()[-1]
            ball = control.bodies.packed()[0]
            asked.append((control.holds(k).drive_target[2, 0] - state.q[k][2, 0, 0],
                          ball[T_END + 1] - ball[T_START + 1]))
            return step(state, control, dt)
        sim.solver.step = recording_step
        return sim, asked, sim.advance()

    sim, asked, report = run(99)
    assert report.ok and len(asked) == 4
    np.testing.assert_allclose(asked, [[0.02, 0.1]] * 4, atol=1e-12)   # 2 and 10 cm a step
    (_, start), (_, end) = sim.control.bodies.plan()['ball']
    assert start.tolist() == end.tolist() == [3.0, 0.4, 0.0]
    sim, asked, report = run(1)
    assert not report.ok and len(asked) == 1
    (_, start), (_, end) = sim.control.plan().grasps['g']
    assert start.tolist() == pytest.approx([0.0, 0.0, 0.02], abs=1e-15)
    assert end.tolist() == [0.0, 0.0, 0.08]


def test_a_step_taken_whole_after_its_retries_is_logged_with_both_strains():
    """``_report_retry`` for n = 1 (core.recovery took the whole step after all)."""
    import types
    from hcloth_ros.core.solvers import StepReport
    from hcloth_ros.node import ClothSimNode
    said = []
    logger = types.SimpleNamespace(warning=lambda text, **_: said.append(('warning', text)),
                                   error=lambda text, **_: said.append(('error', text)))
    node = types.SimpleNamespace(sim=types.SimpleNamespace(dt=1 / 60),
                                 get_logger=lambda: logger)
    report = StepReport(True, max_strain=0.603,
                        extra={'refused': 'strain 0.603 > retry_strain 0.5 on level 1 '
                                          '(from 0.0623)', 'smaller_strain': 1.358})
    ClothSimNode._report_retry(node, report, 1)
    assert len(said) == 1 and said[0][0] == 'warning'
    assert 'strain 0.603 > retry_strain 0.5' in said[0][1]
    assert '(1.36)' in said[0][1] and 'taken whole after all (0.603)' in said[0][1]
