"""The command lines' shared parts: one-line errors, bounded numbers, a help formatter that prints each default once."""

from __future__ import annotations

import argparse
import sys

import numpy as np


class OneLineErrorParser(argparse.ArgumentParser):
    """argparse that reports a bad value in one line (no usage dump) and exits with status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        sys.exit(2)


def number(kind, name: str, low: float | None = None, low_inclusive: bool = True, high: float | None = None):
    """An argparse ``type``: ``kind(text)``, finite and within ``[low, high]`` (``low`` excluded unless
    ``low_inclusive``); a bad value is one line naming ``name`` and the bounds."""
    rel = ">=" if low_inclusive else ">"
    bounds = " and ".join(([f"{rel} {low:g}"] if low is not None else []) + ([f"<= {high:g}"] if high is not None else []))

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a{'n integer' if kind is int else ' number'}, got {text!r}")
        if not np.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name} must be finite, got {text!r}")
        if (low is not None and (value < low or (value == low and not low_inclusive))) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"{name} must be {bounds}, got {text}")
        return value

    return parse


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Examples kept as written; a default printed once (not where the help already says it, nor None/False)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "default" in text.lower() or action.default in (None, False, [], argparse.SUPPRESS):
            return text
        return super()._get_help_string(action)
