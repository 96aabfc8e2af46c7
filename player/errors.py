"""The player's errors, each a :class:`~dynatex.errors.DynatexError` and the builtin it refines."""

from __future__ import annotations

from ..errors import DynatexError


class PlayerClosedError(DynatexError, RuntimeError):
    """The player was closed (``close()`` or the end of its ``with`` block); open a new one."""


class PlayerForkedError(DynatexError, RuntimeError):
    """An OpenCL player used in a process forked from the one that opened it."""


class UnknownControlError(DynatexError, AttributeError):
    """An attribute a player does not have was set (a misspelt control); names the controls it has."""


class OpenCLUnavailableError(DynatexError, RuntimeError):
    """No usable OpenCL platform or device."""


class KernelBuildError(DynatexError, RuntimeError):
    """An OpenCL program failed to build; the message carries the compiler log."""


class DeviceNotVerifiedError(OpenCLUnavailableError):
    """An OpenCL device was asked for by name but did not pass the self-test."""


__all__ = [
    "DeviceNotVerifiedError",
    "KernelBuildError",
    "OpenCLUnavailableError",
    "PlayerClosedError",
    "PlayerForkedError",
    "UnknownControlError",
]
