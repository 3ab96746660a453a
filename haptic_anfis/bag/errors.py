"""The one error a bad bag raises (a ValueError: the CLI prints it as a one-line error)."""
from __future__ import annotations
from ..errors import HapticAnfisError


class BagError(HapticAnfisError, ValueError):
    """A bag that cannot be read, written or used as asked; the message names the path and what
    was expected."""
