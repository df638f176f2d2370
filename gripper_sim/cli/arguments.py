"""argparse validators shared by the verbs: numbers that must be finite and in range."""
from __future__ import annotations

import argparse
import math


def _finite(text: str, requirement: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"'{text}' must be a finite number {requirement}")
    return value


def positive_float(text: str) -> float:
    """A finite number > 0."""
    value = _finite(text, '> 0')
    if value <= 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be a finite number > 0")
    return value


def positive_int(text: str) -> int:
    """A whole number >= 1."""
    try:
        value = int(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f'{text!r} is not an integer') from err
    if value < 1:
        raise argparse.ArgumentTypeError(f'{value} must be at least 1')
    return value


def non_negative_float(text: str) -> float:
    """A finite number >= 0."""
    value = _finite(text, '>= 0')
    if value < 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be a finite number >= 0")
    return value


def port_number(text: str) -> int:
    """A TCP port, 1 to 65535."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a port number") from None
    if not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"'{text}' must be a port number in [1, 65535]")
    return value
