"""The device self-test: a device that crashes, hangs or computes wrong is found out in a child
process and never used, the caller lives, and verdicts are cached."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dynatex.player import open_player
from dynatex.player.base import Player
from dynatex.player.engines.projection import SPEED_ROWS, speed_case
from dynatex.player.opencl import context as opencl
from dynatex.player.opencl import selftest, verify

from ..conftest import verified_devices

KERNELS = {
    # writes through a wild pointer: the device segfaults while running it
    "crash": """__kernel void check(__global const uchar *src, __global uchar *dst)
{
    __global uchar *wild = (__global uchar *)((size_t)0x10 + get_global_id(0) * 4096);
    wild[0] = src[get_global_id(0)];
    dst[get_global_id(0)] = wild[0];
}""",
    # never returns
    "hang": """__kernel void check(__global const uchar *src, __global uchar *dst)
{
    for (uint i = 0; ; ++i)
        dst[i & 4095] = src[i & 4095] + (uchar)i;
}""",
    # one value off among 4096
    "wrong": """__kernel void check(__global const uchar *src, __global uchar *dst)
{
    const size_t i = get_global_id(0);
    dst[i] = src[i] + (i == 1000);
}""",
}


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    """An empty verdict cache, and no device or verdict remembered by this process."""
    monkeypatch.setenv("DYNATEX_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(verify, "_verdicts", {})
    monkeypatch.setattr(opencl, "_contexts", {})
    return tmp_path / "cache" / "devices.json"


@pytest.fixture
def inject(tmp_path, monkeypatch, fresh_cache):
    """``inject(kind)``: the self-test also runs one of KERNELS first, on every device."""

    def use(kind: str) -> None:
        path = tmp_path / f"{kind}.cl"
        path.write_text(KERNELS[kind])
        monkeypatch.setenv(verify.INJECT_ENV, str(path))

    return use


@pytest.fixture(scope="module")
def device():
    """The first verified device: the self-test's machinery is proven on one device, not all."""
    devices = verified_devices()
    if not devices:
        pytest.skip("no OpenCL device passed the self-test here")
    return devices[0]


def test_every_kernel_variant_has_its_checks():
    """The verdict lists the files of ``kernels/variants/`` (:func:`kernel_variants`), the child checks
    CHECK_VARIANTS: one list, or a variant would be used unchecked or never reported."""
    from dynatex.player.opencl.programs import kernel_variants

    assert kernel_variants() and set(kernel_variants()) == set(selftest.CHECK_VARIANTS)


def test_every_verified_device_ran_every_check(cl_device):
    v = verify.verdict(next(d for d in opencl.devices() if d.index == cl_device))
    assert v.ok and v.reason == "" and v.seconds > 0
    assert set(v.variants) == set(selftest.CHECK_VARIANTS)


@pytest.mark.parametrize("kind, words", [("crash", "crashed (signal"), ("wrong", "differ from the numpy reference")])
def test_a_device_that_crashes_or_computes_wrong_is_rejected(device, inject, kind, words):
    if kind == "crash" and not device.is_cpu:
        pytest.skip("a wild write crashes the process on CPU devices; a GPU may report it instead")
    inject(kind)
    v = verify.run_child(device)
    assert not v.ok
    assert words in v.reason and "injected kernel" in v.reason
    assert "\n" not in v.reason
    assert not any(v.variants.values())


def test_a_device_that_hangs_is_rejected_after_the_timeout(device, inject):
    inject("hang")
    v = verify.run_child(device, timeout=20)
    assert not v.ok and v.reason == "hung (no verdict after 20 s) in check 'injected kernel'"
    assert 20 <= v.seconds < 60


def test_the_player_falls_back_to_numpy_when_no_device_passes(device, inject, monkeypatch):
    """Every device crashes in its self-test: the caller lives, gets frames from the numpy
    backend with one warning, and an explicit demand for OpenCL is a clear error."""
    inject("crash")
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    monkeypatch.setattr("dynatex.player.base._fallback_warned", False)
    db = str(Path(selftest._db_path()))
    with pytest.warns(RuntimeWarning, match="uses the numpy backend.*passed the self-test.*crashed"):
        p = open_player(db, selftest.TEXTURE, mode="lds")
    with p, open_player(db, selftest.TEXTURE, mode="lds") as q:  # warned once only
        assert p.backend == q.backend == "numpy"
        assert p.next_frame().shape == (24, 32, 3)
    with pytest.raises(opencl.OpenCLUnavailableError, match="no OpenCL device here passed the self-test"):
        open_player(db, selftest.TEXTURE, mode="lds", backend="opencl")
    with pytest.raises(opencl.DeviceNotVerifiedError, match=rf"device='{device.index}'.*failed the self-test: crashed"):
        open_player(db, selftest.TEXTURE, mode="lds", device=device.index)
    monkeypatch.setenv("PYOPENCL_CTX", device.index)
    with pytest.raises(opencl.DeviceNotVerifiedError, match="PYOPENCL_CTX"):
        open_player(db, selftest.TEXTURE, mode="tiles")


def test_play_without_a_usable_device_exits_2_with_the_fix_in_one_line(device, inject, monkeypatch, tmp_path, capsys):
    """No device passes the self-test: ``dynatex play --backend opencl`` is the user's problem
    with a fix (exit code 2, one line naming the numpy backend), not an internal error."""
    from dynatex.cli import main

    inject("crash")
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    out = tmp_path / "o.mp4"
    assert main(["play", str(selftest._db_path()), "--backend", "opencl", "--frames", "2", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("dynatex: error: no OpenCL device here passed the self-test")
    assert "apt-get install pocl-opencl-icd" in err and "--backend numpy" in err
    assert not out.exists()


def test_verdicts_are_cached_per_device_and_driver(device, fresh_cache, monkeypatch):
    info = device
    v = verify.verdict(info)
    assert v.ok and verify.cache_key(info) in json.loads(fresh_cache.read_text())
    # a new process (nothing in memory) reads the file and runs no child
    monkeypatch.setattr(verify, "_verdicts", {})
    monkeypatch.setattr(verify, "run_child", lambda *a, **k: pytest.fail("the self-test ran again"))
    assert verify.verdict(info) == v
    other = dataclasses.replace(info, driver_version=info.driver_version + "-next")
    assert verify.cache_key(other) != verify.cache_key(info)
    assert verify.cached_verdict(other) is None


def test_an_unwritable_cache_only_costs_the_cache(device, tmp_path, monkeypatch, caplog):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("DYNATEX_CACHE_DIR", str(blocker / "cache"))
    monkeypatch.setattr(verify, "_verdicts", {})
    with caplog.at_level("WARNING"):
        assert verify.verdict(device).ok
    assert "cannot cache the OpenCL self-test verdict" in caplog.text


def test_a_crash_in_a_variant_keeps_the_device_on_its_portable_kernels():
    info = opencl.DeviceInfo("0:0", "P", "OpenCL 3.0", "cpu", "v", "1", True)
    out = "check\tgather: a, b\npass\tgather: a, b\ncheck\tvariant gather_wide\n"
    v = verify._parse(out, -11, False, 60.0, 1.0, info)
    assert v.ok and v.tested and v.variants == {"gather_wide": False, "copy_stream": False}
    assert v.variant_reasons == {"gather_wide": "crashed (signal 11) in check 'variant gather_wide'"}
    v = verify._parse("check\tgather: a, b\nfail\tgather: a, b\tframe 0: wrong\n", 1, False, 60.0, 1.0, info)
    assert not v.ok and v.reason == "gather: a, b: frame 0: wrong"
    v = verify._parse("check\tmode lds\n", -6, False, 60.0, 1.0, info)
    assert not v.ok and v.reason == "crashed (signal 6) in check 'mode lds'"


def test_a_child_that_cannot_run_is_not_the_devices_fault(device, fresh_cache, monkeypatch, tmp_path):
    """A child that fails before its first check (here: dynatex not importable) is a failed
    verdict that is not cached, so a fixed environment is tested again."""
    fake = tmp_path / "python3"
    fake.write_text("#!/bin/sh\necho 'ModuleNotFoundError: No module named dynatex' >&2\nexit 1\n")
    fake.chmod(0o755)
    monkeypatch.setenv("DYNATEX_PYTHON", str(fake))
    v = verify.verdict(device)
    assert not v.ok and not v.tested
    assert v.reason == "the self-test could not run: ModuleNotFoundError: No module named dynatex"
    assert not fresh_cache.exists()
    monkeypatch.delenv("DYNATEX_PYTHON")
    assert verify.verdict(device).ok and fresh_cache.exists()


def test_check_command_lists_every_device_with_its_verdict(device):
    done = subprocess.run(
        [sys.executable, "-m", "dynatex.player", "--check"], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stdout + done.stderr
    lines = [ln for ln in done.stdout.splitlines() if ln[:1].isdigit()]
    assert len(lines) == len(opencl.devices())
    assert all(": verified (" in ln or ": FAILED: " in ln for ln in lines), lines
    assert "the player uses " in done.stdout


def test_every_verified_device_measured_its_engines_against_numpy(cl_device):
    v = verify.verdict(next(d for d in opencl.devices() if d.index == cl_device))
    assert set(selftest.SELFTEST_SPEED_CASES) <= set(v.speed) <= set(selftest.SPEED_CASES), v.speed
    for engine, f in v.speed.items():
        rounds, measures = len(f["rounds"]), f["measures"]  # more than one: an unsettled figure measured again
        assert verify.MIN_ROUNDS * measures <= rounds <= verify.MAX_ROUNDS * measures, (engine, f)
        assert min(f["rounds"]) > 0 and 1 <= measures <= verify.MAX_MEASURES, (engine, f)
        assert f["low"] <= f["ratio"] <= f["high"] and f["opencl"] == verify.prefers_opencl(f["rounds"]), (engine, f)
        assert f["config"] == verify.speed_config(), (engine, f)


def test_auto_takes_numpy_for_an_engine_the_self_test_measured_slower(device, monkeypatch):
    """The verdict's speed decides ``auto`` per engine and precision; a backend asked for is kept."""
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    info = opencl.device_info(opencl.get_context().devices[0])
    v = verify.verdict(info)
    at, config = time.time(), verify.speed_config()
    slow = {  # at every basis rows the figures are keyed by: the self-test's textures are small
        speed_case(precision, 288 * 352 * 3, 1, rows=n): verify.speed_figure([ratio] * 7, at=at, config=config)
        for precision, ratio in (("float32", 0.5), ("float16", 2.0))
        for n in SPEED_ROWS
    }
    monkeypatch.setitem(verify._verdicts, verify.cache_key(info), dataclasses.replace(v, speed=slow))
    db = selftest._db_path()
    for mode in ("lds", "mixture"):
        for precision, backend, want in (
            ("float32", "auto", "numpy"),
            ("float16", "auto", "opencl"),
            ("float32", "opencl", "opencl"),
        ):
            with open_player(db, selftest.TEXTURE, mode=mode, precision=precision, backend=backend, seed=2) as p:
                assert p.backend == want and (p.ctx is None) == (want == "numpy"), (mode, precision, backend)
                assert p.engine.backend == want
                if want == "numpy":  # the reference itself, frame for frame
                    with open_player(db, selftest.TEXTURE, mode=mode, backend="numpy", seed=2) as q:
                        assert np.array_equal(p.next_frame(), q.next_frame())
    with open_player(db, selftest.TEXTURE, mode="turnpoints", seed=1) as p:  # other engines: not measured
        assert p.backend == "opencl"


def test_players_open_on_a_verified_device_by_default(device):
    with open_player(selftest._db_path(), selftest.TEXTURE, mode="turnpoints", seed=1) as p:
        assert isinstance(p, Player) and p.backend == "opencl"
        assert p.next_frame().dtype == np.uint8


def test_an_application_embedding_python_is_not_started_as_the_child(device, fresh_cache, monkeypatch):
    """Where sys.executable is the host application (a game embedding Python), running it with
    -m would start the application: the self-test refuses and says how to name an interpreter."""
    python = sys.executable
    monkeypatch.setattr(sys, "executable", "/opt/game/bin/mygame")
    monkeypatch.delenv("DYNATEX_PYTHON", raising=False)
    v = verify.run_child(device)
    assert not v.ok and "is not a Python interpreter (set DYNATEX_PYTHON" in v.reason
    monkeypatch.setenv("DYNATEX_PYTHON", python)
    assert verify.run_child(device).ok
