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
import time
from dataclasses import asdict, dataclass, field, replace
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
    #: engine -> its speed figure (:func:`speed_figure`: OpenCL's frame rate over numpy's, per
    #: round and summed up), measured after the checks (:data:`.selftest.SPEED_CASES`) and again
    #: where :func:`speed_stale` says; ``backend="auto"`` takes OpenCL where ``figure["opencl"]``
    speed: dict[str, dict] = field(default_factory=dict)


# -- the speed rule ----------------------------------------------------------------------------
#: ``backend="auto"`` takes OpenCL for an engine only where its median rate is at least MARGIN
#: times numpy's and OpenCL won at least three rounds in four (the lower quartile of the
#: per-round ratios at least 1); a tie is numpy's: the contract is "never slower than numpy"
MARGIN = 1.1
#: rounds each figure takes at least, and at most while it is unsettled (:func:`speed_settled`)
MIN_ROUNDS, MAX_ROUNDS = 5, 21
#: seconds the rounds of a figure span at least, so that they sample more than one moment of a
#: changing load (a burst of other work lasts about as long as a few small rounds)
MIN_SECONDS = 1.5
#: an unsettled figure is measured again, its rounds pooled with the earlier ones, on first use
#: at least REMEASURE_S seconds after the last measurement, until it has MAX_MEASURES of them
REMEASURE_S, MAX_MEASURES = 600.0, 3
#: a figure older than this (seconds) is measured afresh
MAX_AGE_S = 30 * 86400.0
#: rounds a figure keeps (the newest)
KEEP_ROUNDS = 63


def _quartiles(ratios: list[float]) -> tuple[float, float, float]:
    import statistics

    if len(ratios) == 1:
        return ratios[0], ratios[0], ratios[0]
    q1, q2, q3 = statistics.quantiles(ratios, n=4, method="inclusive")
    return q1, q2, q3


def prefers_opencl(ratios: list[float]) -> bool:
    """The rule of ``backend="auto"`` on per-round ratios (OpenCL's rate over numpy's, each from
    one round of both, back to back): the median at least :data:`MARGIN`, the lower quartile at
    least 1. No rounds: numpy."""
    if not ratios:
        return False
    q1, median, _ = _quartiles(list(ratios))
    return median >= MARGIN and q1 >= 1.0


def speed_settled(ratios: list[float]) -> bool:
    """Whether the rounds decide clearly: OpenCL won by :data:`MARGIN` in three rounds of four (the
    lower quartile at least MARGIN), or numpy won three rounds of four (the upper quartile below 1).
    A figure in between (close to 1, or swung by the load) is measured more."""
    if not ratios:
        return False
    q1, _, q3 = _quartiles(list(ratios))
    return q1 >= MARGIN or q3 < 1.0


def speed_figure(ratios: list[float], *, at: float, config: str, measures: int = 1) -> dict:
    """A speed figure as the verdict caches it: the per-round ratios (newest :data:`KEEP_ROUNDS`),
    their median (``ratio``) and quartiles (``low``, ``high``), the choice (``opencl``: the rule of
    :func:`prefers_opencl`), whether it is settled, the measurements pooled, when the last one was
    taken (``at``, seconds since the epoch) and in which configuration (:func:`speed_config`)."""
    kept = [round(float(r), 4) for r in ratios][-KEEP_ROUNDS:]
    low, median, high = _quartiles(kept) if kept else (0.0, 0.0, 0.0)
    return {
        "ratio": round(median, 3),
        "low": round(low, 3),
        "high": round(high, 3),
        "opencl": prefers_opencl(kept),
        "settled": speed_settled(kept),
        "rounds": kept,
        "measures": int(measures),
        "at": float(at),
        "config": config,
    }


def pooled_figure(old: dict | None, ratios: list[float], *, at: float, config: str) -> dict:
    """The figure of a new measurement's ``ratios``, pooled with ``old``'s rounds where ``old`` was
    taken in the same configuration and is not too old to count (an unsettled figure measured again)."""
    if old and old.get("config") == config and at - float(old.get("at", 0)) < MAX_AGE_S:
        return speed_figure([*old.get("rounds", []), *ratios], at=at, config=config, measures=old["measures"] + 1)
    return speed_figure(ratios, at=at, config=config)


def speed_stale(figure: dict | None, *, now: float, config: str) -> str | None:
    """Why ``figure`` must be measured again before it decides (None: it may decide as it is):
    none yet or unreadable, another configuration, too old, or unsettled with fewer than
    :data:`MAX_MEASURES` measurements, the last at least :data:`REMEASURE_S` seconds ago."""
    if not isinstance(figure, dict) or not {"rounds", "at", "config", "measures"} <= figure.keys():
        return "not measured"
    if figure["config"] != config:
        return "measured in another configuration"
    age = now - float(figure["at"])
    if age >= MAX_AGE_S:
        return f"measured {age / 86400:.0f} days ago"
    if not figure["settled"] and figure["measures"] < MAX_MEASURES and age >= REMEASURE_S:
        return "close to numpy's rate"
    return None


def speed_config() -> str:
    """What the speed figures depend on besides the device and dynatex (both in the cache key):
    numpy's version, the CPUs this process may use and the variables that set thread counts."""
    import numpy as np

    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 0
    names = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "POCL_MAX_PTHREAD_COUNT")
    threads = ",".join(f"{k}={os.environ[k]}" for k in names if k in os.environ)
    return f"numpy {np.__version__}; {cpus} of {os.cpu_count()} cpus" + (f"; {threads}" if threads else "")


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


_speed_failed: set[tuple[str, str]] = set()  # (cache key, engine) whose re-measurement failed here


def speed(info: DeviceInfo, engine: str) -> dict | None:
    """``engine``'s speed figure on ``info`` (:func:`speed_figure`), measured again first where
    :func:`speed_stale` says (a child process times that engine alone, a few seconds); None where
    the device has no passing verdict or the engine was never measured there."""
    v = cached_verdict(info)
    if v is None or not v.ok:
        return None
    if speed_stale(v.speed.get(engine), now=time.time(), config=speed_config()) is not None:
        v = refresh_speeds(info, [engine])
    return v.speed.get(engine)


def refresh_speeds(info: DeviceInfo, engines: list[str] | None = None) -> Verdict:
    """Measure again those of ``engines`` that :func:`speed_stale` names (None: every engine the
    self-test knows, as its child finds them), in one child process, and cache the verdict with
    their new figures (pooled with an unsettled figure's earlier rounds). A measurement that
    fails keeps the old figure and is not tried again in this process."""
    with _run_lock:
        v = cached_verdict(info)
        if v is None or not v.ok:
            return v
        key, config, now = cache_key(info), speed_config(), time.time()
        wanted = None
        if engines is not None:
            wanted = [
                e
                for e in engines
                if (key, e) not in _speed_failed and speed_stale(v.speed.get(e), now=now, config=config) is not None
            ]
            if not wanted:
                return v
        timeout = float(os.environ.get("DYNATEX_SELFTEST_TIMEOUT", TIMEOUT))
        try:
            child = call("dynatex.player.opencl.selftest:speed_main", asdict(info), wanted, v.speed, timeout=timeout)
            measured = child.value if child.status == 0 and isinstance(child.value, dict) else {}
        except ChildStartError:
            measured = {}
        figures = dict(v.speed)
        for e, ratios in measured.items():
            if ratios:
                figures[e] = pooled_figure(v.speed.get(e), ratios, at=time.time(), config=config)
        for e in wanted or ():
            if not measured.get(e):
                _speed_failed.add((key, e))
                log.warning("could not measure %s on %s again; its earlier figure stays", e, info.describe())
        if figures == v.speed:
            return v
        v = replace(v, speed=figures)
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


def _describe_speed(engine: str, figure: dict) -> str:
    """One line of ``--check``: an engine's speed figure and what ``auto`` takes."""
    if not isinstance(figure, dict) or "ratio" not in figure:
        return f"{engine}: unreadable figure (measured again on use)"
    why = speed_stale(figure, now=time.time(), config=speed_config())
    return (
        f"{engine}: {figure['ratio']:.2f}x numpy (quartiles {figure['low']:.2f}-{figure['high']:.2f}, "
        f"{len(figure['rounds'])} rounds in {figure['measures']} measurement{'s' if figure['measures'] > 1 else ''}"
        f"{'' if figure['settled'] else ', unsettled'}): {'OpenCL' if figure['opencl'] else 'numpy'} under auto"
        + (f" (measured again on use: {why})" if why else "")
    )


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
            if v.ok:
                v = refresh_speeds(info)
        else:
            v = cached_verdict(info)
        if v is None:
            state = "not yet verified (--check runs the self-test)"
        elif v.ok:
            variants = ", ".join(f"{k} {'ok' if ok else 'not used'}" for k, ok in sorted(v.variants.items()))
            speed = "".join(f"\n     {_describe_speed(k, x)}" for k, x in sorted(v.speed.items()))
            state = f"verified ({v.seconds:.1f} s{'; ' + variants if variants else ''}){speed}"
            passed.append(info)
        else:
            state = f"FAILED: {v.reason}"
        print(f"{info.index}  {info.describe()}, driver {info.driver_version}: {state}")
    if args.check or args.refresh:
        if not passed:
            print("no OpenCL device passed the self-test; the player's numpy backend works without one")
            return 1
        print(f"the player uses {passed[0].index} {passed[0].describe()}")
    if any(cached_verdict(i) and cached_verdict(i).speed for i in passed):
        print(
            f"backend auto takes OpenCL for an engine where its median rate over rounds alternated with numpy is at "
            f"least {MARGIN:.2f}x numpy's and it won three rounds in four; else numpy"
        )
    print(f"verdicts cached in {cache_path()}")
    return 0
