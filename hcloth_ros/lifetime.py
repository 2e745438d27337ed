"""
Process lifetime of a node: signals, the spin loop, a clean stop.

Ctrl-C and SIGTERM only set a flag that the spin loop checks, at any moment from the
start of :func:`run`: an exception raised from a signal handler lands in whatever code
runs at that moment, and a handler that swallows it there (seen: Ctrl-C during start-up
lost in 9 of 140 starts, the node then ran on) loses the stop request. The node then
stops with its context still valid, so its last words (tick statistics, the end of the
recording) go out through a live node; rclpy's own handlers shut the context down first
("publisher's context is invalid").
"""

import faulthandler
import os
import re
import signal
import sys
import threading

import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.signals import SignalHandlerOptions
import yaml

STOP = threading.Event()
BAD_CONFIGURATION = 2   # exit code of a start refused for its parameters (as argparse's)


class StartupError(Exception):
    """A node cannot start as configured: ``lines`` say why, one problem each."""

    def __init__(self, lines):
        super().__init__('; '.join(lines))
        self.lines = list(lines)


def _report(lines, name='hcloth_sim'):
    """Write start-up errors in the ROS log format: rclpy's logging may not be up."""
    for line in lines:
        print(f'[ERROR] [{name}]: {line}', file=sys.stderr, flush=True)


def rcl_reason(error):
    """Return rcl's error text without its source locations (``, at /path/file.c:123``)."""
    return re.sub(r',? at \S+:\d+', '', str(error)).strip()


def request_stop(signum=None, frame=None):
    """
    Ask the spin loop to stop (the signal handler); a second signal ends the process.

    The first stop finishes the recording and the bag, which can wait on a disk; whoever
    presses Ctrl-C again wants out now (exit code 128 + the signal, as the shell's).
    """
    if STOP.is_set() and signum is not None:
        os.write(2, b'[WARN] [hcloth_sim]: second stop signal: exiting without finishing '
                    b'the recording\n')
        os._exit(128 + signum)
    STOP.set()


def install_signal_handlers():
    """
    SIGINT and SIGTERM stop the node; ``kill -USR1 <pid>`` prints every thread's stack.

    SIGINT explicitly too: a shell starts background jobs with SIGINT ignored, and Python
    keeps it so.
    """
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, request_stop)
    faulthandler.register(signal.SIGUSR1, all_threads=True)


def unreadable_params_files(argv):
    """
    One line for each ROS argument of ``argv`` rcl would refuse with its own internals.

    A ``--params-file`` that cannot be read as YAML, and lists mixing integers and
    decimal numbers (``[0, 0, 0.5]``) in a params file or a ``-p`` override: rcl wants one
    type per list and says so without naming the parameter.
    """
    from hcloth_ros.node_params import mixed_lists, overrides_in, params_files
    lines = []
    for path in params_files(argv):
        try:
            with open(path) as f:
                doc = yaml.safe_load(f)
        except (OSError, yaml.YAMLError) as e:
            lines.append(f'cannot start: params file {path}: {" ".join(str(e).split())}')
            continue
        lines += [f'cannot start: params file {path}: {line}' for line in mixed_lists(doc)]
    lines += [f'cannot start: -p {line}' for line in mixed_lists(overrides_in(argv))]
    return lines


def run(make_node, args=None, poll=0.1):
    """
    Init rclpy without its signal handlers, build the node, spin until stopped.

    Returns the process's exit code: 0, or :data:`BAD_CONFIGURATION` when rcl refuses
    the arguments (a params file that does not exist or does not parse) or the node
    raises :class:`StartupError`, each reason logged on one line, no traceback.
    """
    install_signal_handlers()
    unreadable = unreadable_params_files(sys.argv if args is None else args)
    if unreadable:      # before rcl, whose own refusal adds a line of its internals
        _report(unreadable)
        return BAD_CONFIGURATION
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except rclpy_implementation.RCLError as e:
        _report([f'cannot start: {rcl_reason(e)}'])
        return BAD_CONFIGURATION
    node = None
    code = 0
    try:
        node = make_node()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not STOP.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=poll)
    except StartupError as e:
        _report(e.lines)
        code = BAD_CONFIGURATION
    except (InvalidParameterTypeException, InvalidParameterValueException) as e:
        # rclpy's own parameters (use_sim_time:=1) are declared before the node's checks
        _report([f'cannot start: {" ".join(str(e).split())}'])
        code = BAD_CONFIGURATION
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
