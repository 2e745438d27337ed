"""
What the node publishes after a tick: the finest cloud and the LOD marker.

Needs message types but no ROS graph: the publishers are passed in (anything with
``publish`` and, for the cloud, ``get_subscription_count``), so it is tested with fakes.
:class:`PublishThread` sends a tick's messages from a thread of its own, so the timer's
thread goes back to stepping while the middleware copies and sends them.
"""

import threading
import time

from hcloth_ros.ros_msgs import pointcloud2, TriangleMarker
from visualization_msgs.msg import Marker


class ClothPublisher:
    """
    Packs and publishes ``cloth/points`` and ``cloth/lod_marker``.

    The cloud (the finest simulated level, point-id order) is built only while someone
    subscribes; the marker of each level is kept serialised between ticks and sent as
    bytes (:class:`~hcloth_ros.ros_msgs.TriangleMarker`).
    """

    def __init__(self, model, frame_id, cloud_publisher, marker_publisher, ns='hcloth_lod'):
        self.model = model
        self.frame_id = frame_id
        self.cloud_publisher = cloud_publisher
        self.marker_publisher = marker_publisher
        self.ns = ns
        self._markers = {}      # level -> TriangleMarker, built on first use
        self._cloud_points = None   # float32 buffer of the last cloud's points
        self.always_cloud = False   # pack the cloud with no subscriber (a bag records it)

    def cloud_wanted(self):
        return self.always_cloud or self.cloud_publisher.get_subscription_count() > 0

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

    def delete_marker(self, stamp):
        """Publish the DELETE of the LOD marker (RViz keeps a marker of lifetime 0)."""
        msg = Marker(ns=self.ns, id=0, action=Marker.DELETE)
        msg.header.frame_id = self.frame_id
        msg.header.stamp = stamp
        self.marker_publisher.publish(msg)


class PublishThread:
    """
    Sends each tick's messages from a thread of its own, one tick in flight at most.

    ``send`` is called with what :meth:`submit` was given, in that thread. A 257 x 257
    cloud costs the middleware 1-4 ms to copy and send; off the timer's thread that time
    overlaps the next step's kernels (they release the GIL) instead of adding to the tick.
    The node waits (:meth:`wait`) for the last tick's messages to be sent before packing
    the next ones: a publisher slower than the timer slows the tick (where it shows)
    instead of dropping messages.
    """

    def __init__(self, send, on_error=None):
        self._send = send
        self._on_error = on_error
        self._ready = threading.Condition()
        self._pending = None        # messages submitted and not yet taken by the thread
        self._busy = False          # the thread is sending
        self._closed = False
        self.sent = 0               # sends finished (whether or not the middleware failed)
        self.last_seconds = 0.0     # how long the last send took (s)
        self._thread = threading.Thread(target=self._run, name='hcloth_publish', daemon=True)
        self._thread.start()

    def submit(self, *messages):
        """
        Hand one tick's messages to the thread; returns whether it took them.

        Refused (False) after :meth:`close` and while the last messages are not sent yet
        (call :meth:`wait` first): a submission never replaces one that is pending.
        """
        with self._ready:
            if self._closed or self._pending is not None or self._busy:
                return False
            self._pending = messages
            self._ready.notify_all()
            return True

    def wait(self, timeout=None):
        """Block until everything submitted has been sent; returns whether it was."""
        with self._ready:
            return self._ready.wait_for(lambda: self._pending is None and not self._busy,
                                        timeout)

    def close(self, timeout=2.0):
        """Send what is pending, then stop the thread (it is a daemon: never blocks exit)."""
        with self._ready:
            self._closed = True
            self._ready.notify_all()
        self._thread.join(timeout)

    def _run(self):
        while True:
            with self._ready:
                self._ready.wait_for(lambda: self._pending is not None or self._closed)
                if self._pending is None:
                    return      # closed, nothing left
                messages, self._pending, self._busy = self._pending, None, True
            start = time.perf_counter()
            try:
                self._send(*messages)
            except BaseException as e:     # the thread must outlive any failure
                self._report(e)
            finally:
                self.last_seconds = time.perf_counter() - start
                with self._ready:
                    self.sent += 1
                    self._busy = False
                    self._ready.notify_all()

    def _report(self, error):
        """Pass a failed send to ``on_error``; a failing handler does not stop the thread."""
        if self._on_error is None:
            return
        try:
            self._on_error(error)
        except BaseException:      # e.g. logging after the context shut down
            pass
