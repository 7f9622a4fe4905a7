"""The listener node: counts the talker's messages, checks their order and writes a JSON
summary to ``result_file`` when it stops (demo_nodes.ListenerNode)."""

import sys

from rig_runtime.node_main import run_node

from .demo_nodes import LISTENER_PARAMETERS, ListenerNode

PARAMETERS = LISTENER_PARAMETERS


def main(argv: list[str] | None = None) -> int:
    return run_node(ListenerNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
