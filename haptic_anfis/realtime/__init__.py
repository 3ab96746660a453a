"""Real-time and OS-process code (no ROS): how the servo threads and the graph's nodes are
scheduled (:mod:`.scheduling`: SCHED_FIFO, RealtimeKit through :mod:`.rtkit`, time slices, tick
workers' cores) and how the nodes run as processes (:mod:`.processes`: start, stop, supervise,
priority and CPU pinning of a node graph)."""

__all__: list[str] = []  # a package of modules, imported by name
