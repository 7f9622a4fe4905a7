"""Test support for the pitching-wing rig (not needed to run it): ``processes`` (graph
processes started and stopped with bounded waits, one DDS domain per test), ``netlab`` (a lab
of hosts inside one Linux machine), and ``talker`` and ``listener`` (two nodes to check a
graph, the transport and the launcher; their classes in ``demo_nodes``)."""
