"""ROS 2 nodes: thin wiring of the pure core (:mod:`haptic_anfis.device`, ``contact``, ``anfis``)
to topics, services and parameters. Each module holds one small node class and a ``main(args=None)``
entry (a console script, ``ros2 run haptic_anfis <name>``); ``haptic-anfis sim`` runs them all in
one process. Topic, message and parameter reference: the README's node table and
:mod:`haptic_anfis.interfaces`.
"""

__all__: list[str] = []  # a package of modules, imported by name (haptic_anfis.nodes.<module>)
