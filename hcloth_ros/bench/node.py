"""
Node benchmark: sim_node and a subscriber in separate processes, per-tick breakdown.

    python -m hcloth_ros.bench.node [--sizes 16k,65k] [--seconds 10] [--rate 60]

For each size the node runs the default hanging scene (level 0 9 x 9; 5 levels = 129 x 129
= 16,641 points, 6 levels = 257 x 257 = 66,049) at ``--rate`` Hz with the Fast DDS
profile for large clouds in both processes, while a second process subscribes to
``cloth/points``. When the node stops it logs its tick statistics (p50/p99 of the solver
step, message packing, publishing, recording and the whole tick, the real-time factor and
the levels simulated); this script prints them with the subscriber's receive rate.
"""

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import time

SIZES = {'16k': 5, '65k': 6}

SUBSCRIBER = """
import sys, time, rclpy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2
rclpy.init()
node = rclpy.create_node('bench_subscriber')
got = []
node.create_subscription(PointCloud2, 'cloth/points', lambda m: got.append(time.monotonic()),
                         qos_profile_sensor_data)
end = time.monotonic() + float(sys.argv[1])
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
span = got[-1] - got[0] if len(got) > 1 else 0.0
print(f'received {len(got)} {(len(got) - 1) / span if span else 0.0:.2f}')
"""


def run(levels, seconds, rate, record):
    from hcloth_ros.params import config_path
    profile = config_path('fastdds_large_clouds.xml')
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(100, 200)),
               FASTDDS_DEFAULT_PROFILES_FILE=profile, PYTHONUNBUFFERED='1')
    args = [sys.executable, '-m', 'hcloth_ros.node', '--ros-args', '-p',
            f'cloth.levels:={levels}', '-p', f'rate_hz:={float(rate)}']
    if record:
        args += ['-p', f'rerun_path:=/tmp/hcloth_bench_{levels}.rrd', '-p',
                 'rerun_finest_every:=10']
    node = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    time.sleep(3.0)     # kernels load from the cache, node starts
    sub = subprocess.run([sys.executable, '-c', SUBSCRIBER, str(seconds)], env=env,
                         capture_output=True, text=True, timeout=seconds + 60)
    node.send_signal(signal.SIGINT)
    out, _ = node.communicate(timeout=30)
    stats = None
    for line in out.splitlines():
        if 'tick stats ' in line:
            stats = json.loads(line.split('tick stats ', 1)[1])
    if stats is None:
        raise RuntimeError(f'node gave no tick stats:\n{out}')
    received = sub.stdout.split()
    stats['received'] = int(received[1])
    stats['receive_hz'] = float(received[2])
    return stats


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', default='16k,65k')
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=60.0)
    parser.add_argument('--record', action='store_true', help='also record to /tmp/*.rrd')
    parser.add_argument('--json', metavar='PATH')
    args = parser.parse_args(argv)
    import numba
    print(f'node benchmark: {args.rate:g} Hz, {args.seconds:g} s a size, numba '
          f'{numba.__version__} (node default numba_threads = 1), load average '
          f'{os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs', flush=True)
    results = {}
    for size in args.sizes.split(','):
        levels = SIZES[size]
        print(f'{size}: running ...', flush=True)
        s = results[size] = run(levels, args.seconds, args.rate, args.record)
        print(f'{size}: {s["ticks"]} ticks, levels {s["levels_min"]}..{s["levels_max"]}, '
              f'real-time factor {s["real_time_factor"]:.3f}, subscriber received '
              f'{s["received"]} at {s["receive_hz"]:.1f} Hz', flush=True)
        for phase in ('step', 'pack', 'publish', 'record', 'tick'):
            print(f'    {phase:8s} p50 {s[phase]["p50"]:7.3f} ms   p99 {s[phase]["p99"]:7.3f} ms')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
