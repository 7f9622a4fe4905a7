"""The talker node: ``count`` numbered messages (JointState, or a 49-tap PointCloud2) at
``rate_hz`` (0 = as fast as the transport takes), once ``wait_for_subscribers`` matched; then
it lingers ``linger_s`` and exits with ``exit_code`` (demo_nodes.TalkerNode)."""

import sys

from rig_runtime.node_main import run_node

from .demo_nodes import TALKER_PARAMETERS, TalkerNode

PARAMETERS = TALKER_PARAMETERS


def main(argv: list[str] | None = None) -> int:
    return run_node(TalkerNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
