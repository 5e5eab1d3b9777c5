"""Argument types shared by several sub-commands."""

from __future__ import annotations

import argparse


def frame_size(text: str) -> tuple[int, int]:
    """``WxH`` (or ``N`` for NxN) as (width, height); at least 32x32, the model's smallest frame."""
    try:
        w, _, h = text.lower().partition("x")
        size = (int(w), int(h or w))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if min(size) < 32:
        raise argparse.ArgumentTypeError(f"frames must be at least 32x32, got {text!r}")
    return size
