"""
The ``sim_node`` executable: imports the node, then runs it.

Importing the node takes up to a second or more (numba, rclpy, numpy). A stop signal in
that time ends the process at once with the shell's code (128 + the signal: 130 for a
Ctrl-C, 143 for SIGTERM): nothing is open yet, so there is nothing to finish. Python's own
Ctrl-C handling was not enough: its KeyboardInterrupt printed a traceback from inside
some library's import, and a process started with SIGINT ignored (a background job of a
non-interactive shell, ``nohup``) keeps ignoring it until a handler is installed, so a
Ctrl-C in the first 0.3-0.4 s was lost and the node ran on (2 of 167 signalled starts of
the stress suite run in the background; every start signalled at 0.3 s in that setting).
From :func:`hcloth_ros.lifetime.run` on, the node's own handlers take over.
"""

import os
import signal
import sys

INTERRUPTED = 128 + signal.SIGINT


def _exit_now(signum, frame):
    os._exit(128 + signum)


def main(args=None):
    """Import and run the node; a stop signal before its handlers are in place exits at once."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _exit_now)
    from hcloth_ros import node
    return node.main(args)


if __name__ == '__main__':
    sys.exit(main())
