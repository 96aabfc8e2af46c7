"""Device verification: each device's self-test verdict, found once in a child process
(:mod:`.selftest` holds the checks the child runs) and cached per device, driver and dynatex
version in the user's cache folder, so a game pays the test once per machine and driver.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import tempfile
import threading
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path

from ...cache import cache_dir
from ...child import call
from ...errors import ChildStartError
from ..errors import OpenCLUnavailableError
from .devices import _FIX, DeviceInfo, devices, log, preference_order
from .programs import kernel_variants

#: Seconds a device's whole self-test may take before it counts as hung
#: (environment variable ``DYNATEX_SELFTEST_TIMEOUT`` overrides).
TIMEOUT = 180.0
#: Environment variable naming an extra ``.cl`` file to check first (kernel ``check(src, dst)``
#: must copy 4096 bytes): how the tests inject a kernel that crashes, hangs or computes wrong.
INJECT_ENV = "DYNATEX_SELFTEST_INJECT"

_lock = threading.Lock()
_run_lock = threading.Lock()
_verdicts: dict[str, Verdict] = {}


@dataclass
class Verdict:
    """The self-test's finding for one device."""

    ok: bool
    reason: str = ""  # what failed, one line ("" when ok)
    variants: dict[str, bool] = field(default_factory=dict)
    variant_reasons: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0
    device: str = ""
    tested: bool = True  # False: the child never reached a check (not the device's fault)
    #: engine -> its OpenCL frame rate over its numpy reference's, measured once after the checks
    #: (:data:`.selftest.SPEED_CASES`); ``backend="auto"`` takes numpy for an engine below 1
    speed: dict[str, float] = field(default_factory=dict)


# -- cache ---------------------------------------------------------------------------------
def cache_path() -> Path:
    """Where verdicts are kept: ``devices.json`` in dynatex's cache folder (``$DYNATEX_CACHE_DIR``,
    else the platform's user cache folder; :func:`dynatex.cache.cache_dir`)."""

    return cache_dir() / "devices.json"


@functools.lru_cache(maxsize=1)
def _sources_hash() -> str:
    """A digest of everything a verdict depends on besides the device: the player's modules,
    kernels and the self-test's database (read once per process)."""
    h = hashlib.sha256()
    for item in sorted(_walk(resources.files("dynatex.player")), key=lambda r: str(r)):
        h.update(item.name.encode() + b"\0" + item.read_bytes())
    return h.hexdigest()[:16]


def _walk(folder):
    for item in folder.iterdir():
        if item.is_dir():
            if item.name != "__pycache__":
                yield from _walk(item)
        elif item.name.endswith((".cl", ".py", ".h5")):
            yield item


def _version() -> str:
    from ... import __version__

    return __version__


def cache_key(info: DeviceInfo) -> str:
    """The key a device's verdict is cached under (changes with its driver and with dynatex)."""
    inject = os.environ.get(INJECT_ENV, "")
    if inject:
        inject = hashlib.sha256(Path(inject).read_bytes()).hexdigest()[:16] if Path(inject).is_file() else inject
    parts = [
        info.platform,
        info.platform_version,
        info.name,
        info.vendor,
        info.driver_version,
        _version(),
        _sources_hash(),
        inject,
    ]
    return hashlib.sha256("\x1f".join(parts).encode()).hexdigest()[:24]


def _read_cache() -> dict:
    try:
        data = json.loads(cache_path().read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _write_cache(key: str, verdict: Verdict) -> None:
    """Add one verdict to the cache file atomically; a cache that cannot be written is only logged."""
    path = cache_path()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        data = _read_cache()
        data[key] = asdict(verdict)
        fd, tmp = tempfile.mkstemp(prefix=".devices.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=1, sort_keys=True)
        os.replace(tmp, path)
    except OSError as exc:
        log.warning("cannot cache the OpenCL self-test verdict in %s: %s", path, exc)


def cached_verdict(info: DeviceInfo) -> Verdict | None:
    """The verdict already known for ``info`` (this process or the cache file), else None."""
    key = cache_key(info)
    with _lock:
        if key in _verdicts:
            return _verdicts[key]
    entry = _read_cache().get(key)
    if not isinstance(entry, dict):
        return None
    try:
        v = Verdict(**entry)
    except TypeError:
        return None
    with _lock:
        _verdicts[key] = v
    return v


def suppose(info: DeviceInfo, variants: frozenset[str] = frozenset()) -> None:
    """Hold ``info`` to a passing verdict that allows kernel ``variants`` and no other, in this
    process only (nothing is cached): the self-test's child runs the player's own code on the
    device under test this way, portable kernels first, then each variant alone."""
    v = Verdict(True, variants={name: True for name in variants}, device=info.describe())
    with _lock:
        _verdicts[cache_key(info)] = v


def verdict(info: DeviceInfo, *, refresh: bool = False) -> Verdict:
    """The self-test verdict for ``info``: cached, or found now in a child process and cached.

    Self-tests run one at a time (two threads opening players wait for one test). A child
    that could not start or run its first check (no interpreter, an import failure) says
    nothing about the device: that verdict is not kept."""
    if not refresh:
        v = cached_verdict(info)
        if v is not None:
            return v
    with _run_lock:
        if not refresh:
            v = cached_verdict(info)
            if v is not None:
                return v
        v = run_child(info)
        if v.tested:
            key = cache_key(info)
            with _lock:
                _verdicts[key] = v
            _write_cache(key, v)
    return v


# -- the parent's side ------------------------------------------------------------------------
def run_child(info: DeviceInfo, *, timeout: float | None = None) -> Verdict:
    """Run the checks for ``info`` in a child process; a crash or hang there is a failed verdict."""
    if timeout is None:
        timeout = float(os.environ.get("DYNATEX_SELFTEST_TIMEOUT", TIMEOUT))
    try:
        child = call("dynatex.player.opencl.selftest:child_main", asdict(info), timeout=timeout)
    except ChildStartError as exc:
        return Verdict(False, f"cannot run the self-test: {exc}", device=info.describe(), tested=False)
    try:
        return _parse(child.out, child.status, child.timed_out, timeout, child.seconds, info, child.err)
    except (ValueError, TypeError) as exc:
        return Verdict(False, f"unreadable self-test verdict ({exc})", device=info.describe(), tested=False)


def _parse(
    out: str, code: int | None, hung: bool, timeout: float, seconds: float, info: DeviceInfo, err: str = ""
) -> Verdict:
    """The verdict from the child's lines (tab-separated: check NAME, pass NAME, fail NAME WHY,
    verdict JSON) and how it ended (``code`` None: killed after ``timeout``)."""
    passed, current, failures, final, started = [], None, {}, None, False
    for line in out.splitlines():
        word, _, rest = line.partition("\t")
        if word == "check":
            current, started = rest, True
        elif word == "pass":
            passed.append(rest)
            current = None
        elif word == "fail":
            name, _, why = rest.partition("\t")
            failures[name] = why
            current = None
        elif word == "verdict":
            final = rest
    if final is not None and code == 0:
        v = Verdict(**json.loads(final))
        v.seconds = seconds
        return v
    if not started and not hung and (code is None or code >= 0):
        last = err.strip().splitlines()[-1] if err.strip() else f"exit status {code}"
        return Verdict(
            False, f"the self-test could not run: {last[:300]}", seconds=seconds, device=info.describe(), tested=False
        )
    if hung:
        what = f"hung (no verdict after {timeout:.0f} s)"
    elif code is not None and code < 0:
        what = f"crashed (signal {-code})" + (" at exit, after its checks" if final is not None else "")
    else:
        what = f"exited with status {code}" + (" after its checks" if final is not None else "")
    where = f" in check {current!r}" if current else ""
    # variants and speed measurements come after every portable check has passed
    failed = [(k, why) for k, why in failures.items() if not k.startswith(("variant ", "speed "))]
    portable_done = not failed and current is not None and current.startswith(("variant ", "speed "))
    reason = f"{failed[0][0]}: {failed[0][1]}" if failed else "" if portable_done else f"{what}{where}"
    v = Verdict(ok=portable_done, reason=reason, seconds=seconds, device=info.describe())
    for name in kernel_variants():
        check = f"variant {name}"
        v.variants[name] = check in passed
        if check == current:
            v.variant_reasons[name] = f"{what}{where}"
        elif check in failures:
            v.variant_reasons[name] = failures[check]
    return v


def _main(argv: list[str] | None = None) -> int:
    """``python -m dynatex.player [--check] [--refresh]``: the devices, their self-test verdicts
    and the one the player uses; with --check exit 1 when no device passed."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m dynatex.player", description="List the OpenCL devices and their self-test verdicts."
    )
    parser.add_argument(
        "--check", action="store_true", help="self-test every device (cached) and exit 1 unless one passed"
    )
    parser.add_argument("--refresh", action="store_true", help="run the self-tests again, ignoring cached verdicts")
    args = parser.parse_args(argv)
    try:
        infos = devices()
    except OpenCLUnavailableError as exc:
        print(f"no usable OpenCL: {exc}")
        return 1
    if not infos:
        print(f"no OpenCL device found; {_FIX}")
        return 1
    passed = []
    for info in preference_order(infos):
        if args.check or args.refresh:
            v = verdict(info, refresh=args.refresh)
        else:
            v = cached_verdict(info)
        if v is None:
            state = "not yet verified (--check runs the self-test)"
        elif v.ok:
            variants = ", ".join(f"{k} {'ok' if ok else 'not used'}" for k, ok in sorted(v.variants.items()))
            speed = ", ".join(
                f"{k} {x:.2f}x numpy ({'OpenCL' if x >= 1 else 'numpy'} under auto)" for k, x in sorted(v.speed.items())
            )
            state = f"verified ({v.seconds:.1f} s{'; ' + variants if variants else ''}{'; ' + speed if speed else ''})"
            passed.append(info)
        else:
            state = f"FAILED: {v.reason}"
        print(f"{info.index}  {info.describe()}, driver {info.driver_version}: {state}")
    if args.check or args.refresh:
        if not passed:
            print("no OpenCL device passed the self-test; the player's numpy backend works without one")
            return 1
        print(f"the player uses {passed[0].index} {passed[0].describe()}")
    print(f"verdicts cached in {cache_path()}")
    return 0
