"""The analyzer's errors, each a :class:`~dynatex.errors.DynatexError` and the builtin it refines."""

from __future__ import annotations

from ..errors import DynatexError


class ClipError(DynatexError, ValueError):
    """A clip cannot be read or does not hold usable frames."""


class SchedulerError(DynatexError, ConnectionError, ValueError):
    """The Dask scheduler named cannot be reached (bad input: a wrong or dead address)."""


__all__ = ["ClipError", "SchedulerError"]
