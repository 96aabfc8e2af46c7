"""The ``dynatex`` command: argparse subcommands, one module each in ``dynatex/commands``.

Exit codes: 0 ok, 2 bad usage or bad input, 1 internal error. Errors print one line
(``dynatex: error: ...``) unless ``--debug`` asks for the traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import traceback
import warnings

from . import __version__

#: subcommand -> module in dynatex.commands (each has ``add_parser(subparsers)`` and ``run(args)``)
COMMANDS = ("analyze", "info", "play", "bench", "evaluate", "demo")


class UsageError(ValueError):
    """Bad command-line input detected after parsing (exit code 2)."""


def _input_errors() -> tuple[type[BaseException], ...]:
    from .player.opencl import OpenCLUnavailableError
    from .tiledb import TileDBError
    errors: list[type[BaseException]] = [UsageError, TileDBError, OpenCLUnavailableError, FileNotFoundError,
                                         IsADirectoryError, PermissionError, ValueError, TypeError, KeyError]
    return tuple(errors)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dynatex", description="Endless, editable dynamic textures.")
    parser.add_argument("--version", action="version", version=f"dynatex {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"dynatex.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"dynatex.commands.{name}":
                continue  # command not built yet
            raise
        p = module.add_parser(sub)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks on errors")
        p.set_defaults(_run=module.run)
    return parser


def _warning_line(message, category, filename, lineno, line=None) -> str:
    return f"dynatex: warning: {message}\n"


def main(argv: list[str] | None = None) -> int:
    warnings.formatwarning = _warning_line          # a warning is one line too, not a source location
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = getattr(args, "debug", False)
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print("dynatex: interrupted", file=sys.stderr)
        return 130
    except _input_errors() as exc:
        if debug:
            traceback.print_exc()
        print(f"dynatex: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except Exception as exc:  # an internal error: still one line unless --debug
        if debug:
            traceback.print_exc()
        print(f"dynatex: internal error: {type(exc).__name__}: {_one_line(exc)} (run with --debug for details)",
              file=sys.stderr)
        return 1


def _one_line(exc: BaseException) -> str:
    text = str(exc)
    if isinstance(exc, KeyError) and text.startswith("'") and text.endswith("'"):
        text = text[1:-1]
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[0] if lines else type(exc).__name__


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
