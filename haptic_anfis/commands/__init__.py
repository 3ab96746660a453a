"""Sub-commands of ``haptic-anfis`` (one module each; see :mod:`haptic_anfis.cli`)."""
