"""
Soak: sim_node for minutes with a subscriber, a recording and a gripper cycling.

    hcloth_soak [--minutes 10] [--cycle 4]

Starts the node (default scene, recording to a temporary .rrd), subscribes to
``cloth/points`` and ``/diagnostics`` in this process and, every ``--cycle`` seconds,
makes gripper ``left`` grasp the free corner, lift it 0.2 m and let go. Every 5 s it
reads the node's resident memory (``VmRSS``); each second ``/diagnostics`` gives the
tick p99 of that second. Printed per minute: resident memory, the median over the
minute of the per-second tick p99, clouds received, the recording's size. The verdict
(issue 12): resident memory grows by under 5 % from the end of the second minute to the
end, and the last minute's tick p99 is within 20 % of the second minute's.
"""

import argparse
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from hcloth_ros.bench.stress import ros_env, sim_node
import rclpy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Bool

CORNER = (-0.5, 1.0, 1.5)     # the default scene's free corner (its pins are at y = 0)


def rss_mb(pid):
    """Return a process's resident memory (MB) from /proc, None once it is gone."""
    try:
        with open(f'/proc/{pid}/status') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) / 1024
    except OSError:
        return None


class Client:
    """This process's ROS side: clouds and diagnostics counted, the gripper driven."""

    def __init__(self):
        self.node = rclpy.create_node('hcloth_soak')
        self.clouds, self.p99 = 0, []       # per-second tick p99 (ms) with its time
        self.node.create_subscription(PointCloud2, 'cloth/points', self._cloud,
                                      qos_profile_sensor_data)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._diagnostics, 10)
        self.pose = self.node.create_publisher(PoseStamped, 'cloth/grippers/left/pose', 10)
        self.close = self.node.create_publisher(Bool, 'cloth/grippers/left/close', 10)

    def _cloud(self, msg):
        self.clouds += 1

    def _diagnostics(self, msg):
        values = {kv.key: kv.value for kv in msg.status[0].values}
        if 'tick_p99_ms' in values:
            self.p99.append((time.monotonic(), float(values['tick_p99_ms'])))

    def gripper(self, phase, lift):
        """Send the gripper's pose (and at the phase's start, its close command)."""
        msg = PoseStamped()
        msg.header.frame_id = 'world'
        msg.pose.position.x, msg.pose.position.y = CORNER[0], CORNER[1] * 0.6
        msg.pose.position.z = 1.0 + lift
        msg.pose.orientation.w = 1.0
        self.pose.publish(msg)
        if phase is not None:
            self.close.publish(Bool(data=phase))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=10.0)
    parser.add_argument('--cycle', type=float, default=4.0, help='s a grasp, lift, release')
    opts = parser.parse_args(argv)
    work = tempfile.mkdtemp(prefix='hcloth_soak_')
    rrd = os.path.join(work, 'soak.rrd')
    env = ros_env(random.randint(100, 200))
    os.environ.update(env)      # this process's rclpy joins the same domain
    node = subprocess.Popen(sim_node(rrd), env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    rclpy.init()
    client = Client()
    rows, samples = [], []
    try:
        end_wait = time.monotonic() + 300      # a first start compiles the kernels
        while client.clouds == 0 and time.monotonic() < end_wait:
            rclpy.spin_once(client.node, timeout_sec=0.1)
        start = time.monotonic()
        next_sample, minute = start, 1
        while minute <= opts.minutes and node.poll() is None:
            t = time.monotonic() - start
            phase_t = t % opts.cycle
            closing = None
            if phase_t < 0.1:
                closing = True
            elif abs(phase_t - 0.75 * opts.cycle) < 0.05:
                closing = False
            client.gripper(closing, 0.2 * min(phase_t / (0.5 * opts.cycle), 1.0))
            rclpy.spin_once(client.node, timeout_sec=0.05)
            if time.monotonic() >= next_sample:
                samples.append((t, rss_mb(node.pid)))
                next_sample += 5.0
            if t >= 60 * minute:
                rows.append(_minute(minute, client, samples, start, rrd))
                print(_line(rows[-1]), flush=True)
                minute += 1
    finally:
        client.node.destroy_node()
        rclpy.try_shutdown()
        node.send_signal(signal.SIGINT)
        try:
            code = node.wait(timeout=20)
        except subprocess.TimeoutExpired:
            node.kill()
            code = 'killed'
    print(f'node exit code {code}')
    return _verdict(rows)


def _minute(minute, client, samples, start, rrd):
    """Return one minute's figures."""
    since = start + 60 * (minute - 1)
    p99 = [v for when, v in client.p99 if since <= when < since + 60]
    return {'minute': minute, 'rss_mb': samples[-1][1],
            'tick_p99_ms': statistics.median(p99) if p99 else float('nan'),
            'clouds': client.clouds,
            'rrd_mb': os.path.getsize(rrd) / 1e6 if os.path.exists(rrd) else 0.0}


def _line(row):
    return (f'minute {row["minute"]:3d}: resident {row["rss_mb"]:.1f} MB, tick p99 (median '
            f'of the seconds) {row["tick_p99_ms"]:.2f} ms, clouds {row["clouds"]}, '
            f'recording {row["rrd_mb"]:.1f} MB')


def _verdict(rows):
    """Print and return (0 pass, 1 fail) the soak's verdict from minute 2 to the end."""
    if len(rows) < 3:
        print('too short for a verdict (3 minutes at least)')
        return 1
    second, last = rows[1], rows[-1]
    growth = last['rss_mb'] / second['rss_mb'] - 1
    drift = last['tick_p99_ms'] / second['tick_p99_ms'] - 1
    ok = growth < 0.05 and abs(drift) <= 0.20
    print(f'resident memory {second["rss_mb"]:.1f} -> {last["rss_mb"]:.1f} MB ({growth:+.1%}, '
          f'limit +5 %); tick p99 {second["tick_p99_ms"]:.2f} -> {last["tick_p99_ms"]:.2f} ms '
          f'({drift:+.1%}, limit 20 %): {"PASS" if ok else "FAIL"}')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
