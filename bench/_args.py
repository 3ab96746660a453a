"""Command-line argument types the bench scripts share (argparse ``type=`` callables)."""
from __future__ import annotations

import argparse
import math

__all__ = ['non_negative_numbers', 'positive_numbers']


def positive_numbers(text: str) -> list[float]:
    """A comma-separated list of finite numbers > 0, such as ``50,150,250`` (argparse type)."""
    return _numbers(text, 0.0, '>')


def non_negative_numbers(text: str) -> list[float]:
    """A comma-separated list of finite numbers >= 0, such as ``0,50,150`` (argparse type)."""
    return _numbers(text, 0.0, '>=')


def _numbers(text: str, bound: float, op: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(',')]
    except ValueError:
        values = []
    if not values or not all(math.isfinite(v) and (v > bound if op == '>' else v >= bound)
                             for v in values):
        raise argparse.ArgumentTypeError(
            f'{text!r}: expected comma-separated numbers {op} {bound:g}, such as '
            f'{"50,150,250" if op == ">" else "0,50,150"}')
    return values
