"""
Signals at the edges of a node's life: during its imports, and a second stop signal.

Each in a process of its own (a signal handler that exits would end pytest).
"""

import os
import signal
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.slow

SECOND_SIGNAL = """
import os, signal, sys, time
from hcloth_ros import lifetime
lifetime.install_signal_handlers()
os.kill(os.getpid(), signal.SIGINT)        # the first asks the node to stop ...
assert lifetime.STOP.is_set()
print('first seen', flush=True)
os.kill(os.getpid(), signal.SIGTERM)       # ... the second, while it stops, ends it
time.sleep(5)
print('still alive', flush=True)
"""


def test_a_second_stop_signal_ends_the_process_at_once():
    done = subprocess.run([sys.executable, '-c', SECOND_SIGNAL], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 128 + signal.SIGTERM
    assert done.stdout == 'first seen\n'
    assert 'second stop signal' in done.stderr and 'Traceback' not in done.stderr


def test_ctrl_c_during_the_imports_exits_quietly_with_130():
    # the executable's first work is importing numba, rclpy and the node: 0.5 s in it is
    # still importing (about 1 s here); without the entry point's guard this printed a
    # KeyboardInterrupt traceback from inside some library
    exe = os.path.join(sys.prefix, 'bin', 'sim_node')
    outcomes = []
    for delay in (0.2, 0.35, 0.5):
        proc = subprocess.Popen([exe], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        assert 'Traceback' not in err, err
        outcomes.append(proc.returncode)
    # 130 while importing; 0 if the node's handlers were already in place
    assert set(outcomes) <= {130, 0} and 130 in outcomes


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_stop_signal_during_the_imports_is_not_lost_when_the_parent_ignored_it(signum):
    """
    A background job of a non-interactive shell starts with SIGINT ignored.

    Python keeps it ignored until someone installs a handler: a Ctrl-C in the imports was
    lost and the node ran on (every start signalled at 0.3 s). The entry point's handler
    ends the process at once, with the shell's code.
    """
    exe = os.path.join(sys.prefix, 'bin', 'sim_node')

    def ignore_stops():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    proc = subprocess.Popen([exe], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=ignore_stops)
    time.sleep(0.2)
    proc.send_signal(signum)
    try:
        proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail('the signal was lost: the node ran on')
    assert proc.returncode == 128 + signum
