"""The ``dynatex`` command: argparse subcommands, one module each in ``dynatex/commands``.

Exit codes: 0 ok; 2 for every :class:`~dynatex.errors.DynatexError` (bad usage, bad input, a
bad database, no usable OpenCL device, output the system refuses: a full disk, a read-only
folder) and for a file the user named that cannot be opened; 1 for anything else, an internal
error. Errors print one line (``dynatex: error: ...``) unless
``--debug`` asks for the traceback. A reader that closes stdout (``| head -1``) ends the
command quietly with exit 0; a closed stderr drops warnings and progress, the work goes on.
Ctrl-C ends a command with "interrupted" and exit 130, SIGTERM the same way with "terminated"
and exit 143: both unwind, so temporary databases, decode folders and spill files are removed.
An interrupt that lands where Python cannot raise it (a finaliser) is delivered again, never lost.
"""

from __future__ import annotations

import _thread
import argparse
import errno
import importlib
import os
import signal
import sys
import threading
import time
import traceback
import warnings

from . import __version__
from .commands import COMMANDS
from .errors import DynatexError, OutputError, UsageError  # noqa: F401 (importable from here, as before)
from .text import printable


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: the command ends as on Ctrl-C, cleaning up on the way (exit code 143)."""


def _input_errors() -> tuple[type[BaseException], ...]:
    """What exit code 2 reports: every error dynatex raises on purpose, and a file the user
    named that the system refuses to open (missing, a folder, no permission)."""
    return (DynatexError, FileNotFoundError, IsADirectoryError, PermissionError)


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line that points to ``--help`` (exit code 2).

    Subcommand parsers are of this class too (argparse makes them of the parent's class).
    """

    def error(self, message: str):  # type: ignore[override]
        pointer = getattr(self, "help_command", f"{self.prog} --help")  # a mode's page for its flags
        self.exit(2, f"{self.prog}: error: {_one_line(message)} (see `{pointer}`)\n")


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The ``dynatex`` parser for the command line ``argv``.

    Only the module of the command that ``argv`` names is imported (``dynatex play`` loads no
    analyzer); every other command is a name and its one-line help from
    :data:`~dynatex.commands.COMMANDS`, enough for ``dynatex --help``. A command whose options
    depend on another option (``play --mode tiles`` offers the tiles controls) reads it from
    ``argv``. ``argv=None`` builds every command in full (for tests and tools that read them all).
    """
    parser = Parser(prog="dynatex", description="Endless, editable dynamic textures.")
    parser.add_argument("--version", action="version", version=f"dynatex {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    named = _command_named(argv)
    for name, summary in COMMANDS.items():
        if argv is not None and name != named:
            sub.add_parser(name, help=summary)
            continue
        module = importlib.import_module(f"dynatex.commands.{name}")
        p = module.add_parser(sub, argv)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks on errors")
        p.set_defaults(_run=module.run, _parser=p)
    return parser


def _command_named(argv: list[str] | None) -> str | None:
    """The command ``argv`` names: its first word that is not an option, as argparse reads it
    (``dynatex`` itself takes no option with a value)."""
    return next((a for a in argv or () if not a.startswith("-")), None)


def _warning_line(message, category, filename, lineno, line=None) -> str:
    return f"dynatex: warning: {message}\n"


def main(argv: list[str] | None = None) -> int:
    warnings.formatwarning = _warning_line  # a warning is one line too, not a source location
    argv = sys.argv[1:] if argv is None else list(argv)
    restore = _catch_signals()
    try:
        return _main(argv)
    except KeyboardInterrupt as exc:  # also while the command is imported (seconds on a busy machine)
        terminated = isinstance(exc, Terminated)
        _Diagnostics(sys.stderr).write(f"dynatex: {'terminated' if terminated else 'interrupted'}\n")
        return 128 + (signal.SIGTERM if terminated else signal.SIGINT)
    finally:
        restore()


def _main(argv: list[str]) -> int:
    parser = build_parser(argv)
    args, extra = parser.parse_known_args(argv)
    if extra:  # reported by the subcommand's parser, so that the line names the subcommand
        getattr(args, "_parser", parser).error(f"unrecognized arguments: {' '.join(extra)}")
    debug = getattr(args, "debug", False)
    stderr, sys.stderr = sys.stderr, _Diagnostics(sys.stderr)
    try:
        code = int(args._run(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here when the output was short
        return code
    except BrokenPipeError:
        return _reader_gone()
    except _input_errors() as exc:
        return _report(exc, debug, 2)
    except OSError as exc:
        return _report(exc, debug, 2 if exc.errno in REFUSED_ERRNOS else 1)
    except Exception as exc:  # an internal error: still one line unless --debug
        return _report(exc, debug, 1)
    finally:
        sys.stderr = stderr


def _catch_signals():
    """While a command runs in the main thread: SIGTERM raises :class:`Terminated`, and a
    KeyboardInterrupt that Python could only report as "Exception ignored" (raised inside a
    finaliser) is raised again by resending its signal. Returns what restores the previous state."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def on_term(signum, frame):
        raise Terminated

    def unraisable(info) -> None:
        if not isinstance(info.exc_value, KeyboardInterrupt):
            hook(info)
            return
        signum = signal.SIGTERM if isinstance(info.exc_value, Terminated) else signal.SIGINT
        # sent from another thread a moment later, so that it lands after this hook has returned
        threading.Thread(target=_resend, args=(signum,), daemon=True).start()

    hook = sys.unraisablehook
    previous = signal.signal(signal.SIGTERM, on_term)
    sys.unraisablehook = unraisable

    def restore() -> None:
        signal.signal(signal.SIGTERM, previous)
        sys.unraisablehook = hook

    return restore


def _resend(signum: int) -> None:
    time.sleep(0.001)
    _thread.interrupt_main(signum)


class _Diagnostics:
    """``sys.stderr`` while a command runs: when its reader goes away, warnings, progress and
    summaries are dropped and the work goes on (a closed stdout, where the results go, ends
    the command instead: see :func:`_reader_gone`)."""

    def __init__(self, stream) -> None:
        self._stream = stream
        self._gone = stream is None

    def write(self, text: str) -> int:
        if not self._gone:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._drop()
        return len(text)

    def flush(self) -> None:
        if not self._gone:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._drop()

    def isatty(self) -> bool:
        return not self._gone and self._stream.isatty()

    def _drop(self) -> None:
        self._gone = True
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._stream.fileno())  # the last buffered bytes must not fail at exit
            os.close(null)
        except (OSError, ValueError, AttributeError):
            pass

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


#: What the system refuses for a reason outside dynatex (a full disk, a read-only folder): bad input, exit 2.
REFUSED_ERRNOS = frozenset(
    {
        errno.ENOSPC,
        errno.EDQUOT,
        errno.EROFS,
        errno.EACCES,
        errno.EPERM,
        errno.ENAMETOOLONG,
        errno.ENOTDIR,
        errno.EISDIR,
        errno.ENOENT,
        errno.EFBIG,
    }
)

#: Exit code when the reader of our output went away (``dynatex info DB | head -1``): the reader chose
#: to stop, which is not an error of ours. Not 141 (128 + SIGPIPE, a death by the signal), because
#: whether the pipe closes before the last write is a race: ``set -o pipefail`` scripts would fail
#: at random. A database being written at that moment is discarded whole (writes are atomic).
EXIT_PIPE_CLOSED = 0


def _reader_gone() -> int:
    """End quietly when stdout's reader went away: point stdout and stderr at the null device so
    that Python's final flush of what is still buffered for the closed pipe cannot print an error
    of its own."""
    null = os.open(os.devnull, os.O_WRONLY)
    for stream in (sys.stdout, sys.stderr):
        try:
            os.dup2(null, stream.fileno())
        except (OSError, ValueError, AttributeError):
            pass
    os.close(null)
    return EXIT_PIPE_CLOSED


def _report(exc: BaseException, debug: bool, code: int) -> int:
    """One line on stderr (the traceback too with ``--debug``); ``code`` 2 is bad input, 1 internal."""
    try:
        if debug:
            traceback.print_exc()
        if code == 2:
            print(f"dynatex: error: {_one_line(exc)}", file=sys.stderr)
        else:
            print(
                f"dynatex: internal error: {type(exc).__name__}: {_one_line(exc)} (run with --debug for details)",
                file=sys.stderr,
            )
        sys.stderr.flush()
    except BrokenPipeError:
        return _reader_gone()
    return code


def _one_line(exc: BaseException) -> str:
    text = str(exc)
    if isinstance(exc, KeyError) and text.startswith("'") and text.endswith("'"):
        text = text[1:-1]
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return printable(lines[0]) if lines else type(exc).__name__


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
