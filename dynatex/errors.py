"""The root of every error dynatex raises on purpose; the errors of bad arguments, the command line and child processes.

This module imports nothing of ours, so every layer (the tile database at the bottom, the
analyzer and the player above it, the CLI on top) may derive its errors from it. Each error
also derives from the builtin it refines, so ``except ValueError`` keeps working; the CLI
turns a :class:`DynatexError` into one line and exit code 2, anything else into exit code 1.
Each layer keeps its own in one module: ``tiledb/errors.py``, ``analyzer/errors.py``,
``player/errors.py``; the command line's and the top-level helpers' (:mod:`dynatex.child`) are
here. README.md ("What ``import dynatex`` gives") lists the family.
"""

from __future__ import annotations


class DynatexError(Exception):
    """Root of every error dynatex raises on purpose: bad input, a bad database, no device."""


class InvalidArgumentError(DynatexError, ValueError):
    """An argument with a value out of its range or set (names the argument and the rule)."""


class ArgumentTypeError(InvalidArgumentError, TypeError):
    """An argument of the wrong type. Also a ValueError: to a caller it is one more bad value."""


class UsageError(DynatexError, ValueError):
    """Bad command-line input detected after parsing (exit code 2)."""


class OutputError(DynatexError, OSError):
    """The command's output cannot be written: refused by the codec, the folder or the disk (exit code 2)."""


class ChildStartError(DynatexError, OSError):
    """No child process can be started for risky work (:mod:`dynatex.child`): no Python
    interpreter to run it with, or the system refused a process."""


__all__ = ["ArgumentTypeError", "ChildStartError", "DynatexError", "InvalidArgumentError", "OutputError", "UsageError"]
