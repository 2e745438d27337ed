"""``sim_node``: the cloth simulation as a ROS 2 node (default name ``hcloth_sim``).

Steps the engine on a timer at ``rate_hz`` and after every tick publishes

* ``cloth/points`` (``sensor_msgs/PointCloud2``, best effort): the finest simulated level,
  float32 ``x y z``, in point-id order (so the first ``n_k`` points are level k);
* ``cloth/lod_marker`` (``visualization_msgs/Marker``, ``TRIANGLE_LIST``): level
  ``lod_level``, changeable at runtime.

Grippers (parameter ``grippers``, default ``['left', 'right']``), for each name:

* ``cloth/grippers/<name>/pose`` (``geometry_msgs/PoseStamped`` in ``frame_id``): the
  gripper's target pose; only the newest pose is kept and applied at the next tick;
* ``cloth/grippers/<name>/close`` (``std_msgs/Bool``): true grasps the finest-level points
  within ``grasp_radius`` of the gripper (the nearest point if none is that close), which
  then move rigidly with the gripper pose at every level; false releases them.

Bad input (non-finite poses, wrong frames, commands before any pose) is logged, throttled,
and dropped; the simulation goes on.

``cloth/reset`` (``std_srvs/Trigger``) returns the cloth to its initial state and releases
every grasp.
``pinned_points`` may be changed at runtime; scene and cloth parameters are read-only.
"""

import faulthandler
import gc
import json
import signal
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numba
import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Bool
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

from hcloth_ros import params
from hcloth_ros.core import warm_up
from hcloth_ros.core.solvers import prolong_state
from hcloth_ros.core.control import PINNED, quaternion_to_matrix
from hcloth_ros.recorder import Recorder
from hcloth_ros.ros_msgs import TriangleMarker, pointcloud2

NODE_PARAMS = [
    params.Param('rate_hz', 60.0, 'timer rate: steps and publications per second (Hz)',
                 1.0, 1000.0),
    params.Param('frame_id', 'world', 'frame of every published position'),
    params.Param('lod_level', 1, 'level published as cloth/lod_marker (0 = coarsest)', 0, 9,
                 False),
    params.Param('grippers', ['left', 'right'], 'gripper names: each gets '
                 'cloth/grippers/<name>/pose and .../close'),
    params.Param('rerun_path', '', 'record the run to this .rrd file; empty: no recording'),
    params.Param('rerun_url', '', 'stream to a running Rerun viewer at this url instead '
                 '(e.g. rerun+http://127.0.0.1:9876/proxy); empty: none'),
    params.Param('rerun_finest_every', 1, 'log the finest mesh every N ticks (the LOD mesh '
                 'and metrics every tick)', 1, 10000),
    params.Param('numba_threads', 1, 'threads of the numba kernels (capped at the cores); 1 '
                 'gave the lowest tail latency with subscribers on the same 2 cores', 1, 256),
    params.Param('grasp_radius', 0.03, 'a closing gripper takes the points this close (m)',
                 0.0, 1.0, False),
]


@dataclass
class Gripper:
    """The newest command of one gripper; applied by the timer, never queued."""

    name: str
    rotation: np.ndarray = None
    translation: np.ndarray = None
    pose_pending: bool = False
    close_request: bool = None      # None: nothing new; True: grasp; False: release
    grasping: bool = False


def _descriptor(spec):
    d = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    scalar = spec.default if not isinstance(spec.default, list) else None
    if spec.low is not None and isinstance(scalar, bool) is False:
        if isinstance(scalar, float):
            d.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                         to_value=float(spec.high), step=0.0)]
        elif isinstance(scalar, int):
            d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high),
                                            step=1)]
    return d


@dataclass
class TickStats:
    """Per-tick phase times (s), summarised when the node stops (percentiles over the
    last 36,000 ticks; the real-time factor over the whole run)."""

    samples: dict = field(default_factory=dict)
    count: int = 0
    wall_start: float = None

    def add(self, **values):
        if self.wall_start is None:
            self.wall_start = time.monotonic() - values['tick']
        for name, value in values.items():
            # the last 10 minutes at 60 Hz: bounded memory on long runs
            self.samples.setdefault(name, deque(maxlen=36000)).append(value)
        self.count += 1

    def summary(self):
        """p50/p99 in ms of each phase, ticks, real-time factor, levels simulated."""
        out = {'ticks': self.count}
        for name in ('step', 'pack', 'publish', 'record', 'tick'):
            ms = np.asarray(self.samples[name]) * 1e3
            out[name] = {'p50': float(np.percentile(ms, 50)), 'p99': float(np.percentile(ms, 99))}
        wall = time.monotonic() - self.wall_start
        out['real_time_factor'] = self.samples['sim_time'][-1] / wall if wall > 0 else 0.0
        out['levels_min'] = int(min(self.samples['levels']))
        out['levels_max'] = int(max(self.samples['levels']))
        return out


class ClothSimNode(Node):
    """The simulation node; see the module docstring for its interface."""

    def __init__(self, **kwargs):
        super().__init__('hcloth_sim', **kwargs)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        for spec in params.PARAMS + NODE_PARAMS:
            self.declare_parameter(spec.name, spec.default, _descriptor(spec))
        self._warn_unknown_overrides()
        values = params.resolve({spec.name: self.get_parameter(spec.name).value
                                 for spec in params.PARAMS})
        self.model, self.solver, self.state, self.control = params.build_all(values)
        self.initial = self.state.copy()
        self._markers = {}      # level -> TriangleMarker, built on first use
        self.dt = float(values['solver.dt'])
        self.substeps = int(values['solver.substeps'])
        self.frame_id = self.get_parameter('frame_id').value
        self.lod_level = self.get_parameter('lod_level').value
        if self.lod_level >= self.model.level_count:
            self.get_logger().warning(f'lod_level {self.lod_level} beyond the finest level '
                                      f'{self.model.level_count - 1}: using the finest')
            self.lod_level = self.model.level_count - 1
        threads = min(self.get_parameter('numba_threads').value, numba.config.NUMBA_NUM_THREADS)
        numba.set_num_threads(threads)
        self.get_logger().info(f'numba kernels ready in {warm_up():.2f} s, {threads} thread(s)')
        # numba's compiler leaves a large object graph behind; a full collection walking it
        # cost ~50 ms ticks (p99) in the node benchmark. Freeze what exists now so the
        # collector only looks at objects made while running.
        gc.collect()
        gc.freeze()
        self.cloud_pub = self.create_publisher(PointCloud2, 'cloth/points',
                                               qos_profile_sensor_data)
        self.marker_pub = self.create_publisher(Marker, 'cloth/lod_marker', 10)
        self.create_service(Trigger, 'cloth/reset', self._on_reset)
        self.grippers = {}
        latest = QoSProfile(depth=1)    # a flood keeps only the newest command
        for name in self.get_parameter('grippers').value:
            if not name or name in self.grippers or '/' in name:
                self.get_logger().error(f'gripper name {name!r} is empty, duplicate or has a '
                                        '"/": ignored')
                continue
            g = self.grippers[name] = Gripper(name)
            self.create_subscription(PoseStamped, f'cloth/grippers/{name}/pose',
                                     lambda msg, g=g: self._on_pose(g, msg), latest)
            self.create_subscription(Bool, f'cloth/grippers/{name}/close',
                                     lambda msg, g=g: self._on_close(g, msg), latest)
        # commands to a gripper name nobody declared reach no subscriber: look for them
        self._gripper_prefix = self.resolve_topic_name('cloth/grippers') + '/'
        self._reported_unknown = set()
        self.create_timer(1.0, self._check_unknown_grippers)
        self.stats = TickStats()
        self.recorder = None
        path, url = self.get_parameter('rerun_path').value, self.get_parameter('rerun_url').value
        if path or url:
            self.recorder = Recorder(self.model, path=path, url=url,
                                     finest_every=self.get_parameter('rerun_finest_every').value)
            self.get_logger().info(f'recording to {path or url}')
        self.period = 1.0 / self.get_parameter('rate_hz').value
        self.top_level = self.model.level_count - 1
        self.level_cap = self.top_level      # the real-time governor's ceiling
        self._overruns = self._headroom = 0
        self._grace = 30
        self.timer = self.create_timer(self.period, self._tick)
        lv = self.model.level(self.top_level)
        self.get_logger().info(
            f'{self.solver.name} cloth, {self.model.level_count} levels, finest '
            f'{lv.rows}x{lv.cols}, dt {self.dt * 1e3:.2f} ms x {self.substeps} per tick')

    # --- parameters and services -------------------------------------------------------
    def _warn_unknown_overrides(self):
        """rclpy silently ignores overrides (params file, -p) that match no declared
        parameter, so a misspelt ``cloth.widht`` would leave the default in place unseen."""
        # rclpy has no public accessor for the overrides it was given
        given = getattr(self, '_parameter_overrides', {})
        unknown = sorted(n for n in given
                         if not self.has_parameter(n) and not n.startswith('qos_overrides.'))
        if unknown:
            self.get_logger().error(f'unknown parameters ignored: {", ".join(unknown)} '
                                    '(see the README parameter table)')
        return unknown

    def _on_set_parameters(self, changes):
        if not hasattr(self, 'model'):
            return SetParametersResult(successful=True)     # initial declaration
        for p in changes:
            if p.name == 'lod_level' and not 0 <= p.value < self.model.level_count:
                return SetParametersResult(
                    successful=False,
                    reason=f'lod_level {p.value} out of range 0..{self.model.level_count - 1}')
            if p.name == 'pinned_points':
                bad = [i for i in params.pin_ids(p.value)
                       if not 0 <= i < self.model.point_count]
                if bad:
                    return SetParametersResult(
                        successful=False, reason=f'pinned_points {bad[:5]} out of range '
                        f'0..{self.model.point_count - 1}')
        # every change is valid: apply them all (nothing was changed while checking, so a
        # refused batch leaves the node as it was)
        for p in changes:
            if p.name == 'pinned_points':
                self.control.set_pins(params.pin_ids(p.value))
            elif p.name == 'lod_level':
                self.lod_level = p.value
            elif p.name == 'solver.dt':
                self.dt = float(p.value)
            elif p.name == 'solver.substeps':
                self.substeps = int(p.value)
            elif p.name == 'solver.strain_limit':
                self.solver.strain_limit = float(p.value) if p.value > 0 else None
        return SetParametersResult(successful=True)

    def _on_pose(self, gripper, msg):
        if msg.header.frame_id != self.frame_id:
            self.get_logger().warning(
                f'gripper {gripper.name}: pose in frame {msg.header.frame_id!r}, expected '
                f'{self.frame_id!r} (no tf here): dropped', throttle_duration_sec=1.0)
            return
        p, o = msg.pose.position, msg.pose.orientation
        try:
            rotation = quaternion_to_matrix(o.x, o.y, o.z, o.w)
            translation = np.array([p.x, p.y, p.z])
            if not np.all(np.isfinite(translation)):
                raise ValueError(f'position must be finite, got {translation.tolist()}')
        except ValueError as e:
            self.get_logger().error(f'gripper {gripper.name}: bad pose dropped: {e}',
                                    throttle_duration_sec=1.0)
            return
        gripper.rotation, gripper.translation = rotation, translation
        gripper.pose_pending = True

    def _check_unknown_grippers(self):
        """Name (once each) gripper topics that someone publishes to but that are not in
        ``grippers``: ROS delivers them nowhere, so the sender would otherwise never know."""
        for topic, _ in self.get_topic_names_and_types():
            if not topic.startswith(self._gripper_prefix) or topic in self._reported_unknown:
                continue
            name = topic[len(self._gripper_prefix):].rsplit('/', 1)[0]
            if name not in self.grippers and self.count_publishers(topic) > 0:
                self._reported_unknown.add(topic)
                self.get_logger().error(
                    f'{topic} has publishers but gripper {name!r} is not in grippers '
                    f'{sorted(self.grippers)}: its commands are not received')
        return sorted(self._reported_unknown)

    def _on_close(self, gripper, msg):
        gripper.close_request = bool(msg.data)

    def _apply_grippers(self):
        """Apply the newest gripper commands before a step."""
        for g in self.grippers.values():
            if g.close_request is not None:
                request, g.close_request = g.close_request, None
                if request and g.translation is None:
                    self.get_logger().warning(f'gripper {g.name}: close before any pose: '
                                              'ignored', throttle_duration_sec=1.0)
                elif request and not g.grasping:
                    ids = self._points_near(g.translation)
                    self.control.grasp(g.name, ids, self.state, g.rotation, g.translation)
                    g.grasping, g.pose_pending = True, False
                    self.get_logger().info(f'gripper {g.name}: grasped {len(ids)} points')
                elif not request and g.grasping:
                    self.control.release(g.name)
                    g.grasping = False
            if g.grasping and g.pose_pending:
                self.control.move_grasp(g.name, g.rotation, g.translation)
                g.pose_pending = False

    def _points_near(self, position):
        """Finest simulated level ids within grasp_radius, or the nearest one."""
        k = self.solver.levels()[-1]
        pts = self.state.points_by_id(self.model, k)
        d = np.linalg.norm(pts - position, axis=1)
        ids = np.flatnonzero(d <= self.get_parameter('grasp_radius').value)
        return ids if ids.size else np.array([int(np.argmin(d))])

    def _on_reset(self, request, response):
        self.state.assign(self.initial)
        self.control.release_all()
        for g in self.grippers.values():
            g.grasping, g.close_request, g.pose_pending = False, None, False
        response.success = True
        response.message = 'cloth reset to its initial state, every grasp released'
        return response

    # --- the timer -----------------------------------------------------------------------
    def _finest_needed(self):
        """The finest level anyone consumes: all of them for a cloud subscriber or a
        recording, else only up to the LOD marker's level."""
        if self.recorder is not None or self.cloud_pub.get_subscription_count() > 0:
            return self.top_level
        return self.lod_level

    def _govern(self, tick_seconds):
        """Drop the finest simulated level after 3 ticks in a row overran the period;
        restore it after 60 ticks in a row that would still fit in 80 % of the period with
        2.5x the work (the next level has about 4x the points, but packing and publishing
        do not grow with the simulated levels). Ticks right after start-up or a level
        change (first messages, restarted levels) are not judged.
        """
        if self._grace > 0:
            self._grace -= 1
            return
        if tick_seconds > self.period:
            self._overruns, self._headroom = self._overruns + 1, 0
        elif 2.5 * tick_seconds < 0.8 * self.period:
            self._overruns, self._headroom = 0, self._headroom + 1
        else:
            self._overruns = self._headroom = 0
        if self._overruns >= 3 and self.level_cap > self.lod_level:
            self.level_cap -= 1
            self._overruns = 0
            self.get_logger().warning(
                f'ticks overrun the {self.period * 1e3:.1f} ms period: simulating up to level '
                f'{self.level_cap}', throttle_duration_sec=1.0)
        elif self._headroom >= 60 and self.level_cap < self.top_level:
            self.level_cap += 1
            self._headroom = 0
            self.get_logger().info(f'headroom again: simulating up to level {self.level_cap}')

    def _set_levels(self):
        """Simulate only the levels consumed (hierarchical solver); a level that comes
        back starts from the coarser state, so nothing jumps."""
        if self.solver.name != 'hierarchical':
            return
        finest = max(min(self._finest_needed(), self.level_cap), self.lod_level)
        for k in range(self.solver.finest_level + 1, finest + 1):
            prolong_state(self.state, k)
            self.control.recapture(self.state, k)
        if finest != self.solver.finest_level:
            self.get_logger().info(f'simulating levels 0..{finest}')
            self.solver.finest_level = finest
            self._grace = 30

    def _tick(self):
        t0 = time.perf_counter()
        self._set_levels()
        self._apply_grippers()
        for _ in range(self.substeps):
            report = self.solver.step(self.state, self.control, self.dt)
            if not report.ok:
                self.get_logger().error(report.reason, throttle_duration_sec=1.0)
                break
        t1 = time.perf_counter()
        stamp = self.get_clock().now().to_msg()
        finest = self.solver.levels()[-1]
        cloud = None
        if self.cloud_pub.get_subscription_count() > 0:
            cloud = pointcloud2(self.state.points_by_id(self.model, finest), self.frame_id,
                                stamp)
        k = min(self.lod_level, finest) if self.solver.name == 'hierarchical' else finest
        marker = self._marker(k).update(self.state.points(k), stamp)
        t2 = time.perf_counter()
        if cloud is not None:
            self.cloud_pub.publish(cloud)
        self.marker_pub.publish(marker)
        t3 = time.perf_counter()
        if self.recorder is not None:
            self.recorder.log_step(self.state, finest, k, report, t3 - t0,
                                   self.dt * self.substeps, self._held_points(finest))
        t4 = time.perf_counter()
        self.stats.add(step=t1 - t0, pack=t2 - t1, publish=t3 - t2, record=t4 - t3,
                       tick=t4 - t0, levels=finest + 1, sim_time=self.state.time)
        self._govern(t4 - t0)

    def _marker(self, k):
        if k not in self._markers:
            self._markers[k] = TriangleMarker(self.model.grid_triangles(k), self.frame_id,
                                              ns='hcloth_lod', marker_id=0)
        return self._markers[k]

    def _held_points(self, k):
        kind = self.control.holds(k).kind.ravel()
        pts = self.state.points(k)
        return {'pins': pts[kind == PINNED], 'grasps': pts[kind > PINNED]}

    def destroy_node(self):
        # also called by the context's shutdown on a node whose __init__ was interrupted
        # (Ctrl-C during warm-up): only what exists is reported and closed
        if getattr(self, 'stats', None) is not None and self.stats.count:
            self.get_logger().info(f'tick stats {json.dumps(self.stats.summary())}')
        if getattr(self, 'recorder', None) is not None:
            self.recorder.close()
            self.recorder = None
        super().destroy_node()


_STOP = threading.Event()


def _request_stop(signum, frame):
    # Only a flag: an exception raised from a signal handler lands in whatever code runs
    # at that moment, and a handler that swallows it there (seen: Ctrl-C during start-up
    # lost in 9 of 140 starts, the node then ran on) loses the stop request.
    _STOP.set()


def main(args=None):
    # Our handlers first: Ctrl-C or SIGTERM at any moment from here on stops the node
    # after start-up, with the context still valid, so the tick statistics and the end of
    # the recording go out through a live node (rclpy's own handlers shut the context
    # down first: "publisher's context is invalid"). Explicitly for SIGINT too: a shell
    # starts background jobs with SIGINT ignored, and Python keeps it so.
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _request_stop)
    # `kill -USR1 <pid>` prints every thread's Python stack: a hung node explains itself
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    # numba picks its threading layer (OpenMP here). OpenMP once crashed on an early
    # Ctrl-C (1 in 12 starts, under rclpy's signal handlers); with the stop flag above, 0
    # crashes in about 220 interrupted starts (doc/interrupt_stress.py), while the
    # workqueue layer costs 2-4x the step at one thread (16k-point node benchmark: tick
    # p99 16.0 ms against 7.7 ms).
    # NUMBA_THREADING_LAYER in the environment chooses another.
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = ClothSimNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not _STOP.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
