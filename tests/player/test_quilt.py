"""Mode ``evolve``: OpenCL against the numpy reference, the time jitter (monotone, within e,
copies of one block desynchronised), the rate map (M = 2 reaches the end in half the time,
a smoothed boundary shows no seam), end modes, state, controls and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.metrics import seam_visibility
from dynatex.analyzer.quilt import learn_quilt, spreading_clip
from dynatex.player import open_player
from dynatex.player.engines.runs import RATE_STEP, quantize_rate
from dynatex.player.modes import ratemap
from dynatex.player.modes.evolve import ENDS, EvolvePlayer, fold_time, jitter_warp
from dynatex.tiledb import DatabaseWriter, MethodNotFoundError, QuiltModel

from ..conftest import best_backend


def write_db(path, frames, model, name="s"):
    clip = load_clip(frames)
    with DatabaseWriter(path) as w:
        w.put_texture(name, clip.source_info())
        w.put_frames(name, clip.frames)
        w.put_method(name, "quilt", model)
    return path


@pytest.fixture(scope="module")
def spread_db(tmp_path_factory):
    frames = spreading_clip(24, 32, 32)
    q = learn_quilt(frames, size=(56, 72), block=12, rank=6, lowpass=6.0, seed=1)
    assert q.blend_weight is not None and q.gain is not None
    return write_db(tmp_path_factory.mktemp("evolve") / "s.h5", frames, q), frames, q


def step_db(tmp_path, t=30, switch=12):
    """Source: a 8x8 block that turns from dark to light at frame ``switch``; the quilt tiles
    four copies of that one source block (blocks 0..3) on a 16x16 canvas."""
    frames = np.full((t, 8, 8, 3), 40, np.uint8)
    frames[switch:] = 220
    frames[:, ::2, ::2] += 10  # some texture
    yy, xx = np.mgrid[0:16, 0:16]
    smap = np.stack([yy % 8, xx % 8], axis=-1).astype(np.int32)
    labels = ((yy // 8) * 2 + xx // 8).astype(np.int32)
    model = QuiltModel(
        source_map=smap,
        labels=labels,
        block_sources=np.zeros((4, 2), np.int32),
        block_positions=np.array([[0, 0], [0, 8], [8, 0], [8, 8]], np.int32),
        singular_values=np.ones(3),
        rank_error=np.array([0.1, 0.05, 0.0]),
        info={"block_h": 8, "block_w": 8},
    )
    return write_db(tmp_path / "step.h5", frames, model)


# -- OpenCL == numpy ---------------------------------------------------------------------------------
@pytest.mark.parametrize("end", ENDS)
def test_opencl_matches_numpy(spread_db, cl_device, end):
    path = spread_db[0]
    rate = ratemap.point_light((56, 72), (10, 40), 20.0, max_rate=3.0, min_rate=0.5)
    opts = dict(jitter=3.0, end=end, seed=4)
    with (
        EvolvePlayer(path, backend="numpy", **opts) as ref,
        EvolvePlayer(path, backend="opencl", device=cl_device, **opts) as cl,
    ):
        exact = 0
        for k in range(40):
            if k == 20:
                ref.rate_map = cl.rate_map = rate
                ref.rate_sigma = cl.rate_sigma = 2.0
                ref.speed = cl.speed = 1.7
            a, b = ref.next_frame(), cl.next_frame()
            diff = np.abs(a.astype(int) - b)
            assert diff.max() <= 1, k  # float32 on both sides; contracted multiply-adds may round apart
            exact += bool(diff.max() == 0)
        assert exact >= 30


@pytest.mark.parametrize("interpolate", [True, False])
def test_opencl_matches_numpy_rate_classes(spread_db, cl_device, interpolate):
    """Rate maps cut into runs of constant (quantized) rate: halves, a smoothed band, many
    steps that are not multiples of the quantization step."""
    path = spread_db[0]
    h, w = 56, 72
    stairs = np.repeat(np.linspace(0.5, 3.0, 12, dtype=np.float32), -(-w // 12))[:w]
    maps = [
        (ratemap.halves((h, w), 2.0, 1.0), 0.0),
        (ratemap.halves((h, w), 2.0, 1.0), 3.0),
        (np.tile(stairs, (h, 1)), 0.0),
    ]
    opts = dict(jitter=2.5, seed=2, interpolate=interpolate, end="pingpong")
    with (
        EvolvePlayer(path, backend="numpy", **opts) as ref,
        EvolvePlayer(path, backend="opencl", device=cl_device, **opts) as cl,
    ):
        exact = total = 0
        for rate, sigma in maps:
            ref.rate_map = cl.rate_map = rate
            ref.rate_sigma = cl.rate_sigma = sigma
            for t in (0.0, 3.3, 11.7, 25.2, 40.9):
                a, b = ref.render_at(t), cl.render_at(t)
                diff = np.abs(a.astype(int) - b)
                assert diff.max() <= 1, (sigma, t)
                exact += bool(diff.max() == 0)
                total += 1
        assert exact >= total - 3


def test_integer_times_copy_source_pixels(spread_db):
    """No jitter, rate 1, integer time, no gain/blend: a frame is the source frame through the map."""
    path, frames, _ = spread_db
    q = learn_quilt(frames, size=(40, 40), block=10, rank=4, feather=0, seed=0)
    p2 = write_db(path.parent / "plain.h5", frames, q)
    with EvolvePlayer(p2) as p:
        for t in (0, 5, 23):
            np.testing.assert_array_equal(p.render_at(float(t)), frames[t][q.source_map[..., 0], q.source_map[..., 1]])


# -- jitter ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("end", ENDS)
@pytest.mark.parametrize("e", [0.0, 1.0, 4.5, 12.0])
def test_warp_monotone_within_e(e, end):
    w = jitter_warp(50, 40, e, end=end, seed=7)
    k = np.arange(41)
    last = 40 if end == "loop" else 39
    assert w.shape == (50, 41) and w.dtype == np.float32
    assert (np.diff(w, axis=1) >= 0).all()
    assert np.abs(w - np.minimum(k, last)).max() <= e + 1e-5
    assert (w[:, 0] == 0).all() and np.allclose(w[:, last], last)  # starts and ends on the true frame
    if e >= 1:
        assert np.abs(w - np.minimum(k, last)).max() > 0.5 * e  # it does jitter
        assert len({tuple(r) for r in np.round(w, 4)}) == 50  # every block its own warp


def test_jitter_desynchronises_copies_of_one_block(tmp_path):
    path = step_db(tmp_path)
    e = 4.0

    def switch_frames(jitter):
        with EvolvePlayer(path, jitter=jitter, interpolate=False, seed=3) as p:
            frames = np.stack([p.next_frame() for _ in range(30)])
            labels = p.labels
            times = np.stack([p.source_times(float(t)) for t in range(30)])
        first = {}
        for b in range(4):
            light = frames[:, labels == b, 0].mean(axis=1) > 130
            first[b] = int(np.argmax(light))
            # the time function of every pixel of the block is monotone and within e of the true time
            tb = times[:, labels == b]
            assert (np.diff(tb, axis=0) >= -1e-6).all()
            assert np.abs(tb - np.arange(30)[:, None].clip(0, 29)).max() <= jitter + 1e-5
        return first

    plain = switch_frames(0.0)
    assert set(plain.values()) == {12}  # without jitter, all copies change together
    jittered = switch_frames(e)
    assert len(set(jittered.values())) >= 3  # with jitter they no longer do
    assert all(abs(f - 12) <= e + 1 for f in jittered.values())


# -- rate map ----------------------------------------------------------------------------------------
def region_progress(frames, mask):
    """Per-frame appearance statistic of a region: mean colour, as a fraction of the way from first to last."""
    means = frames[:, mask].astype(float).mean(axis=1)
    span = means[-1] - means[0]
    return ((means - means[0]) @ span) / (span @ span)


def reach_time(progress, level=0.95):
    return int(np.argmax(progress >= level))


def test_rate_two_reaches_the_end_in_half_the_time(spread_db):
    path = spread_db[0]
    with EvolvePlayer(path, backend="numpy") as p:
        h, w = p.shape[:2]
        p.rate_map = ratemap.halves((h, w), 2.0, 1.0)
        frames = np.stack([p.next_frame() for _ in range(26)])
    left = np.zeros((h, w), bool)
    left[:, : w // 2] = True
    tl, tr = reach_time(region_progress(frames, left)), reach_time(region_progress(frames, ~left))
    assert tr >= 18 and abs(tl / tr - 0.5) <= 0.1, (tl, tr)


def test_rate_map_semantics(spread_db):
    path = spread_db[0]
    with EvolvePlayer(path, backend="numpy", end="hold") as p:
        h, w = p.shape[:2]
        m = np.zeros((h, w), np.float32)
        m[:, 10:] = 0.5
        p.rate_map = m
        st = p.source_times(10.0)
        assert np.allclose(st[:, :10], 0) and np.allclose(st[:, 10:], 5.0)
        p.rate_sigma = 3.0
        eff = p.effective_rate
        assert 0 < eff[0, 9] < 0.5 and eff.shape == (h, w)
        np.testing.assert_array_equal(p.rate_map, m)  # the raw map is kept
        p.rate_map = None
        assert np.allclose(p.source_times(7.0), 7.0)


# -- end modes ---------------------------------------------------------------------------------------
def test_fold_time_end_modes():
    tau = np.array([-2, 0, 5.5, 9, 10, 13, 18, 19.5], np.float32)
    np.testing.assert_allclose(fold_time(tau, 10, "hold"), [0, 0, 5.5, 9, 9, 9, 9, 9])
    np.testing.assert_allclose(fold_time(tau, 10, "loop"), [8, 0, 5.5, 9, 0, 3, 8, 9.5])
    np.testing.assert_allclose(fold_time(tau, 10, "pingpong"), [2, 0, 5.5, 9, 8, 5, 0, 1.5])


def test_end_control_changes_playback_after_the_last_frame(tmp_path):
    path = step_db(tmp_path, t=20, switch=10)
    with EvolvePlayer(path, interpolate=False) as p:
        for end, expect_light in (("hold", True), ("loop", False), ("pingpong", True)):
            p.end = end
            assert bool(p.render_at(21.0)[0, 0, 0] > 130) == expect_light, end
        p.end = "pingpong"
        assert p.render_at(30.0)[0, 0, 0] < 130  # back below the switch on the way down


# -- state, controls, bad input ----------------------------------------------------------------------
def test_state_round_trip(spread_db):
    path = spread_db[0]
    with EvolvePlayer(path, jitter=2.0, seed=5) as p, EvolvePlayer(path, seed=0) as q:
        p.rate_map = ratemap.halves(p.shape[:2], 1.5, 0.5)
        p.end = "loop"
        for _ in range(7):
            p.next_frame()
        state = p.get_state()
        q.set_state(state)
        for _ in range(5):
            np.testing.assert_array_equal(p.next_frame(), q.next_frame())
        np.testing.assert_array_equal(p.warp, q.warp)


def test_open_player_and_deterministic(spread_db):
    path = spread_db[0]
    with (
        open_player(path, mode="evolve", jitter=3.0, seed=9) as a,
        open_player(path, mode="evolve", jitter=3.0, seed=9) as b,
    ):
        assert isinstance(a, EvolvePlayer)
        for _ in range(4):
            np.testing.assert_array_equal(a.next_frame(), b.next_frame())


def test_kernels_built_once(spread_db, cl_context):
    from dynatex.player.opencl.programs import build_count

    path = spread_db[0]
    with EvolvePlayer(path) as p:
        p.rate_map = ratemap.halves(p.shape[:2])
        before = build_count()
        for _ in range(3):
            p.next_frame()
        p.rate_map = None
        p.end = "loop"
        p.jitter = 5.0
        p.next_frame()
        assert build_count() == before


@pytest.mark.parametrize(
    "control, value, error, message",
    [
        ("rate_map", np.ones((5, 5)), ValueError, "rate_map is 5x5 .* the output is 72x56"),
        ("rate_map", -np.ones((56, 72)), ValueError, r"rate_map values must lie in \[0, 64\]"),
        ("rate_map", np.full((56, 72), np.nan), ValueError, "NaN or infinite"),
        ("rate_map", np.full((56, 72), np.inf), ValueError, "NaN or infinite"),
        ("rate_map", [[1.0]], TypeError, "rate_map must be a numpy array"),
        ("rate_sigma", -1, ValueError, "rate_sigma"),
        ("jitter", 100, ValueError, "jitter"),
        ("end", "bounce", ValueError, "end must be one of"),
        ("speed", float("nan"), ValueError, "speed"),
    ],
)
def test_bad_controls(spread_db, control, value, error, message):
    with EvolvePlayer(spread_db[0], backend="numpy") as p:
        with pytest.raises(error, match=message):
            setattr(p, control, value)


def test_bad_open(spread_db, lds_db):
    with pytest.raises(
        ValueError,
        match=r"size \(72, 56\) does not fit the stored quilt, whose canvas \(height, "
        r"width\) is \(56, 72\)",
    ):
        EvolvePlayer(spread_db[0], size=(72, 56))
    with pytest.raises(MethodNotFoundError, match="no 'quilt' data"):
        EvolvePlayer(lds_db)


def test_ratemap_generators():
    m = ratemap.point_light((40, 60), (30, 20), 10.0, max_rate=2.0, min_rate=0.5)
    assert m.shape == (40, 60) and abs(m.max() - 2.0) < 1e-6 and m.min() >= 0.5
    assert np.unravel_index(np.argmax(m), m.shape) == (20, 30)
    img = np.zeros((4, 4, 3), np.uint8)
    img[:2] = 255
    r = ratemap.from_image(img, low=1.0, high=2.0)
    assert np.allclose(r[:2], 2.0) and np.allclose(r[2:], 1.0)
    with pytest.raises(ValueError, match="height must be positive"):
        ratemap.point_light((4, 4), (1, 1), 0.0)
    with pytest.raises(ValueError, match="image values"):
        ratemap.from_image(np.full((3, 3), 2.0))
    with pytest.raises(ValueError, match=r"shape must be \(height, width\) with each side in 1\.\.16384, not \(0, 4\)"):
        ratemap.halves((0, 4))
    with pytest.raises(TypeError, match=r"shape must be \(height, width\) integers, not \(4\.5, 4\)"):
        ratemap.uniform((4.5, 4))


# -- must show on a real clip --------------------------------------------------------------------------
@pytest.mark.clips
@pytest.mark.slow
def test_rate_map_on_rusting_steel(clips_dir, tmp_path):
    """M = 2 on the left, 1 on the right: the left reaches the final appearance in half the time;
    with the boundary smoothed (sigma 16 px) there is no seam between the halves."""
    clip = load_clip(clips_dir / "timevarying_rusting_steel.gif")
    q = learn_quilt(clip, size=(192, 192), seed=0)
    path = write_db(tmp_path / "rust.h5", clip.frames, q)
    n = clip.n_frames
    with EvolvePlayer(path, backend=best_backend()) as p:
        h, w = p.shape[:2]
        p.rate_map = ratemap.halves((h, w), 2.0, 1.0)
        frames = np.stack([p.next_frame() for _ in range(n)])
        left = np.zeros((h, w), bool)
        left[:, : w // 2] = True
        tl, tr = reach_time(region_progress(frames, left)), reach_time(region_progress(frames, ~left))
        assert abs(tl / tr - 0.5) <= 0.08, (tl, tr)
        sharp = seam_visibility(np.stack([p.render_at(t) for t in (20.0, 35.0, 50.0)]), left.astype(np.int32))
        p.rate_sigma = 16.0
        smooth = seam_visibility(np.stack([p.render_at(t) for t in (20.0, 35.0, 50.0)]), left.astype(np.int32))
    assert smooth.mean() <= 1.2 and smooth.mean() < sharp.mean(), (smooth, sharp)


def test_reseed_draws_new_jitter(spread_db):
    path, _, _ = spread_db
    with open_player(path, mode="evolve", seed=3, backend="numpy") as p:
        p.jitter = 3.0
        first = p.warp.copy()
        p.reseed(4)
        assert not np.array_equal(p.warp, first)
        p.reseed(3)
        np.testing.assert_array_equal(p.warp, first)
        with pytest.raises(ValueError, match="seed must be a non-negative integer"):
            p.reseed(-2)


def test_rate_map_quantized_and_copy_path(spread_db, cl_device):
    """Both backends play the rate map quantized to RATE_STEP (so the OpenCL runs have one
    rate each); frames copied from the device buffer equal those written into the caller's array."""
    path = spread_db[0]
    rate = ratemap.point_light((56, 72), (10, 40), 20.0, max_rate=3.0, min_rate=0.5)
    with EvolvePlayer(path, jitter=2.0, seed=3, rate_map=rate, rate_sigma=2.0) as p:
        eff = p.effective_rate
        np.testing.assert_array_equal(eff, quantize_rate(eff))
        q = np.rint(eff.astype(np.float64) / RATE_STEP)
        assert np.abs(q * RATE_STEP - eff).max() == 0
        frames = [p.render_at(t) for t in (4.2, 13.9)]
        p.engine.out.direct = not p.engine.out.direct
        for t, f in zip((4.2, 13.9), frames):
            np.testing.assert_array_equal(p.render_at(t), f)


# -- hostile maps: no read outside the frame stack ----------------------------------------------------
_RENDER_CHILD = """
import sys, numpy as np
from dynatex.player.modes.evolve import EvolvePlayer
with EvolvePlayer(sys.argv[1], backend="opencl", device=sys.argv[2], jitter=2.0) as cl, \\
        EvolvePlayer(sys.argv[1], backend="numpy", jitter=2.0) as ref:
    d = max(int(np.abs(cl.next_frame().astype(int) - ref.next_frame()).max()) for _ in range(5))
print("maxdiff", d)
"""


@pytest.mark.parametrize("mutation", ["blend_map zeros", "blend_weight transposed"])
def test_maps_whose_bands_extend_outside_the_frames_render_safely(spread_db, cl_device, tmp_path, mutation):
    """Maps that pass validation but whose cross-fade streams, extended over a merged plain run,
    would leave the source frame (found by a mutation probe: SIGSEGV on OpenCL): the runs are
    not merged there, and the device renders what the reference does. Run in a child process,
    so that a regression fails this test instead of killing the suite."""
    import shutil
    import subprocess
    import sys

    import h5py

    path = tmp_path / "mutant.h5"
    shutil.copy(spread_db[0], path)
    with h5py.File(path, "r+") as f:
        (name,) = f["textures"].keys()
        g = f[f"textures/{name}/quilt"]
        if mutation == "blend_map zeros":
            g["blend_map"][...] = 0
        else:
            w = g["blend_weight"][...]
            del g["blend_weight"]
            g["blend_weight"] = np.ascontiguousarray(w[::-1, ::-1])  # same values and shape, other pixels
    done = subprocess.run(
        [sys.executable, "-c", _RENDER_CHILD, str(path), cl_device], capture_output=True, text=True, timeout=240
    )
    assert done.returncode == 0, (done.returncode, done.stderr[-500:])
    assert int(done.stdout.split()[-1]) <= 1
