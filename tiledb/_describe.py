"""Plain values for a model's ``describe()``: what ``dynatex info`` prints and ``--json`` writes.

Every model class of a method group has ``describe() -> dict`` (facts as plain Python values:
numbers, strings, lists, nothing numpy) and ``summary() -> str`` (one line, what ``dynatex
analyze`` prints once the model is learned). A ``"warning"`` entry of ``describe()`` is a
caveat about the model that the analyzer also prints.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def plain(value: Any) -> Any:
    """``value`` as a plain Python value (numpy scalars and arrays to numbers and lists, bytes to text).

    >>> plain(np.float32(0.5)), plain(np.arange(3)), plain(b"ring")
    (0.5, [0, 1, 2], 'ring')
    """
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    return value


def plain_info(info: dict | None) -> dict:
    """A model's ``info`` attributes as plain values, in their order."""
    return {k: plain(v) for k, v in (info or {}).items()}


class Described:
    """Base of the model classes: ``describe()`` is the ``info`` attributes as plain values;
    a model with more facts extends it."""

    info: dict

    def describe(self) -> dict:
        """Facts as plain values: the ``info`` attributes."""
        return plain_info(self.info)
