"""
Node benchmark: sim_node and a subscriber in separate processes, per-tick breakdown.

    python -m hcloth_ros.bench.node [--sizes 16k,65k] [--seconds 10] [--rate 60]
                                    [-p solver.accurate_level:=3 ...]

For each size the node runs the default hanging scene (level 0 9 x 9; 4 levels = 65 x 65 =
4,225 points, 5 levels = 129 x 129
= 16,641 points, 6 levels = 257 x 257 = 66,049) at ``--rate`` Hz with the Fast DDS
profile for large clouds in both processes, while a second process subscribes to
``cloth/points``. When the node stops it logs its tick statistics (p50/p99 of the solver
step, message packing, publishing, recording and the whole tick, the real-time factor and
the levels simulated); this script prints them with the subscriber's receive rate, over
every tick and over the ticks that simulated the most levels seen (the node runs fewer
before the subscriber connects and after its governor sheds levels: the count says how
many, the level count which).

    python -m hcloth_ros.bench.node --sizes '' --first-start 3

First start: a subscriber waits for ``cloth/points``, then ``sim_node`` starts on the
default scene with an empty numba cache (a temporary ``NUMBA_CACHE_DIR``); the figure is
the time from starting the node's process to the first cloud the subscriber receives
(imports, compiling the kernels, building the cloth, the first tick), ``--first-start``
times, then once more with the cache the last run filled.
"""

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import time

SIZES = {'4k': 4, '16k': 5, '65k': 6}

# A subscriber to cloth/points in its own process: `rate SECONDS` counts the clouds for
# that long and prints how many and how often; `first SECONDS` says 'ready', then prints
# the monotonic time of the first cloud (-1 if none came).
SUBSCRIBER = """
import sys, time, rclpy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2
mode, seconds = sys.argv[1], float(sys.argv[2])
rclpy.init()
node = rclpy.create_node('bench_subscriber')
got = []
node.create_subscription(PointCloud2, 'cloth/points', lambda m: got.append(time.monotonic()),
                         qos_profile_sensor_data)
print('ready', flush=True)
end = time.monotonic() + seconds
while time.monotonic() < end and not (mode == 'first' and got):
    rclpy.spin_once(node, timeout_sec=0.02)
if mode == 'first':
    print('first', got[0] if got else -1.0, flush=True)
else:
    span = got[-1] - got[0] if len(got) > 1 else 0.0
    print(f'received {len(got)} {(len(got) - 1) / span if span else 0.0:.2f}')
"""


def first_start(cache, timeout=600.0):
    """
    Return seconds from starting sim_node to the first cloud a subscriber receives.

    ``cache`` is the ``NUMBA_CACHE_DIR`` the node uses; also returns the node's log.
    """
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(100, 200)),
               PYTHONUNBUFFERED='1', NUMBA_CACHE_DIR=cache)
    probe = subprocess.Popen([sys.executable, '-c', SUBSCRIBER, 'first', str(timeout)], env=env,
                             stdout=subprocess.PIPE, text=True)
    if probe.stdout.readline().strip() != 'ready':
        raise RuntimeError('the probe subscriber did not start')
    start = time.monotonic()    # CLOCK_MONOTONIC: the same clock in both processes
    node = subprocess.Popen([sys.executable, '-m', 'hcloth_ros.node'], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    first = float(probe.stdout.readline().split()[1])
    node.send_signal(signal.SIGINT)
    log, _ = node.communicate(timeout=60)
    probe.wait(timeout=10)
    if first < 0:
        raise RuntimeError(f'no cloud within {timeout} s:\n{log}')
    return first - start, log


def run(levels, seconds, rate, record, extra=()):
    from hcloth_ros.params import config_path
    profile = config_path('fastdds_large_clouds.xml')
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(100, 200)),
               FASTDDS_DEFAULT_PROFILES_FILE=profile, PYTHONUNBUFFERED='1')
    # the node paces itself by its real-time factor: ``rate`` ticks of dt a second
    dt = next((float(a.split(':=')[1]) for a in extra if a.startswith('solver.dt:=')), 1 / 60)
    args = [sys.executable, '-m', 'hcloth_ros.node', '--ros-args', '-p',
            f'cloth.levels:={levels}', '-p', f'real_time_factor:={rate * dt!r}']
    for assignment in extra:
        args += ['-p', assignment]
    if record:
        args += ['-p', f'rerun_path:=/tmp/hcloth_bench_{levels}.rrd', '-p',
                 'rerun_finest_every:=10']
    node = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    time.sleep(3.0)     # kernels load from the cache, node starts
    sub = subprocess.run([sys.executable, '-c', SUBSCRIBER, 'rate', str(seconds)], env=env,
                         capture_output=True, text=True, timeout=seconds + 60)
    node.send_signal(signal.SIGINT)
    out, _ = node.communicate(timeout=30)
    stats = None
    for line in out.splitlines():
        if 'tick stats ' in line:
            stats = json.loads(line.split('tick stats ', 1)[1])
    if stats is None:
        raise RuntimeError(f'node gave no tick stats:\n{out}')
    received = sub.stdout.split('\n', 1)[1].split()
    stats['received'] = int(received[1])
    stats['receive_hz'] = float(received[2])
    return stats


def first_starts(repeats):
    """Time ``repeats`` first starts on empty caches, then one on the filled cache."""
    import tempfile
    cold = []
    for i in range(repeats):
        with tempfile.TemporaryDirectory(prefix='hcloth_first_start_') as cache:
            seconds, log = first_start(cache)
            cold.append(seconds)
            print(f'first start {i + 1}/{repeats} (empty cache): first cloud after '
                  f'{seconds:.1f} s', flush=True)
            if i == repeats - 1:
                warm, _ = first_start(cache)
                print(f'start with the filled cache: first cloud after {warm:.1f} s',
                      flush=True)
    notice = [line for line in log.splitlines() if 'preparing' in line or 'ready in' in line]
    print('\n'.join(f'    {line}' for line in notice), flush=True)
    return {'cold_s': cold, 'warm_s': warm, 'log': notice}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', default='16k,65k')
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=60.0,
                        help='ticks a second (the node runs at real_time_factor rate x dt)')
    parser.add_argument('--record', action='store_true', help='also record to /tmp/*.rrd')
    parser.add_argument('--first-start', type=int, default=0, metavar='N',
                        help='also time N first starts on an empty numba cache')
    parser.add_argument('--json', metavar='PATH')
    parser.add_argument('-p', '--param', action='append', default=[], metavar='NAME:=VALUE',
                        help='a node parameter for every size (repeatable), e.g. '
                             'solver.accurate_level:=3')
    args = parser.parse_args(argv)
    import numba
    print(f'node benchmark: {args.rate:g} Hz, {args.seconds:g} s a size, numba '
          f'{numba.__version__} (node default numba_threads = 1), load average '
          f'{os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs', flush=True)
    results = {}
    for size in filter(None, args.sizes.split(',')):
        levels = SIZES[size]
        print(f'{size}: running ...', flush=True)
        s = results[size] = run(levels, args.seconds, args.rate, args.record, args.param)
        print(f'{size}: {s["ticks"]} ticks, levels {s["levels_min"]}..{s["levels_max"]}, '
              f'real-time factor {s["real_time_factor"]:.3f}, subscriber received '
              f'{s["received"]} at {s["receive_hz"]:.1f} Hz', flush=True)
        top = s['top_levels']
        print(f'    {"":8s} every tick                     the {top["ticks"]} ticks at '
              f'{s["levels_max"]} levels')
        for phase in ('step', 'pack', 'publish', 'send', 'record', 'tick'):
            print(f'    {phase:8s} p50 {s[phase]["p50"]:7.3f} ms   p99 {s[phase]["p99"]:7.3f} ms'
                  f'   p50 {top[phase]["p50"]:7.3f} ms   p99 {top[phase]["p99"]:7.3f} ms')
    if args.first_start:
        results['first_start'] = first_starts(args.first_start)
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
