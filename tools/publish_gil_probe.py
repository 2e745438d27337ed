"""
How long publishing a 257 x 257 cloud keeps another Python thread of the process waiting.

The node sends its cloud from a thread of its own while the next step runs; the step's
kernels release the GIL, the Python between them needs it and a core. This probe
publishes a 786 KB PointCloud2 (66,049 float32 points) from one thread every 4 ms for 3 s
while the main thread runs a Python loop, and reports the loop's gaps longer than 0.5 ms:
time the main thread could not run Python, waiting for the GIL or for a core. Run it with
and without a subscriber to tell the two apart (the README's figures: 0.6-1.4 ms a send
with one on the same two cores, 0.02-0.06 ms without). The subscriber, with the same Fast
DDS profile in both processes:

    export FASTDDS_DEFAULT_PROFILES_FILE=$(.venv/bin/python -c "from hcloth_ros.params
    import config_path; print(config_path('fastdds_large_clouds.xml'))")
    .venv/bin/python -c "from hcloth_ros.bench.node import SUBSCRIBER; exec(SUBSCRIBER)"
    rate 10 &
    .venv/bin/python tools/publish_gil_probe.py

(each command on one line).
"""

import threading
import time

from builtin_interfaces.msg import Time
from hcloth_ros.ros_msgs import pointcloud2
import numpy as np
import rclpy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2

POINTS = 257 * 257


def main(seconds=3.0):
    rclpy.init()
    node = rclpy.create_node('publish_gil_probe')
    publisher = node.create_publisher(PointCloud2, 'cloth/points', qos_profile_sensor_data)
    msg = pointcloud2(np.random.default_rng(0).random((POINTS, 3)), 'world', Time())
    sends, stop = [], threading.Event()

    def sender():
        while not stop.is_set():
            start = time.perf_counter()
            publisher.publish(msg)
            sends.append(time.perf_counter() - start)
            time.sleep(0.004)

    thread = threading.Thread(target=sender)
    thread.start()
    gaps = []
    last = time.perf_counter()
    end = last + seconds
    while last < end:
        now = time.perf_counter()
        gaps.append(now - last)
        last = now
    stop.set()
    thread.join()
    node.destroy_node()
    rclpy.shutdown()
    gaps = np.array(gaps) * 1e3
    long = gaps[gaps > 0.5]
    print(f'{len(sends)} sends of {POINTS * 12 / 1024:.0f} KB, median '
          f'{np.median(sends) * 1e3:.2f} ms; the Python loop waited {long.size} times over '
          f'0.5 ms, {long.sum():.0f} ms in all ({long.sum() / len(sends):.2f} ms a send), '
          f'longest {gaps.max():.2f} ms')


if __name__ == '__main__':
    main()
