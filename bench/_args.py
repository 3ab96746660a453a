"""Command-line argument types the bench scripts share (argparse ``type=`` callables)."""
from __future__ import annotations

import argparse
import math

__all__ = ['positive_numbers']


def positive_numbers(text: str) -> list[float]:
    """A comma-separated list of finite numbers > 0, such as ``50,150,250`` (argparse type)."""
    try:
        values = [float(v) for v in text.split(',')]
    except ValueError:
        values = []
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(
            f'{text!r}: expected comma-separated numbers > 0, such as 50,150,250')
    return values
