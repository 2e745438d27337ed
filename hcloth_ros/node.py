"""``sim_node``: the cloth simulation as a ROS 2 node (default name ``hcloth_sim``).

Steps the engine on a timer at ``rate_hz`` and after every tick publishes

* ``cloth/points`` (``sensor_msgs/PointCloud2``, best effort): the finest simulated level,
  float32 ``x y z``, in point-id order (so the first ``n_k`` points are level k);
* ``cloth/lod_marker`` (``visualization_msgs/Marker``, ``TRIANGLE_LIST``): level
  ``lod_level``, changeable at runtime.

``cloth/reset`` (``std_srvs/Trigger``) returns the cloth to its initial state.
``pinned_points`` may be changed at runtime; scene and cloth parameters are read-only.
"""

import rclpy
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

from hcloth_ros import params
from hcloth_ros.core import warm_up
from hcloth_ros.ros_msgs import pointcloud2, triangle_marker

NODE_PARAMS = [
    params.Param('rate_hz', 60.0, 'timer rate: steps and publications per second (Hz)',
                 1.0, 1000.0),
    params.Param('frame_id', 'world', 'frame of every published position'),
    params.Param('lod_level', 1, 'level published as cloth/lod_marker (0 = coarsest)', 0, 9,
                 False),
]


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


class ClothSimNode(Node):
    """The simulation node; see the module docstring for its interface."""

    def __init__(self, **kwargs):
        super().__init__('hcloth_sim', **kwargs)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        for spec in params.PARAMS + NODE_PARAMS:
            self.declare_parameter(spec.name, spec.default, _descriptor(spec))
        values = params.resolve({spec.name: self.get_parameter(spec.name).value
                                 for spec in params.PARAMS})
        self.model, self.solver, self.state, self.control = params.build_all(values)
        self.initial = self.state.copy()
        self.dt = float(values['solver.dt'])
        self.substeps = int(values['solver.substeps'])
        self.frame_id = self.get_parameter('frame_id').value
        self.lod_level = min(self.get_parameter('lod_level').value,
                             self.model.level_count - 1)
        self.get_logger().info(f'numba kernels ready in {warm_up():.2f} s')
        self.cloud_pub = self.create_publisher(PointCloud2, 'cloth/points',
                                               qos_profile_sensor_data)
        self.marker_pub = self.create_publisher(Marker, 'cloth/lod_marker', 10)
        self.create_service(Trigger, 'cloth/reset', self._on_reset)
        self.timer = self.create_timer(1.0 / self.get_parameter('rate_hz').value, self._tick)
        lv = self.model.level(self.model.level_count - 1)
        self.get_logger().info(
            f'{self.solver.name} cloth, {self.model.level_count} levels, finest '
            f'{lv.rows}x{lv.cols}, dt {self.dt * 1e3:.2f} ms x {self.substeps} per tick')

    # --- parameters and services -------------------------------------------------------
    def _on_set_parameters(self, changes):
        if not hasattr(self, 'model'):
            return SetParametersResult(successful=True)     # initial declaration
        for p in changes:
            if p.name == 'lod_level' and not 0 <= p.value < self.model.level_count:
                return SetParametersResult(
                    successful=False,
                    reason=f'lod_level {p.value} out of range 0..{self.model.level_count - 1}')
            if p.name == 'pinned_points':
                try:
                    self.control.set_pins(params.pin_ids(p.value))
                except (IndexError, ValueError) as e:
                    return SetParametersResult(successful=False, reason=str(e))
        for p in changes:
            if p.name == 'lod_level':
                self.lod_level = p.value
        return SetParametersResult(successful=True)

    def _on_reset(self, request, response):
        self.state.assign(self.initial)
        self.control.release_all()
        response.success = True
        response.message = 'cloth reset to its initial state, every grasp released'
        return response

    # --- the timer -----------------------------------------------------------------------
    def _tick(self):
        for _ in range(self.substeps):
            report = self.solver.step(self.state, self.control, self.dt)
            if not report.ok:
                self.get_logger().error(report.reason, throttle_duration_sec=1.0)
                break
        stamp = self.get_clock().now().to_msg()
        finest = self.solver.levels()[-1]
        self.cloud_pub.publish(pointcloud2(self.state.points_by_id(self.model, finest),
                                           self.frame_id, stamp))
        k = self.lod_level
        self.marker_pub.publish(triangle_marker(self.state.points(k),
                                                self.model.grid_triangles(k), self.frame_id,
                                                stamp, ns='hcloth_lod', marker_id=0))


def main(args=None):
    rclpy.init(args=args)
    node = None
    try:
        node = ClothSimNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
