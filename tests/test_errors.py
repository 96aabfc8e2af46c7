"""One root for every error dynatex raises on purpose."""
from __future__ import annotations

from dynatex.tiledb import DynatexError, TileDBError, TileDBFormatError


def test_every_dynatex_error_shares_one_root():
    from dynatex.analyzer import ClipError
    from dynatex.errors import ArgumentTypeError
    from dynatex.cli import UsageError
    from dynatex.player import DeviceNotVerifiedError, KernelBuildError, OpenCLUnavailableError
    for cls in (TileDBError, TileDBFormatError, ClipError, ArgumentTypeError, UsageError, OpenCLUnavailableError,
                DeviceNotVerifiedError, KernelBuildError):
        assert issubclass(cls, DynatexError), cls
    assert issubclass(TileDBFormatError, ValueError) and issubclass(ClipError, ValueError)
