"""Sub-commands of ``haptic-anfis`` (one module each; see :mod:`haptic_anfis.cli`)."""

__all__: list[str] = []  # a package of modules, imported by name (haptic_anfis.commands.<module>)
