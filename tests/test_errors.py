"""One root for every error dynatex raises on purpose."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

from dynatex.tiledb import DynatexError, TileDBError, TileDBFormatError

PACKAGES = ("dynatex", "dynatex.commands", "dynatex.tiledb", "dynatex.analyzer", "dynatex.player")
#: the one exception class that is no error: SIGTERM, handled as Ctrl-C is
SIGNALS = ("dynatex.cli.Terminated",)


def _our_exception_classes() -> dict[str, type]:
    """Every exception class defined in a module of dynatex, by its qualified name."""
    found = {}
    for package in PACKAGES:
        root = importlib.import_module(package)
        names = [package] + [i.name for i in pkgutil.walk_packages(root.__path__, package + ".")]  # subpackages too
        for name in names:
            if name.endswith("__main__"):
                continue
            module = importlib.import_module(name)
            for obj in vars(module).values():
                if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == name:
                    found[f"{name}.{obj.__qualname__}"] = obj
    return found


def test_every_exception_class_of_ours_is_a_dynatex_error_and_a_builtin_one():
    """The CLI reports a DynatexError as bad input (exit 2): an error class outside the root
    would make a user's mistake read as an internal error. Each also refines a builtin
    (or is the root itself or a family base), so ``except ValueError`` and the like keep working."""
    classes = _our_exception_classes()
    assert "dynatex.analyzer.errors.SchedulerError" in classes and "dynatex.cli.Terminated" in classes
    assert "dynatex.errors.ChildStartError" in classes and "dynatex.tiledb.errors.TileDBWriteError" in classes
    outside = sorted(n for n, c in classes.items() if n not in SIGNALS and not issubclass(c, DynatexError))
    assert not outside, f"not under DynatexError: {outside}"
    for name, cls in classes.items():
        if name in SIGNALS or cls in (DynatexError, TileDBError):
            continue
        builtins = [
            b for b in cls.__mro__ if b.__module__ == "builtins" and b not in (Exception, BaseException, object)
        ]
        assert builtins, f"{name} refines no builtin error"


def test_every_dynatex_error_shares_one_root():
    from dynatex.analyzer import ClipError
    from dynatex.cli import UsageError
    from dynatex.errors import ArgumentTypeError
    from dynatex.player import DeviceNotVerifiedError, KernelBuildError, OpenCLUnavailableError

    for cls in (
        TileDBError,
        TileDBFormatError,
        ClipError,
        ArgumentTypeError,
        UsageError,
        OpenCLUnavailableError,
        DeviceNotVerifiedError,
        KernelBuildError,
    ):
        assert issubclass(cls, DynatexError), cls
    assert issubclass(TileDBFormatError, ValueError) and issubclass(ClipError, ValueError)


def test_the_cli_reports_dynatex_errors_as_bad_input_and_anything_else_as_internal(monkeypatch, capsys, tmp_path):
    """Exit 2 with one line for an error raised on purpose; exit 1 with the --debug hint for a
    bare builtin error, which is a bug even when it is a ValueError."""
    import dynatex.commands.info as info
    from dynatex.cli import main
    from dynatex.errors import InvalidArgumentError

    def bug(args):
        raise ValueError("an internal slip")

    def bad_input(args):
        raise InvalidArgumentError("n must be an integer >= 1, not 0")

    monkeypatch.setattr(info, "run", bug)
    assert main(["info", str(tmp_path / "x.h5")]) == 1
    err = capsys.readouterr().err.strip()
    assert err == "dynatex: internal error: ValueError: an internal slip (run with --debug for details)"
    monkeypatch.setattr(info, "run", bad_input)
    assert main(["info", str(tmp_path / "x.h5")]) == 2
    assert capsys.readouterr().err.strip() == "dynatex: error: n must be an integer >= 1, not 0"


def test_argument_errors_are_dynatex_errors_and_the_builtins_they_refine():
    import pytest

    from dynatex.checks import check_int
    from dynatex.errors import ArgumentTypeError, InvalidArgumentError
    from dynatex.player import player_class

    assert issubclass(InvalidArgumentError, ValueError) and issubclass(ArgumentTypeError, TypeError)
    with pytest.raises(InvalidArgumentError, match="mode must be one of"):
        player_class("nope")
    with pytest.raises(ArgumentTypeError, match="n must be an integer, not 1.5"):
        check_int("n", 1.5)
