"""The package's one error base class.

Every error the package raises on purpose for bad input or a failed operation derives from
:class:`HapticAnfisError` (most also from ``ValueError`` or ``OSError``, so existing ``except``
clauses keep working). The ``haptic-anfis`` command catches it once and prints its message as one
line, no traceback.
"""
from __future__ import annotations

__all__ = ['HapticAnfisError']


class HapticAnfisError(Exception):
    """Base of the package's own errors: the message is one line naming the input and what was
    expected."""
