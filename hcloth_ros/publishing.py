"""
What the node publishes after a tick: the finest cloud and the LOD marker.

Needs message types but no ROS graph: the publishers are passed in (anything with
``publish`` and, for the cloud, ``get_subscription_count``), so it is tested with fakes.
"""

from hcloth_ros.ros_msgs import pointcloud2, TriangleMarker


class ClothPublisher:
    """
    Packs and publishes ``cloth/points`` and ``cloth/lod_marker``.

    The cloud (the finest simulated level, point-id order) is built only while someone
    subscribes; the marker of each level keeps its ``Point`` objects between ticks
    (:class:`~hcloth_ros.ros_msgs.TriangleMarker`).
    """

    def __init__(self, model, frame_id, cloud_publisher, marker_publisher, ns='hcloth_lod'):
        self.model = model
        self.frame_id = frame_id
        self.cloud_publisher = cloud_publisher
        self.marker_publisher = marker_publisher
        self.ns = ns
        self._markers = {}      # level -> TriangleMarker, built on first use
        self._cloud_points = None   # float32 buffer of the last cloud's points

    def cloud_wanted(self):
        return self.cloud_publisher.get_subscription_count() > 0

    def pack(self, state, finest, lod, stamp):
        """Return ``(cloud or None, marker)`` of levels ``finest`` and ``lod``."""
        cloud = None
        if self.cloud_wanted():
            self._cloud_points = state.points_by_id_f32(self.model, finest, self._cloud_points)
            cloud = pointcloud2(self._cloud_points, self.frame_id, stamp)
        if lod not in self._markers:
            self._markers[lod] = TriangleMarker(self.model.grid_triangles(lod), self.frame_id,
                                                ns=self.ns, marker_id=0)
        return cloud, self._markers[lod].update(state.points(lod), stamp)

    def publish(self, cloud, marker):
        if cloud is not None:
            self.cloud_publisher.publish(cloud)
        self.marker_publisher.publish(marker)
