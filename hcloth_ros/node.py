"""
``sim_node``: the cloth simulation as a ROS 2 node (default name ``hcloth_sim``).

Steps the engine on a timer and after every tick publishes

* ``cloth/points`` (``sensor_msgs/PointCloud2``, best effort): the finest simulated level,
  float32 ``x y z``, in point-id order (so the first ``n_k`` points are level k);
* ``cloth/lod_marker`` (``visualization_msgs/Marker``, ``TRIANGLE_LIST``): level
  ``lod_level``, changeable at runtime.

Both are packed in the tick and sent from a thread of their own (``publish_thread``,
default true) while the timer's thread steps on; the next tick waits for that send.

Time: every message is stamped with the simulation's time, which ``/clock``
(``rosgraph_msgs/Clock``) carries after every tick (it starts at 0 and goes back to 0 on
reset). The timer runs on the steady wall clock whether or not ``use_sim_time`` is set
(the node is the source of ``/clock``, so a timer on ROS time would wait for itself):
a tick every ``solver.dt * solver.substeps / real_time_factor`` seconds, back to back
when ``real_time_factor`` is 0. ``use_sim_time`` only chooses what the node's own ROS
clock reads. ``cloth/pause`` (``std_srvs/SetBool``: true pauses, false resumes) and
``cloth/step`` (``std_srvs/Trigger``: one tick while paused, answered once its messages
are sent) make scripted runs deterministic; a paused node publishes nothing new and
answers every request. ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``, 1 Hz)
holds the tick statistics of the last second, the levels simulated, the governor's state
and whether the node is paused. Publishers accept rclpy's ``qos_overrides.*``
parameters (history, depth, reliability). ``bag_path`` records the node's own topics
to an MCAP file. On shutdown the LOD marker and the scene markers are deleted.

Grippers (parameter ``grippers``, default ``['left', 'right']``), for each name:

* ``cloth/grippers/<name>/pose`` (``geometry_msgs/PoseStamped`` in ``frame_id``): the
  gripper's target pose; only the newest pose is kept and applied at the next tick;
* ``cloth/grippers/<name>/close`` (``std_msgs/Bool``): true grasps the finest-level points
  within ``grasp_radius`` of the gripper (the nearest point if none is that close), which
  then move rigidly with the gripper pose at every level; false releases them.

Moving obstacles (parameter ``scene.moving_obstacles``, see :mod:`~hcloth_ros.obstacles`):
each follows ``cloth/obstacles/<name>/pose`` (``geometry_msgs/PoseStamped`` in
``frame_id``, newest pose applied at the next tick) from its first pose on. The scene
(ground, boxes, spheres, moving obstacles) is published as ``cloth/scene``
(``visualization_msgs/MarkerArray``, transient local) at start, when it changes and when
an obstacle moves.

Bad input (non-finite poses, wrong frames, commands before any pose) is logged, throttled,
and dropped; the simulation goes on. A step refused for blow-up, or for stretching a
spring past ``solver.retry_strain`` from a start within it while self-contact found
pairs, is retried in 2, 4 and 8 smaller steps (grasps and moving bodies moving evenly
over them) and the node says so. ``cloth/reset``
(``std_srvs/Trigger``) returns the cloth to its initial state and releases every grasp.
``pinned_points``, the static obstacles (``scene.*``: a cloth inside a new obstacle is
pushed out over a few steps) and the solver's step parameters may change at runtime; cloth
parameters are read-only.

The node is wiring: the units it wires are ROS-free and tested on their own
(:mod:`~hcloth_ros.grippers`, :mod:`~hcloth_ros.governor`, :mod:`~hcloth_ros.publishing`,
:mod:`~hcloth_ros.node_params`, :mod:`~hcloth_ros.tick_stats`,
:mod:`~hcloth_ros.lifetime`); the solver decides how a level comes back.
"""

import gc
import json
import os
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from hcloth_ros import lifetime, memory, params
from hcloth_ros.core import kernels_cached, warm_up
from hcloth_ros.core.blas import limit_openblas_threads
from hcloth_ros.core.control import PINNED
from hcloth_ros.core.recovery import retry_warning
from hcloth_ros.core.self_contact import solved_level_warning, thickness_warning
from hcloth_ros.core.solvers import HierarchicalSolver
from hcloth_ros.diagnostics import node_status
from hcloth_ros.governor import finest_to_simulate, Governor
from hcloth_ros.grippers import GripperBank, points_within
from hcloth_ros.lifetime import StartupError
from hcloth_ros.node_params import (ALL_PARAMS, as_declared_type, check_change, descriptor,
                                    NODE_PARAMS, params_files, scene_after, sections_for,
                                    SPEC_BY_NAME, startup_problems, unknown_overrides)
from hcloth_ros.publishing import ClothPublisher, PublishThread
from hcloth_ros.ros_msgs import sim_stamp
from hcloth_ros.scene_markers import scene_markers
from hcloth_ros.simulation import plain, SETTINGS, Simulation
from hcloth_ros.tick_stats import TickStats
import numba
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Bool
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import Marker, MarkerArray


__all__ = ['ClothSimNode', 'main', 'NODE_PARAMS']

# parameters the tick timer's period and the governor depend on
PACE = {'solver.dt', 'solver.substeps', 'real_time_factor', 'governor'}

# What a first start costs on an empty numba cache (measured here: README, "First start").
CATCH_UP = 6        # most ticks one timer call runs to make up for late calls
# periods the ticks may fall behind wall time and still be made up (over several calls):
# the stress suite's requests with 10^6-element arrays held the executor 0.2-0.6 s in
# rclpy's own conversion, and with 6 the node lost 2-20 % of an 8 s phase's ticks here
LAG = 30
FIRST_START = 'about 30-40 s on 2 cores'
# s the shutdown waits for each marker topic's subscribers to have the deletes (a stuck
# one must not hold the exit past the stress test's 2 s)
DELETE_ACK_WAIT = 0.5


class ClothSimNode(Node):
    """The simulation node; see the module docstring for its interface."""

    def __init__(self, **kwargs):
        super().__init__('hcloth_sim', **kwargs)
        self._check_overrides()
        self._check_params_files(kwargs.get('cli_args'))
        self._check_output_paths()
        self.add_pre_set_parameters_callback(self._declared_types)
        self.add_on_set_parameters_callback(self._check_parameters)
        for spec in ALL_PARAMS:
            self.declare_parameter(spec.name, spec.default, descriptor(spec))
        self._warn_unknown_overrides()
        values = params.resolve({spec.name: self.get_parameter(spec.name).value
                                 for spec in params.PARAMS})
        too_big = memory.refusal(values, self.get_parameter('memory_budget_mb').value)
        if too_big:
            raise StartupError([too_big])
        try:
            # every change to it is a command, kept for the recording (exact replay)
            self.sim = Simulation.build(values)
        except ValueError as e:     # combinations the table cannot state (parallel axes)
            raise StartupError([f'the scene cannot be built: {e}']) from None
        try:
            self.sim.add_moving_obstacles(self.get_parameter('scene.moving_obstacles').value)
        except ValueError as e:
            raise StartupError([f'parameter scene.moving_obstacles: {e}']) from None
        # the same objects as the simulation's, for short: commands change them in place
        self.model, self.solver, self.state, self.control = \
            self.sim.model, self.sim.solver, self.sim.state, self.sim.control
        self.obstacles = self.sim.obstacles
        self._warn_self_contact_settings()
        # multi-level solvers simulate levels on demand and publish any level of detail
        self._levelled = isinstance(self.solver, HierarchicalSolver)
        self.frame_id = self.get_parameter('frame_id').value
        self.top_level = self.model.level_count - 1
        self.lod_level = self.get_parameter('lod_level').value
        if self.lod_level > self.top_level:
            self.get_logger().warning(f'lod_level {self.lod_level} beyond the finest level '
                                      f'{self.top_level}: using the finest')
            self.lod_level = self.top_level
        self._warm_up()
        overridable = QoSOverridingOptions.with_default_policies()
        self.publisher = ClothPublisher(
            self.model, self.frame_id,
            self.create_publisher(PointCloud2, 'cloth/points', qos_profile_sensor_data,
                                  qos_overriding_options=overridable),
            self.create_publisher(Marker, 'cloth/lod_marker', 10,
                                  qos_overriding_options=overridable))
        self._clock_publisher = self.create_publisher(ClockMsg, '/clock', QoSProfile(depth=1),
                                                      qos_overriding_options=overridable)
        self._sender = None
        self._sends_seen = 0
        self.bag = None         # made last: a start refused later leaves no file behind
        self._bag_lock = threading.Lock()     # the timer's and the sending thread write
        self._bag_offset = 0    # ns: bag times go on across resets (the stamps start again)
        if self.get_parameter('publish_thread').value:
            self._sender = PublishThread(self._send, self._on_send_error)
        self.paused = False
        self.create_service(Trigger, 'cloth/reset', self._on_reset)
        self.create_service(SetBool, 'cloth/pause', self._on_pause)
        self.create_service(Trigger, 'cloth/step', self._on_step)
        self._make_grippers()
        self._make_obstacles()
        self.recorder = self._make_recorder()
        if self.recorder is not None:
            self.recorder.log_start(self.sim.start_record(), numba.get_num_threads())
            self.recorder.log_obstacles(self.model.scene, self.state.time)
            self.recorder.log_bodies(self.control.bodies, self.state.time)
        self.bag = self._make_bag()
        self._bag_scene()
        self.stats = TickStats()
        self.report = None      # the last step's report
        # the node is the source of /clock: its timers run on the steady clock, so that
        # with use_sim_time they do not wait for the time they are to make
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.governor = Governor(1.0, self.top_level, floor=self.lod_level)
        self.timer = None
        self._start_timer()
        self._make_diagnostics()
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._clock_publisher.publish(ClockMsg(clock=sim_stamp(self.state.time)))
        lv = self.model.level(self.top_level)
        self.get_logger().info(
            f'{self.solver.name} cloth, {self.model.level_count} levels, finest '
            f'{lv.rows}x{lv.cols}, dt {self.sim.dt * 1e3:.2f} ms x {self.sim.substeps} per '
            f'tick, {self._pace()}')

    # --- start-up ----------------------------------------------------------------------
    def _warn_self_contact_settings(self):
        """
        Log (and return) what self-contact's settings will not do well, or None.

        A thickness not below the finest spacing; the finest level solved by multigrid
        without strain limiting on it (``solved_level_warning``); retries below the strain
        limit (``retry_warning``).
        """
        contact = self.solver.self_contact
        texts = [thickness_warning(self.model, contact.thickness),
                 solved_level_warning(self.solver),
                 retry_warning(self.solver)] if contact else []
        text = '; '.join(t for t in texts if t) or None
        if text:
            self.get_logger().warning(text)
        return text

    def _check_overrides(self):
        """
        Refuse to start on a disallowed value (one line each); integers become floats.

        rclpy would raise a traceback at the first bad value, naming neither what is
        allowed nor the next one; an integer where a float is declared it refuses too.
        """
        overrides = getattr(self, '_parameter_overrides', {})
        for name, given in list(overrides.items()):
            spec = SPEC_BY_NAME.get(name)
            value = as_declared_type(spec, given.value) if spec else given.value
            if value is not given.value:
                overrides[name] = Parameter(name, value=value)
        problems = startup_problems({name: p.value for name, p in overrides.items()})
        if problems:
            raise StartupError([f'parameter {line}' for line in problems])

    def _check_params_files(self, cli_args):
        """
        Report a params file with no section for this node (rcl ignores it silently).

        Returns the paths reported.
        """
        fqn = self.get_fully_qualified_name()
        reported = []
        for path in params_files(sys.argv + list(cli_args or [])):
            try:
                matched = sections_for(path, fqn)
            except (OSError, ValueError) as e:      # yaml.YAMLError is a ValueError
                self.get_logger().error(f'params file {path}: cannot read it: {e}')
                reported.append(path)
                continue
            if not matched:
                reported.append(path)
                self.get_logger().error(
                    f'params file {path} has no section for node {fqn} (keys it would '
                    f'match: /**, {fqn} or {fqn.rsplit("/", 1)[1]} in the root namespace): '
                    'none of its values are used')
        return reported

    def _check_output_paths(self):
        """
        Refuse recording paths that cannot be written before the kernels are warmed.

        Found later, a bad path ended the start after seconds of warm-up, with the
        recording library's own warnings beside the error.
        """
        problems = []
        for name in ('rerun_path', 'bag_path'):
            given = self._parameter_overrides.get(name)
            path = given.value if given is not None else ''
            if not isinstance(path, str) or not path:
                continue
            folder = os.path.dirname(os.path.abspath(path))
            if not os.path.isdir(folder) or not os.access(folder, os.W_OK):
                problems.append(f'parameter {name} = {path!r}: cannot write in {folder}')
            elif name == 'bag_path' and os.path.exists(path):
                problems.append(f'parameter bag_path = {path!r}: the file exists (a bag is '
                                'never overwritten)')
        if problems:
            raise StartupError(problems)

    def _declared_types(self, changes):
        """Pre-set callback: an integer given for a float parameter becomes a float."""
        out = []
        for p in changes:
            spec = SPEC_BY_NAME.get(p.name)
            value = as_declared_type(spec, p.value) if spec else p.value
            out.append(p if value is p.value else Parameter(p.name, value=value))
        return out

    def _warm_up(self):
        """Compile (first start) or load the kernels before the timer starts."""
        threads = min(self.get_parameter('numba_threads').value,
                      numba.config.NUMBA_NUM_THREADS)
        numba.set_num_threads(threads)
        # OpenBLAS's own spinning threads would take the cores numba's need (core.blas)
        limit_openblas_threads(1)
        recording = bool(self.get_parameter('rerun_path').value
                         or self.get_parameter('rerun_url').value)
        wanted = {'solvers': [self.solver.name], 'parallel': threads > 1,
                  'energy': recording, 'self_contact': self.solver.self_contact is not None,
                  'bodies': bool(self.obstacles.names()),
                  'tangent_strain': self.solver.contact_strain == 'tangent'}
        if not kernels_cached(**wanted):
            self.get_logger().info(
                f'preparing the numba kernels of the {self.solver.name} solver: the first '
                f'start on a machine compiles them ({FIRST_START}), later starts load them '
                'in under a second')
        self.get_logger().info(f'numba kernels ready in {warm_up(**wanted):.2f} s, '
                               f'{threads} thread(s)')
        # numba's compiler leaves a large object graph behind; a full collection walking
        # it cost ~50 ms ticks (p99) in the node benchmark. Freeze what exists now so the
        # collector only looks at objects made while running.
        gc.collect()
        gc.freeze()

    def _make_grippers(self):
        self.grippers = GripperBank(self.get_parameter('grippers').value)
        for name in self.grippers.refused:
            self.get_logger().error(f'gripper name {name!r} is empty, duplicate or has a '
                                    '"/": ignored')
        latest = QoSProfile(depth=1)    # a flood keeps only the newest command
        for name in self.grippers.names():
            self.create_subscription(
                PoseStamped, f'cloth/grippers/{name}/pose',
                lambda msg, name=name: self._on_pose(self.grippers, name, msg), latest)
            self.create_subscription(
                Bool, f'cloth/grippers/{name}/close',
                lambda msg, name=name: self.grippers.request_close(name, msg.data), latest)
        # commands to a gripper name nobody declared reach no subscriber: look for them
        self._gripper_prefix = self.resolve_topic_name('cloth/grippers') + '/'
        self._reported_unknown = set()
        self.create_timer(1.0, self._check_unknown_grippers,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _make_obstacles(self):
        latest = QoSProfile(depth=1)    # a flood keeps only the newest pose
        for name in self.obstacles.names():
            self.create_subscription(
                PoseStamped, f'cloth/obstacles/{name}/pose',
                lambda msg, name=name: self._on_pose(self.obstacles, name, msg), latest)
        # a late RViz gets the last scene
        self._scene_publisher = self.create_publisher(
            MarkerArray, 'cloth/scene',
            QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL),
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self._show_scene('obstacles')     # the recorder, made later, logs it all at start

    def _show_scene(self, changed):
        """
        Publish the scene markers; when recording, log what ``changed``.

        ``'obstacles'`` (the static ones) or ``'bodies'`` (a moving one moved). The markers
        always hold the whole scene: the topic keeps only its last message for late viewers.
        """
        self._scene_message = scene_markers(self.model.scene, self.control.bodies,
                                            self.frame_id, sim_stamp(self.state.time))
        self._scene_publisher.publish(self._scene_message)
        if getattr(self, 'bag', None) is not None:
            self._bag_scene()
        if getattr(self, 'recorder', None) is None:
            return
        if changed == 'obstacles':
            self.recorder.log_obstacles(self.model.scene, self.state.time)
        else:
            self.recorder.log_bodies(self.control.bodies, self.state.time)

    def _make_bag(self):
        """Open the MCAP bag of ``bag_path`` and register the node's topics (None: no bag)."""
        path = self.get_parameter('bag_path').value
        if not path:
            return None
        from hcloth_ros.bag import BagWriter
        try:
            bag = BagWriter(path)
        except (OSError, ValueError) as e:
            raise StartupError([f'parameter bag_path = {path!r}: {e}']) from None
        self._bag_topics = {name: self.resolve_topic_name(name) for name in
                            ('cloth/points', 'cloth/lod_marker', 'cloth/scene', '/clock')}
        topics = self._bag_topics
        cloud_qos = self.publisher.cloud_publisher.qos_profile     # overrides included
        bag.add_topic(topics['cloth/points'], PointCloud2, depth=cloud_qos.depth,
                      qos='reliable' if cloud_qos.reliability == ReliabilityPolicy.RELIABLE
                      else 'best_effort')
        bag.add_topic(topics['cloth/lod_marker'], Marker)
        bag.add_topic(topics['cloth/scene'], MarkerArray, transient_local=True, depth=1)
        bag.add_topic(topics['/clock'], ClockMsg, depth=1)
        self.publisher.always_cloud = True      # the bag wants every level
        self.get_logger().info(f'recording cloth/points, cloth/lod_marker, cloth/scene and '
                               f'/clock to {path}')
        return bag

    def _bag_time(self):
        """Return the bag's time of now (ns): sim time, carried on across resets."""
        return round(self.state.time * 1e9) + self._bag_offset

    def _bag_write(self, messages, bag_ns):
        """
        Write ``(topic, message)`` pairs at ``bag_ns`` (:meth:`_bag_time`) to the bag, if any.

        A failed write (disk full) closes the bag with one error; the simulation goes on.
        The time is taken in the tick, not here: a reset during a send must not move it.
        """
        with self._bag_lock:
            if self.bag is None:
                return
            try:
                for topic, msg in messages:
                    if msg is not None:
                        self.bag.write(self._bag_topics[topic], msg, bag_ns)
            except (OSError, ValueError) as e:
                self.get_logger().error(f'bag {self.bag.path}: {e}; bag closed, the '
                                        'simulation goes on')
                self._close_bag(quietly=True)

    def _close_bag(self, quietly=False):
        """Finish the bag (call with the bag lock held); ``quietly``: after a failed write."""
        bag, self.bag = self.bag, None
        try:
            bag.close()
        except (OSError, ValueError) as e:
            if not quietly:     # the failed write was reported: one error, not two
                self.get_logger().error(f'bag {bag.path}: closing failed: {e}')

    def _bag_scene(self):
        self._bag_write([('cloth/scene', self._scene_message)], self._bag_time())

    def _send(self, cloud, marker, bag_ns):
        """Publish a tick's cloud and marker; write them to the bag too."""
        self.publisher.publish(cloud, marker)
        self._bag_write([('cloth/points', cloud), ('cloth/lod_marker', marker)], bag_ns)

    def _make_recorder(self):
        path, url = self.get_parameter('rerun_path').value, self.get_parameter('rerun_url').value
        if not (path or url):
            return None
        from hcloth_ros.recorder import Recorder
        try:
            recorder = Recorder(self.model, path=path, url=url,
                                finest_every=self.get_parameter('rerun_finest_every').value)
        except (RuntimeError, OSError, ValueError) as e:    # rerun: "Failed to create file"
            name = 'rerun_path' if path else 'rerun_url'
            raise StartupError([f'parameter {name} = {path or url!r}: {e}']) from None
        self.get_logger().info(f'recording to {path or url}')
        return recorder

    def _warn_unknown_overrides(self):
        # rclpy has no public accessor for the overrides it was given
        # (rclpy's own parameters, use_sim_time and the like, are declared by now)
        given = getattr(self, '_parameter_overrides', {})
        unknown = unknown_overrides(given, {name for name in given if self.has_parameter(name)})
        if unknown:
            self.get_logger().error(f'unknown parameters ignored: {", ".join(unknown)} '
                                    '(see the README parameter table)')
        return unknown

    # --- parameters, commands, services -----------------------------------------------
    def _check_parameters(self, changes):
        """Refuse a batch if any change is invalid: nothing is applied before all pass."""
        if not hasattr(self, 'model'):
            return SetParametersResult(successful=True)     # initial declaration
        for p in changes:
            if not p.name:     # rclpy lets an empty name through as if it were declared
                return SetParametersResult(successful=False, reason='empty parameter name')
            reason = check_change(p.name, p.value, self.model)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        if _changes_scene(changes):
            _, reason = scene_after({p.name: p.value for p in changes}, self._scene_values())
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _scene_values(self):
        """Return the ``scene.*`` parameters' values, plain (rclpy's arrays as lists)."""
        return {spec.name: plain(self.get_parameter(spec.name).value) for spec in params.PARAMS
                if spec.name.startswith('scene.')}

    def _apply_parameters(self, changes):
        """Apply an accepted batch of runtime changes."""
        for p in changes:
            if p.name == 'pinned_points':
                self.sim.apply(['pins', params.pin_ids(p.value)])
            elif p.name == 'lod_level':
                self.lod_level = self.governor.floor = p.value
            elif p.name in SETTINGS:
                self.sim.apply(['set', p.name, plain(p.value)])
        if {p.name for p in changes} & {'solver.retry_strain', 'solver.strain_limit'}:
            text = retry_warning(self.solver)
            if text:
                self.get_logger().warning(text)
        if _changes_scene(changes):
            # built a second time (the check built it too): rare, and the command then
            # holds only values, as a replay needs
            self.sim.apply(['scene', self._scene_values()])
            self.get_logger().info('static obstacles changed; a cloth inside them is pushed '
                                   'out over the next steps')
            self._show_scene('obstacles')
        if {p.name for p in changes} & PACE:
            self._start_timer()

    def _on_pose(self, bank, name, msg):
        """Hand a PoseStamped to a gripper or obstacle bank; log why it was dropped, if it was."""
        p, o = msg.pose.position, msg.pose.orientation
        dropped = bank.set_pose(name, msg.header.frame_id, self.frame_id, (p.x, p.y, p.z),
                                (o.x, o.y, o.z, o.w))
        if dropped:
            self._log(*dropped)

    def _check_unknown_grippers(self):
        """
        Name (once each) gripper topics with publishers but no gripper of that name.

        ROS delivers them nowhere, so the sender would otherwise never know.
        """
        for topic, _ in self.get_topic_names_and_types():
            if not topic.startswith(self._gripper_prefix) or topic in self._reported_unknown:
                continue
            name = topic[len(self._gripper_prefix):].rsplit('/', 1)[0]
            if name not in self.grippers and self.count_publishers(topic) > 0:
                self._reported_unknown.add(topic)
                self.get_logger().error(
                    f'{topic} has publishers but gripper {name!r} is not in grippers '
                    f'{self.grippers.names()}: its commands are not received')
        return sorted(self._reported_unknown)

    def _on_reset(self, request, response):
        self._bag_offset += round((self.state.time - self.sim.initial.time) * 1e9)
        self.sim.apply(['reset'])
        self.grippers.forget_grasps()
        self._publish_clock()           # time goes back now, paused or not
        response.success = True
        response.message = ('cloth reset to its initial state and time 0, every grasp '
                            'released' + (' (paused: cloth/step advances it)'
                                          if self.paused else ''))
        return response

    def _on_pause(self, request, response):
        """Pause (``data`` true) or resume (false) the timer's ticks."""
        was, self.paused = self.paused, bool(request.data)
        self._due = None        # a pause is not time to make up
        state = 'paused' if self.paused else 'running'
        response.success = True
        response.message = f'already {state}' if was == self.paused else state
        if was != self.paused:
            self.get_logger().info(f'simulation {state} at t = {self.state.time:.4f} s')
        return response

    def _on_step(self, request, response):
        """
        Advance one tick while paused; answer once its messages are sent.

        Refused while running (as simulation_interfaces' StepSimulation): the timer's
        ticks and a requested one would race for the same state.
        """
        if not self.paused:
            response.success = False
            response.message = 'not paused: call cloth/pause with true first'
            return response
        self._tick()
        sent = self._sender is None or self._sender.wait(timeout=1.0)
        response.success = sent and (self.report is None or self.report.ok)
        response.message = f'stepped to t = {self.state.time:.6f} s'
        if not sent:
            response.message += ' (its messages were not sent within 1 s)'
        elif not response.success:
            response.message += f' ({self.report.reason})'
        return response

    # --- pace, diagnostics ---------------------------------------------------------------
    def _start_timer(self):
        """
        (Re)start the tick timer at the pace the parameters ask for.

        The governor judges ticks against the period; with no period (as fast as
        possible) there is nothing to keep up with, and shedding levels would only make a
        batch run depend on the machine, so it is off.
        """
        rtf = self.get_parameter('real_time_factor').value
        period = self.sim.dt * self.sim.substeps / rtf if rtf > 0 else 0.0
        wanted = self.get_parameter('governor').value and period > 0
        if self.timer is not None and period == self.period \
                and wanted == self.governor.enabled:
            return      # a value set again (a slider, a reconfigure tool): no tick lost
        self.period = period
        self._due = None        # ticks are due from the new timer's first call
        if self.timer is not None:
            self.destroy_timer(self.timer)
        self.timer = self.create_timer(self.period, self._on_timer, clock=self._steady)
        self.governor.period = self.period
        if wanted != self.governor.enabled:
            self.governor.set_enabled(wanted)

    def _pace(self):
        rtf = self.get_parameter('real_time_factor').value
        if rtf <= 0:
            return 'as fast as possible'
        return f'a tick every {self.period * 1e3:.2f} ms (real-time factor {rtf:g})'

    def _make_diagnostics(self):
        self._diagnostics = self.create_publisher(
            DiagnosticArray, '/diagnostics', 10,
            qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self._diagnosed = (0, self.state.time, time.monotonic())   # ticks, sim, wall
        self.create_timer(1.0, self._publish_diagnostics, clock=self._steady)

    def _publish_diagnostics(self):
        """Publish the last second's figures on /diagnostics."""
        ticks, sim, wall = self.stats.count, self.state.time, time.monotonic()
        last_ticks, last_sim, last_wall = self._diagnosed
        self._diagnosed = (ticks, sim, wall)
        # a reset in the window sends sim time back: no factor for that window
        factor = (sim - last_sim) / (wall - last_wall) if sim >= last_sim and wall > last_wall \
            else None
        self._diagnostics.publish(node_status(
            self.get_fully_qualified_name(), sim_stamp(sim),
            recent=self.stats.recent(ticks - last_ticks), real_time_factor=factor,
            target_factor=self.get_parameter('real_time_factor').value, paused=self.paused,
            levels=len(self.solver.levels()), level_count=self.model.level_count,
            governor_cap=self.governor.cap if self.governor.enabled else None,
            refused=None if self.report is None or self.report.ok else self.report.reason,
            sim_time=sim))

    # --- the tick -----------------------------------------------------------------------
    def _on_timer(self):
        """
        Tick, and make up for calls that came late, up to :data:`CATCH_UP` ticks a call.

        rcl skips the periods a late timer missed: under a storm of parameter requests
        (the stress suite) a busy executor lost 3-11 % of the ticks of a 4 s phase. Ticks
        are due every period from the first; a call runs those due by now (a quarter
        period early counts: the timer's own jitter), at most :data:`CATCH_UP`, the next
        calls the rest. Further behind than :data:`LAG` periods (ticks slower than the
        period), the lost time stays lost and the governor sheds levels.
        """
        if self.paused:
            return
        if self.period <= 0:
            self._tick()
            return
        now = time.monotonic()
        if self._due is None or now - self._due > LAG * self.period:
            self._due = now
        for _ in range(CATCH_UP):
            if now < self._due - 0.25 * self.period:
                break
            self._tick()
            self._due += self.period

    def _set_levels(self):
        """Simulate only the levels someone consumes, within the governor's cap."""
        if not self._levelled:
            return
        consumed_all = self.recorder is not None or self.publisher.cloud_wanted()
        finest = finest_to_simulate(consumed_all, self.lod_level, self.governor.cap,
                                    self.top_level)
        if finest != self.solver.finest_level:
            self.sim.apply(['levels', finest])
            self.get_logger().info(f'simulating levels 0..{finest}')
            self.governor.restart_grace()

    def _points_near(self, position):
        """Finest simulated level ids within ``grasp_radius`` of a position."""
        pts = self.state.points_by_id(self.model, self.solver.levels()[-1])
        return points_within(pts, position, self.get_parameter('grasp_radius').value)

    def _max_step(self, parameter):
        """How far a gripper or an obstacle may travel this tick (m), or None: no limit."""
        speed = self.get_parameter(parameter).value
        return speed * self.sim.dt * self.sim.substeps if speed > 0 else None

    def _tick(self):
        t0 = time.perf_counter()
        self._set_levels()
        for severity, text in self.grippers.apply(self.sim.apply, self._points_near,
                                                  self._max_step('grasp_max_speed')):
            self._log(severity, text)
        moved, log = self.obstacles.apply(self.sim.apply, self._max_step('obstacle_max_speed'))
        for severity, text in log:
            self._log(severity, text)
        commands = self.sim.take_commands()
        report = self.report = self.sim.advance(self._report_retry)
        stamp = self._publish_clock()
        bag_ns = self._bag_time()
        if moved:
            self._show_scene('bodies')
        t1 = time.perf_counter()
        free, sent = self._wait_for_sender()
        t1b = time.perf_counter()
        finest = self.solver.levels()[-1]
        lod = min(self.lod_level, finest) if self._levelled else finest
        if free:
            cloud, marker = self.publisher.pack(self.state, finest, lod, stamp)
        t2 = time.perf_counter()
        if self._sender is None:
            self._send(cloud, marker, bag_ns)
        t3 = time.perf_counter()
        if self.recorder is not None:
            self.recorder.log_step(self.state, finest, lod, report, t3 - t0,
                                   self.sim.dt * self.sim.substeps, self._held_points(finest),
                                   commands)
        t4 = time.perf_counter()
        if self._sender is not None and free:
            # after the recorder: its Python would wait for the GIL the sending thread
            # holds (recording, 16k points: record 1.1-1.5 -> 2.7-3.1 ms p50 when sent
            # before it); from here the send overlaps the next step's kernels instead
            self._sender.submit(cloud, marker, bag_ns)
        t5 = time.perf_counter()
        self.stats.add(step=t1 - t0, pack=t2 - t1b, publish=(t1b - t1) + (t3 - t2) + (t5 - t4),
                       send=sent, record=t4 - t3, tick=t5 - t0, levels=finest + 1,
                       sim_time=self.state.time)
        if self.period > 0:
            self._govern(t5 - t0)

    def _publish_clock(self):
        """Publish (and bag) the simulation's time on /clock; return its stamp."""
        stamp = sim_stamp(self.state.time)
        clock = ClockMsg(clock=stamp)
        self._clock_publisher.publish(clock)
        self._bag_write([('/clock', clock)], self._bag_time())
        return stamp

    def _wait_for_sender(self):
        """
        Wait until the last tick's messages are sent: ``(free, seconds)``.

        ``free``: this tick may pack and send (False when the last send is still running
        after 1 s: this tick publishes nothing, rather than rewrite a marker the thread may
        be reading). ``seconds``: how long the send that finished since the last tick took,
        0 if none did (and always without the publishing thread, whose tick's own publish
        time says it all).
        """
        if self._sender is None:
            return True, 0.0
        free = self._sender.wait(timeout=1.0)
        if not free:
            self.get_logger().error('cloth/points and cloth/lod_marker: the messages of the '
                                    'last tick are still being sent after 1 s; this tick '
                                    'publishes nothing', throttle_duration_sec=1.0)
        done = self._sender.sent
        seconds = self._sender.last_seconds if done > self._sends_seen else 0.0
        self._sends_seen = done
        return free, seconds

    def _on_send_error(self, error):
        self.get_logger().error(f'publishing failed: {error}', throttle_duration_sec=1.0)

    def _report_retry(self, report, steps):
        """Say what recovery did: n smaller steps went through, the whole step, or none."""
        ms = self.sim.dt * 1e3
        if steps == 1:
            self.get_logger().warning(
                f'step of {ms:.2f} ms refused ({report.extra["refused"]}); the smallest '
                f'retried steps stretched the springs further '
                f'({report.extra["smaller_strain"]:.3g}): '
                f'taken whole after all ({report.max_strain:.3g})', throttle_duration_sec=1.0)
        elif steps:
            self.get_logger().warning(
                f'step of {ms:.2f} ms refused ({report.extra["refused"]}); '
                f'retried as {steps} steps of {ms / steps:.2f} ms: went through',
                throttle_duration_sec=1.0)
        else:
            self.get_logger().error(f'{report.reason}; retried in 2, 4 and 8 smaller steps, '
                                    'all refused', throttle_duration_sec=1.0)

    def _govern(self, tick_seconds):
        change = self.governor.judge(tick_seconds)
        if change == 'drop':
            self.get_logger().warning(
                f'ticks overrun the {self.period * 1e3:.1f} ms period: simulating up to level '
                f'{self.governor.cap}', throttle_duration_sec=1.0)
        elif change == 'restore':
            self.get_logger().info(f'headroom again: simulating up to level '
                                   f'{self.governor.cap}')

    def _log(self, severity, text):
        """
        Log a unit's message: warnings and errors throttled (they can come every tick).

        One call site per severity: rclpy keys a throttled log by its call site and raises
        when one site logs at two severities (a wrong frame then a NaN pose killed the node).
        """
        if severity == 'info':
            self.get_logger().info(text)
        elif severity == 'warning':
            self.get_logger().warning(text, throttle_duration_sec=1.0)
        else:
            self.get_logger().error(text, throttle_duration_sec=1.0)

    def _held_points(self, k):
        kind = self.control.holds(k).kind.ravel()
        pts = self.state.points(k)
        return {'pins': pts[kind == PINNED], 'grasps': pts[kind > PINNED]}

    def _delete_markers(self):
        """Delete the LOD and scene markers: RViz keeps a marker of lifetime 0 for good."""
        self.publisher.delete_marker(sim_stamp(self.state.time))
        delete_all = Marker(action=Marker.DELETEALL)
        delete_all.header.frame_id = self.frame_id
        self._scene_publisher.publish(MarkerArray(markers=[delete_all]))
        # the process exits next: wait (briefly) until the subscribers have them, or a
        # loaded machine's DDS drops them with the process (a CI run lost the DELETE)
        for publisher in (self.publisher.marker_publisher, self._scene_publisher):
            publisher.wait_for_all_acked(Duration(seconds=DELETE_ACK_WAIT))

    def destroy_node(self):
        # also called by the context's shutdown on a node whose __init__ was interrupted
        # (Ctrl-C during warm-up): only what exists is reported and closed
        if getattr(self, '_sender', None) is not None:
            self._sender.close()
            self._sender = None
        if getattr(self, '_scene_publisher', None) is not None and self.context.ok():
            self._delete_markers()
        if getattr(self, 'bag', None) is not None:
            with self._bag_lock:    # a send the thread gave up waiting for may still write
                self._close_bag()
        if getattr(self, 'stats', None) is not None and self.stats.count:
            self.get_logger().info(f'tick stats {json.dumps(self.stats.summary())}')
        if getattr(self, 'recorder', None) is not None:
            self.recorder.close()
            self.recorder = None
        super().destroy_node()


def _changes_scene(changes):
    """Whether a batch of parameter changes touches the static obstacles."""
    return any(p.name in params.PARAM_BY_NAME and p.name.startswith('scene.') for p in changes)


def main(args=None):
    # numba picks its threading layer (OpenMP here). OpenMP once crashed on an early
    # Ctrl-C (1 in 12 starts, under rclpy's signal handlers); with the stop flag of
    # lifetime, 0 crashes in about 220 interrupted starts (tools/interrupt_stress.py),
    # while the workqueue layer costs 2-4x the step at one thread (16k-point node
    # benchmark: tick p99 16.0 ms against 7.7 ms). NUMBA_THREADING_LAYER chooses another.
    return lifetime.run(ClothSimNode, args)


if __name__ == '__main__':
    sys.exit(main())
