"""Argument types the command-line tools share (argparse ``type=`` callables).

Each raises ``argparse.ArgumentTypeError`` naming what was wrong, which argparse turns into a
usage error (exit 2) naming the option.
"""

import argparse
import math

__all__ = ['positive_float']


def positive_float(text: str) -> float:
    """A finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f'expected a positive finite number, got {text!r}')
    return value
