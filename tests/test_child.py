"""Risky work in a child process (dynatex.child): real children that succeed, raise, crash, run
out of memory, hang past their timeout or are interrupted; none outlives the call."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

import pytest

from dynatex.child import MEMORY_STATUS, call
from dynatex.errors import ChildStartError, DynatexError

posix = pytest.mark.skipif(os.name != "posix", reason="process groups and shell children are POSIX")


def _gone(pid: int, within: float = 10.0) -> bool:
    """Whether process ``pid`` has ended (a zombie waiting for its reaper counts) within ``within`` s."""
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().rsplit(")", 1)[1].split()[0] == "Z":
                    return True
        except FileNotFoundError:
            return True
        except OSError:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                return True
        time.sleep(0.05)
    return False


def _pids(path) -> list[int]:
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if path.exists() and path.read_text().count("\n") >= 2:
            return [int(p) for p in path.read_text().split()]
        time.sleep(0.02)
    raise AssertionError("the child never wrote its process ids")


def test_a_child_that_succeeds_returns_its_value():
    child = call("os.path:join", "a", "b", timeout=60)
    assert child.ok and child.status == 0 and child.value == os.path.join("a", "b")
    assert child.raised is None and child.out == "" and child.seconds < 60
    if sys.platform.startswith("linux"):
        assert child.peak_bytes > 2**20  # an interpreter's resident memory, measured


def test_what_a_child_raises_comes_back_as_one_line():
    child = call("math:sqrt", -1.0, timeout=60)
    assert child.status == 1 and not child.ok and child.value is None
    assert child.raised == ("ValueError", "math domain error")
    assert child.describe() == "failed: ValueError: math domain error"
    missing = call("dynatex.no_such_module:f", timeout=60)
    assert missing.status == 1 and missing.raised[0] == "ModuleNotFoundError"


@posix
def test_a_child_that_crashes_is_reported_with_its_signal():
    child = call("os:abort", timeout=60)
    assert child.status == -signal.SIGABRT and child.raised is None
    assert child.describe() == f"crashed (signal {int(signal.SIGABRT)})"


def test_a_child_out_of_memory_exits_with_its_own_status():
    child = call("builtins:bytearray", 2**62, timeout=60)
    assert child.status == MEMORY_STATUS and child.describe().startswith("ran out of memory")


@posix
def test_a_child_that_hangs_is_killed_at_its_timeout_with_what_it_started(tmp_path):
    pids = tmp_path / "pids"
    script = f"echo $PPID > {pids}.tmp; echo $$ >> {pids}.tmp; mv {pids}.tmp {pids}; echo started; exec sleep 60"
    t0 = time.monotonic()
    child = call("subprocess:call", ["sh", "-c", script], timeout=3)
    assert child.timed_out and child.status is None and time.monotonic() - t0 < 30
    assert child.describe() == "did not finish within 3 s"
    assert child.out.strip() == "started"  # what it printed before it hung is kept
    assert all(_gone(pid) for pid in _pids(pids))  # the child and the sleep it started


@posix
def test_an_interrupt_kills_the_child_before_it_is_raised(tmp_path):
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signals reach the main thread only")
    pids = tmp_path / "pids"
    script = f"echo $PPID > {pids}.tmp; echo $$ >> {pids}.tmp; mv {pids}.tmp {pids}; exec sleep 60"
    main = threading.get_ident()

    def interrupt() -> None:
        _pids(pids)
        signal.pthread_kill(main, signal.SIGINT)

    sender = threading.Thread(target=interrupt)
    sender.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            call("subprocess:call", ["sh", "-c", script], timeout=120)
    finally:
        sender.join(60)
    child_pid, sleep_pid = _pids(pids)
    assert _gone(child_pid, within=0.5)  # reaped before the interrupt was raised
    assert _gone(sleep_pid)


@posix
def test_a_child_ends_when_its_parent_is_killed_outright(tmp_path):
    """SIGKILL gives the parent no chance to kill its child: the lifeline on stdin ends it."""
    import subprocess

    pids = tmp_path / "pids"
    script = f"echo $PPID > {pids}.tmp; echo $$ >> {pids}.tmp; mv {pids}.tmp {pids}; exec sleep 60"
    parent = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"from dynatex.child import call; call('subprocess:call', ['sh', '-c', {script!r}], timeout=120)",
        ]
    )
    try:
        child_pid, sleep_pid = _pids(pids)
    finally:
        parent.kill()
        parent.wait(30)
    assert _gone(child_pid) and _gone(sleep_pid)


def test_without_an_interpreter_no_child_starts(monkeypatch):
    monkeypatch.setenv("DYNATEX_PYTHON", "/usr/bin/my-game")
    words = r"'/usr/bin/my-game' is not a Python interpreter \(set DYNATEX_PYTHON to one\)"
    with pytest.raises(ChildStartError, match=words) as e:
        call("os.path:join", "a", timeout=60)
    assert isinstance(e.value, DynatexError) and isinstance(e.value, OSError)
