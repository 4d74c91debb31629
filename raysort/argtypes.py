"""argparse types shared by the command-line apps (``raysort render``, ``bench``, ``sweep``).

Each raises ``argparse.ArgumentTypeError`` with the value it got, which the
parser prints as one line with exit status 2.
"""
from __future__ import annotations

import argparse

__all__ = ["size", "at_least", "positive", "non_negative", "seed", "SCHEDULER_HELP"]

SCHEDULER_HELP = ("render on Dask (needs raysort[distributed]): the address of a running "
                  "scheduler (tcp://HOST:8786), or local[:N] for N single-threaded worker "
                  "processes here (default: one per core); --threads does not apply")



def size(text):
    """WIDTHxHEIGHT, each at least 1, at most 64 Mpixels in all."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT such as 320x240, got {text!r}") from None
    if w < 1 or h < 1 or w * h > 64 * 1024 * 1024:
        raise argparse.ArgumentTypeError(f"image size {text!r} is out of range")
    return w, h


def at_least(lo):
    """An argparse type: a whole number >= lo."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < lo:
            raise argparse.ArgumentTypeError(f"expected a number >= {lo}, got {value}")
        return value
    return parse


positive, non_negative = at_least(1), at_least(0)


def seed(text):
    """A seed, a whole number in 0..2**32-1 (the random numbers are keyed on 32 bits, so
    a larger one would repeat another's image)."""
    from raysort.pipeline import MAX_SEED

    value = non_negative(text)
    if value > MAX_SEED:
        raise argparse.ArgumentTypeError(f"expected a seed in 0..{MAX_SEED}, got {value}")
    return value
