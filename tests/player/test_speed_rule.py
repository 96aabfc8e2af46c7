"""The rule by which ``backend="auto"`` takes OpenCL or numpy per engine: the self-test's speed
figures (per-round ratios of alternating rounds), when they decide, when they are measured
again, and the shape they are cached in. Synthetic timings only: nothing here is timed."""

from __future__ import annotations

import dataclasses
import json
import time

import pytest

from dynatex.child import Outcome
from dynatex.player.engines.projection import SPEED_PER_PASS, speed_case
from dynatex.player.opencl import selftest, verify
from dynatex.player.opencl.devices import DeviceInfo

NOW = 1.8e9
CONFIG = "numpy 2.0; 2 of 2 cpus"


def figure(ratios, *, at=NOW, config=CONFIG, measures=1):
    return verify.speed_figure(ratios, at=at, config=config, measures=measures)


@pytest.mark.parametrize(
    ("ratios", "opencl", "settled"),
    [
        ([1.6, 1.5, 1.7, 1.4, 1.6, 1.55, 1.65], True, True),  # clearly faster
        ([0.7, 0.8, 0.75, 0.6, 0.8, 0.7, 0.72], False, True),  # clearly slower
        ([1.0, 1.02, 0.98, 1.05, 0.99, 1.01, 1.0], False, False),  # a tie is numpy's
        ([1.08, 1.09, 1.05, 1.07, 1.09, 1.06, 1.08], False, False),  # faster, but within the margin
        ([0.5, 0.6, 1.3, 1.4, 1.5, 1.6, 0.55], False, False),  # swung by the load: median 1.3, lost 3 of 7
        ([1.12, 1.3, 1.0, 1.25, 1.15, 1.2, 1.05], True, False),  # faster, not clearly enough to be settled
        ([], False, False),
    ],
)
def test_auto_takes_opencl_only_where_it_was_clearly_faster(ratios, opencl, settled):
    assert verify.prefers_opencl(ratios) is opencl
    assert verify.speed_settled(ratios) is settled
    assert figure(ratios)["opencl"] is opencl if ratios else True


def test_the_median_of_rounds_is_not_moved_by_a_few_rounds_under_load():
    """A round of seven hit by load on one side leaves the choice as it was; two of seven (more
    than one in four) make it unclear, and unclear is numpy's."""
    hit_once = [1.5, 0.2, 1.5, 1.6, 1.5, 1.5, 1.45]
    assert verify.prefers_opencl(hit_once) and figure(hit_once)["ratio"] == 1.5
    hit_twice = [1.5, 0.2, 1.5, 1.6, 1.5, 1.5, 0.25]
    assert not verify.prefers_opencl(hit_twice) and not verify.speed_settled(hit_twice)


def test_a_cached_figure_holds_its_rounds_summary_choice_and_provenance():
    f = figure([1.2, 1.4, 1.3, 1.25, 1.35])
    assert set(f) == {"ratio", "low", "high", "opencl", "settled", "rounds", "measures", "at", "config"}
    assert f["ratio"] == 1.3 and f["low"] == 1.25 and f["high"] == 1.35
    assert (f["opencl"], f["settled"], f["measures"], f["at"], f["config"]) == (True, True, 1, NOW, CONFIG)
    assert json.loads(json.dumps(f)) == f  # the cache is JSON
    many = figure([1.0 + k / 1000 for k in range(100)])
    assert len(many["rounds"]) == verify.KEEP_ROUNDS and many["rounds"][-1] == 1.099  # the newest kept


def test_a_verdict_with_figures_survives_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DYNATEX_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(verify, "_verdicts", {})
    monkeypatch.setattr(verify, "_sources_hash", lambda: "0" * 16)
    info = DeviceInfo("9:0", "Test platform", "Test 1.0", "dev", "vendor", "1.0", True)
    v = verify.Verdict(True, device=info.describe(), speed={"projection float32 352x288": figure([1.5] * 7)})
    verify._write_cache(verify.cache_key(info), v)
    monkeypatch.setattr(verify, "_verdicts", {})
    assert verify.cached_verdict(info) == v


def test_pooling_adds_a_measurement_in_the_same_configuration_and_starts_afresh_in_another():
    old = figure([1.0, 1.3, 0.9, 1.2, 1.1, 1.4, 0.95], at=NOW - 3600)
    same = verify.pooled_figure(old, [1.5] * 7, at=NOW, config=CONFIG)
    assert same["measures"] == 2 and len(same["rounds"]) == 14 and same["at"] == NOW
    other = verify.pooled_figure(old, [1.5] * 7, at=NOW, config="numpy 2.1; 2 of 2 cpus")
    assert other["measures"] == 1 and other["rounds"] == [1.5] * 7
    stale = verify.pooled_figure(old, [1.5] * 7, at=NOW + verify.MAX_AGE_S, config=CONFIG)
    assert stale["measures"] == 1


def test_a_figure_is_measured_again_when_unsettled_old_or_from_another_configuration():
    def stale(f, now=NOW + verify.REMEASURE_S, config=CONFIG):
        return verify.speed_stale(f, now=now, config=config)

    clear, close = figure([1.6] * 7), figure([1.0, 1.3, 0.9, 1.2, 1.1, 1.4, 0.95])
    assert stale(clear) is None
    assert stale(None) == stale({"ratio": 1.2}) == "not measured"  # absent, or cached in an older shape
    assert stale(clear, config="numpy 2.1; 1 of 2 cpus") == "measured in another configuration"
    assert stale(clear, now=NOW + 40 * 86400) == "measured 40 days ago"
    assert stale(close) == "close to numpy's rate"
    assert stale(close, now=NOW + 1) is None  # not again at once: the next measurement waits for other conditions
    assert stale(dict(close, measures=verify.MAX_MEASURES)) is None  # pooled enough: it decides as it is


def test_a_player_takes_the_figure_of_the_nearest_measured_size_and_rows():
    assert speed_case("float32", 24 * 32 * 3, 1) == "projection float32 352x288"
    assert speed_case("float16", 288 * 352, 1) == "projection float16 352x288"  # grey
    assert speed_case("float32", 720 * 1280 * 3, 4) == f"projection float32 1280x720, {SPEED_PER_PASS} per pass"
    assert speed_case("float32", 1080 * 1920 * 3, 1) == "projection float32 1280x720"
    assert speed_case("float32", 288 * 352 * 3, 1, detail=True) == "projection float32 352x288, detail"
    # and the nearest measured basis rows: the stand-in's 50 go unnamed
    assert speed_case("float32", 288 * 352 * 3, 1, rows=40) == "projection float32 352x288"
    assert speed_case("float32", 288 * 352 * 3, 1, rows=6) == "projection float32 352x288, 16 rows"
    assert speed_case("float16", 720 * 1280 * 3, 8, True, 400) == (
        f"projection float16 1280x720, 150 rows, {SPEED_PER_PASS} per pass, detail"
    )
    assert set(selftest.SPEED_CASES) == {
        speed_case(p, h * w * 3, k, d, n)
        for p in ("float32", "float16")
        for h, w in ((288, 352), (720, 1280))
        for k in (1, 8)
        for d in (False, True)
        for n in (16, 50, 150)
    }
    assert len(selftest.SELFTEST_SPEED_CASES) == 8 and all("352x288" in e for e in selftest.SELFTEST_SPEED_CASES)


def test_rounds_alternate_which_goes_first_and_stop_once_settled(monkeypatch):
    """With a clock that only the fake calls move: numpy twice as slow in every round."""
    clock = [0.0]
    order: list[str] = []

    def call(name, cost):
        def f():
            order.append(name)
            clock[0] += cost

        return f

    monkeypatch.setattr(selftest.time, "perf_counter", lambda: clock[0])
    ratios = selftest.measure_rounds(call("opencl", 0.1), call("numpy", 0.2), block_s=0.4)
    # a round takes 0.4 + 0.2 s: settled once MIN_ROUNDS rounds and MIN_SECONDS have passed
    rounds = max(verify.MIN_ROUNDS, int(-(-verify.MIN_SECONDS // 0.6)))
    assert ratios == pytest.approx([2.0] * rounds)
    timed = order[3:]  # after the warm-up calls and the calibration
    blocks = [timed[k : k + 2] for k in range(0, len(timed), 2)]  # 2 calls of 20 ms make a 40 ms block
    assert all(len(set(b)) == 1 for b in blocks) and blocks[0][0] == "numpy" and blocks[2][0] == "opencl"


def test_rounds_continue_while_unsettled_up_to_the_limit(monkeypatch):
    """OpenCL 5% faster, then 5% slower, round after round: never settled, so the most rounds."""
    clock = [0.0]
    calls = [0]

    def opencl():
        calls[0] += 1
        clock[0] += 0.01 / (1.05 if calls[0] % 2 else 0.95)

    def numpy():
        clock[0] += 0.01

    monkeypatch.setattr(selftest.time, "perf_counter", lambda: clock[0])
    ratios = selftest.measure_rounds(opencl, numpy, block_s=0.01)
    assert len(ratios) == verify.MAX_ROUNDS and not verify.speed_settled(ratios)
    assert not verify.prefers_opencl(ratios)


def test_a_stale_figure_is_measured_again_in_a_child_and_pooled(tmp_path, monkeypatch):
    monkeypatch.setenv("DYNATEX_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(verify, "_verdicts", {})
    monkeypatch.setattr(verify, "_speed_failed", set())
    monkeypatch.setattr(verify, "_sources_hash", lambda: "0" * 16)
    info = DeviceInfo("9:0", "Test platform", "Test 1.0", "dev", "vendor", "1.0", True)
    engine = "projection float32 352x288"
    close = figure(
        [1.0, 1.3, 0.9, 1.2, 1.1, 1.4, 0.95], at=time.time() - verify.REMEASURE_S - 1, config=verify.speed_config()
    )
    v = verify.Verdict(True, device=info.describe(), speed={engine: close})
    verify._write_cache(verify.cache_key(info), v)
    asked = []

    def fake_call(target, info_dict, engines, figures, timeout):
        asked.append((target, engines))
        return Outcome(0, timeout, 1.0, 0, value={e: [1.6] * 7 for e in engines})

    monkeypatch.setattr(verify, "call", fake_call)
    got = verify.speed(info, engine)
    assert asked == [("dynatex.player.opencl.selftest:speed_main", [engine])]
    assert got["measures"] == 2 and len(got["rounds"]) == 14 and got["opencl"]
    monkeypatch.setattr(verify, "_verdicts", {})
    assert verify.cached_verdict(info).speed[engine] == got  # cached
    assert verify.speed(info, engine) == got and len(asked) == 1  # now recent: not again

    def failing_call(target, info_dict, engines, figures, timeout):
        return Outcome(1, timeout, 1.0, 0)

    other = "projection float16 352x288"
    monkeypatch.setattr(verify, "call", failing_call)
    assert verify.speed(info, other) is None  # never measured, and the measurement failed: nothing decides
    monkeypatch.setattr(verify, "call", fake_call)
    assert verify.speed(info, other) is None and len(asked) == 1  # not tried again in this process
    assert dataclasses.asdict(verify.cached_verdict(info))["speed"].keys() == {engine}


def test_check_leaves_the_choice_of_what_is_due_to_the_child(tmp_path, monkeypatch):
    """``--check`` measures every engine due: the plumbing does not import the self-test's cases,
    so the child finds them from the figures it is given, and starts nothing when none is due
    (a case of other basis rows than the self-test's is due only once a player measured it)."""
    monkeypatch.setenv("DYNATEX_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(verify, "_verdicts", {})
    monkeypatch.setattr(verify, "_sources_hash", lambda: "0" * 16)
    info = DeviceInfo("9:0", "Test platform", "Test 1.0", "dev", "vendor", "1.0", True)
    fresh = {e: figure([1.6] * 7, at=time.time(), config=verify.speed_config()) for e in selftest.SPEED_CASES}
    assert selftest.speed_main(dataclasses.asdict(info), None, fresh) == {}  # the device is not even looked for
    # other basis rows than the self-test's are measured by a player that needs them, not by --check
    rows50 = {e: f for e, f in fresh.items() if " rows" not in e}
    assert len(rows50) == len(fresh) // 3 and selftest.speed_main(dataclasses.asdict(info), None, rows50) == {}
    verify._write_cache(verify.cache_key(info), verify.Verdict(True, device=info.describe(), speed=fresh))
    asked = []

    def fake_call(target, info_dict, engines, figures, timeout):
        asked.append((engines, figures))
        return Outcome(0, timeout, 1.0, 0, value={})

    monkeypatch.setattr(verify, "call", fake_call)
    assert verify.refresh_speeds(info).speed == fresh
    assert asked == [(None, fresh)]


def test_a_projection_player_asks_for_the_figure_of_its_own_basis_rows(lds_db, monkeypatch):
    """``backend="auto"`` decides an lds player by the figure nearest its basis (12 rows: the 16-row one)."""
    from dynatex.player import open_player
    from dynatex.player.opencl import context

    from ..conftest import verified_devices

    if not verified_devices():
        pytest.skip("no verified OpenCL device here: auto decides between OpenCL and numpy only with one")
    asked = []
    monkeypatch.setattr(context, "engine_speed", lambda device, engine: asked.append(engine))  # never measured
    with open_player(lds_db, mode="lds") as p:
        assert p.backend == "opencl"
    assert len(asked) == 1 and asked[0].startswith("projection float32 352x288, 16 rows"), asked
