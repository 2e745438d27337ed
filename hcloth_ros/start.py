"""
The ``sim_node`` executable: imports the node, then runs it.

Importing the node takes a second or more (numba, rclpy, numpy). A Ctrl-C in that time
raised KeyboardInterrupt inside some library's import and printed its traceback; here it
ends the process quietly with the shell's code for an interrupted command (130), as a
SIGTERM then ends it by its default action. From :func:`hcloth_ros.lifetime.run` on, the
node's own handlers take over.
"""

import signal
import sys

INTERRUPTED = 128 + signal.SIGINT


def main(args=None):
    """Import and run the node; a Ctrl-C before its handlers are in place exits 130."""
    try:
        from hcloth_ros import node
        return node.main(args)
    except KeyboardInterrupt:
        return INTERRUPTED


if __name__ == '__main__':
    sys.exit(main())
