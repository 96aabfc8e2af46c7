"""The LDS player: backends agree, edits do what they claim (measured on the output), state, errors."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.player import open_player
from dynatex.player.modes.lds import LDSPlayer, edited_poles, scale_groups, speed_dynamics
from dynatex.player.opencl.programs import build_count
from dynatex.tiledb import DatabaseWriter

from ..conftest import wave_clip

#: OpenCL and numpy sum in different orders and round at .5 differently: frames may differ
#: by one grey level on a small share of pixels, never more.
MAX_LEVEL_DIFF = 1
MAX_DIFF_SHARE = 1e-3


@pytest.fixture(scope="module")
def osc_db(tmp_path_factory):
    """A texture with one clear oscillation (a travelling wave of period 16 frames)."""
    clip = load_clip(wave_clip(t=200, h=24, w=32, seed=1, periods=(16.0,)))
    path = tmp_path_factory.mktemp("osc") / "osc.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("osc", clip.source_info())
        w.put_method("osc", "lds", learn_lds(clip, n=10))
    return path


@pytest.mark.parametrize("precision", ["float32", "float16"])
def test_opencl_matches_numpy_reference(lds_db, precision, cl_device):
    with (
        open_player(lds_db, seed=4, precision=precision, backend="opencl", device=cl_device) as pc,
        open_player(lds_db, seed=4, precision=precision, backend="numpy") as pn,
    ):
        for _ in range(20):
            a, b = pc.next_frame(), pn.next_frame()
            diff = np.abs(a.astype(int) - b)
            assert diff.max() <= MAX_LEVEL_DIFF
            assert (diff > 0).mean() <= MAX_DIFF_SHARE
        assert a.shape == (24, 32, 3) and a.dtype == np.uint8


def test_grey_texture_outputs_three_equal_channels(tmp_path):
    clip = load_clip(wave_clip(t=40, h=12, w=20, channels=1))
    path = tmp_path / "g.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("g", clip.source_info())
        w.put_method("g", "lds", learn_lds(clip, n=6))
    with open_player(path, seed=1) as pc, open_player(path, seed=1, backend="numpy") as pn:
        a, b = pc.next_frame(), pn.next_frame()
    assert a.shape == (12, 20, 3)
    assert (a[..., 0] == a[..., 1]).all() and (a[..., 1] == a[..., 2]).all()
    assert np.abs(a.astype(int) - b).max() <= MAX_LEVEL_DIFF


def test_float16_basis_psnr_above_45_db(lds_db):
    with open_player(lds_db, seed=2) as p32, open_player(lds_db, seed=2, precision="float16") as p16:
        err = []
        for _ in range(10):
            err.append((p32.next_frame().astype(float) - p16.next_frame()) ** 2)
    psnr = 10 * np.log10(255**2 / max(np.mean(err), 1e-12))
    assert psnr >= 45


def test_no_kernel_built_or_fetched_per_frame(lds_db):
    with open_player(lds_db) as p:
        before = build_count()
        out = np.empty(p.shape, np.uint8)
        for i in range(50):
            p.speed = 1 + (i % 3) * 0.5
            p.next_frame(out=out)
        assert build_count() == before


def test_deterministic_for_a_seed_and_state_restores(lds_db):
    with open_player(lds_db, seed=9) as a, open_player(lds_db, seed=9) as b, open_player(lds_db, seed=10) as c:
        fa = [a.next_frame() for _ in range(5)]
        fb = [b.next_frame() for _ in range(5)]
        fc = [c.next_frame() for _ in range(5)]
        assert all((x == y).all() for x, y in zip(fa, fb))
        assert not all((x == y).all() for x, y in zip(fa[1:], fc[1:]))
        a.speed, a.intensity, a.scales = -1.5, 2.0, (1, 0.5, 2)
        saved = a.get_state()
        first = [a.next_frame() for _ in range(5)]
        a.speed = 3
        a.next_frame()
        a.set_state(saved)
        assert a.speed == -1.5 and a.scales == (1.0, 0.5, 2.0)
        again = [a.next_frame() for _ in range(5)]
        assert all((x == y).all() for x, y in zip(first, again))


def test_edited_poles_are_powers_on_the_principal_branch():
    poles = np.array(
        [
            0.9 * np.exp(1j * 0.5),
            0.9 * np.exp(-1j * 0.5),
            0.8,
            -0.7,
            0.95 * np.exp(1j * 2.0),
            0.95 * np.exp(-1j * 2.0),
            0,
        ]
    )
    e = edited_poles(poles, 2.0)
    np.testing.assert_allclose(e[:6], poles[:6] ** 2, atol=1e-12)  # magnitudes squared too, none annihilated
    assert e[6] == 0
    h = edited_poles(poles, 0.5)
    np.testing.assert_allclose(np.abs(h[:4]), np.sqrt([0.9, 0.9, 0.8, 0.7]))
    np.testing.assert_allclose(np.angle(h[:2]), [0.25, -0.25])
    np.testing.assert_allclose(h[1], np.conj(h[0]))  # a conjugate pair stays one
    np.testing.assert_allclose(edited_poles(poles, -2.0), e)  # the sign is the basis' business
    np.testing.assert_allclose(edited_poles(poles, 0.0)[:6], 1.0)


def _random_model(n: int = 6, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A stable, non-normal transition with complex, real positive and real negative poles, and its P."""
    from dynatex.analyzer.lds import stationary_covariance

    rng = np.random.default_rng(seed)
    blocks = np.zeros((n, n))
    blocks[:2, :2] = 0.95 * np.array([[np.cos(0.4), -np.sin(0.4)], [np.sin(0.4), np.cos(0.4)]])
    blocks[2, 2], blocks[3, 3], blocks[4, 4], blocks[5, 5] = 0.9, -0.6, 0.5, 0.2
    t = rng.standard_normal((n, n)) + 3 * np.eye(n)
    a = t @ blocks @ np.linalg.inv(t)
    b = rng.standard_normal((n, 3))
    return a, stationary_covariance(a, b @ b.T)


@pytest.mark.parametrize("speed", [2.0, 3.0, -1.0, -2.0])
def test_whole_speeds_keep_the_stationary_covariance_exactly(speed):
    a, p = _random_model()
    a_s, b_s = speed_dynamics(a, p, speed)
    assert np.isrealobj(a_s) and max(abs(np.linalg.eigvals(a_s))) < 1
    np.testing.assert_allclose(a_s @ p @ a_s.T + b_s @ b_s.T, p, atol=1e-9 * np.abs(p).max())


@pytest.mark.parametrize("speed", [0.5, 1.7, -0.5, 0.1])
def test_fractional_speeds_keep_the_stationary_covariance_closely(speed):
    """A fractional power of a non-normal transition may need a little negative noise variance; it is
    clipped, so the covariance of the played process is P up to a few percent."""
    from dynatex.analyzer.lds import stationary_covariance

    a, p = _random_model()
    a_s, b_s = speed_dynamics(a, p, speed)
    assert np.isrealobj(a_s) and max(abs(np.linalg.eigvals(a_s))) < 1
    played = stationary_covariance(a_s, b_s @ b_s.T)
    assert np.linalg.norm(played - p) < 0.05 * np.linalg.norm(p)


def test_speed_two_is_two_steps_and_negative_speed_is_the_reversed_process():
    a, p = _random_model()
    np.testing.assert_allclose(speed_dynamics(a, p, 2.0)[0], a @ a, atol=1e-10)
    # Run backwards, a stationary process has its lag covariances transposed: E[x(t+1) x(t)^T] = (A P)^T.
    a_r, _ = speed_dynamics(a, p, -1.0)
    np.testing.assert_allclose(a_r @ p, (a @ p).T, atol=1e-10)
    a_r2, _ = speed_dynamics(a, p, -2.0)
    np.testing.assert_allclose(a_r2 @ p, (a @ a @ p).T, atol=1e-10)


def test_speed_zero_freezes_the_frame(lds_db):
    with open_player(lds_db, seed=3) as p:
        p.advance(5)
        p.speed = 0.0
        first = p.next_frame()
        assert all((p.next_frame() == first).all() for _ in range(5))
        p.speed = 1.0
        p.advance(3)
        assert not (p.next_frame() == first).all()


def test_scale_groups_follow_the_seed_split():
    g = scale_groups(50)
    assert (g[:5] == 0).all() and (g[5:15] == 1).all() and (g[15:] == 2).all()
    assert set(scale_groups(3)) <= {0, 1, 2} and scale_groups(1)[0] == 0


def _dominant_frequency(player: LDSPlayer, frames: int) -> float:
    """Peak of the Welch-averaged power spectrum of the output frames (cycles per frame)."""
    out = np.empty(player.shape, np.uint8)
    sig = np.empty((frames, 64))
    rng = np.random.default_rng(0)
    pix = rng.choice(out.size, 64, replace=False)
    for t in range(frames):
        player.next_frame(out=out)
        sig[t] = out.reshape(-1)[pix]
    sig -= sig.mean(axis=0)
    seg = 512
    win = np.hanning(seg)[:, None]
    power = sum(
        np.abs(np.fft.rfft(sig[i : i + seg] * win, axis=0)) ** 2 for i in range(0, frames - seg + 1, seg // 2)
    ).sum(axis=1)
    power[0] = 0
    k = int(np.argmax(power[1:-1])) + 1
    a, b, c = np.log(power[k - 1 : k + 2] + 1e-30)  # parabolic peak interpolation
    return float((k + 0.5 * (a - c) / (a - 2 * b + c)) / seg)


@pytest.mark.parametrize("speed", [2.0, 0.5])
def test_speed_scales_the_dominant_frequency(osc_db, speed):
    with open_player(osc_db, seed=5) as p1, open_player(osc_db, seed=5) as ps:
        ps.speed = speed
        f1 = _dominant_frequency(p1, 4096)
        fs = _dominant_frequency(ps, 4096)
    assert f1 > 0.03, (f1, fs)
    assert abs(fs / f1 - speed) <= 0.15 * speed


def test_negative_speed_reverses_time(osc_db):
    """The output's states, run backwards, have the forward process's lag covariances transposed:
    ``E[x(t+1) x(t)^T] = (A P)^T`` (measured on 20,000 frames), and the same energy."""
    with open_player(osc_db, seed=6) as p:
        p.speed = -1.0
        x = p.advance(20000, record=True)[1000:]
        a, cov = p._A, p.stationary_cov
    lag1 = x[1:].T @ x[:-1] / (len(x) - 1)
    scale = np.abs(cov).max()
    assert np.abs(lag1 - (a @ cov).T).max() < 0.1 * scale
    assert np.abs(lag1 - a @ cov).max() > 0.3 * scale  # the forward process's differs: this is a test
    assert abs(np.trace(x.T @ x / len(x)) / np.trace(cov) - 1) < 0.15


def test_intensity_zero_decays_to_the_mean_image(lds_db):
    with open_player(lds_db, seed=1) as p:
        model_mean = p.texture.read("lds").mean.reshape(p.texture.source.frame_shape)
        p.intensity = 0.0
        start = np.linalg.norm(p.state)
        p.advance(3000)
        assert np.linalg.norm(p.state) < 1e-3 * start
        frame = p.next_frame()
    assert np.abs(frame.astype(int) - np.rint(model_mean)).max() <= 1


def _high_band_share(frames: np.ndarray, mean: np.ndarray) -> float:
    spec = 0
    for f in frames:
        d = f.astype(float).mean(axis=2) - mean.mean(axis=2)
        spec = spec + np.abs(np.fft.fft2(d)) ** 2
    fy = np.fft.fftfreq(spec.shape[0])[:, None]
    fx = np.fft.fftfreq(spec.shape[1])[None, :]
    r = np.hypot(fx, fy)
    return float(spec[r > 0.15].sum() / spec[r > 0].sum())


@pytest.mark.clips
def test_scale_weights_move_the_spatial_spectrum(clips_dir, tmp_path):
    clip = load_clip(clips_dir / "water_sea_waves_dyntex.avi", stop=120, size=(144, 176))
    path = tmp_path / "w.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("w", clip.source_info())
        w.put_method("w", "lds", learn_lds(clip, n=40))
    shares = {}
    with open_player(path, seed=2) as p:
        mean = p.texture.read("lds").mean.reshape(p.texture.source.frame_shape)
        saved = p.get_state()
        for name, scales in {"neutral": (1, 1, 1), "coarse": (2, 1, 0.2), "fine": (0.2, 1, 2)}.items():
            p.set_state(saved)
            p.scales = scales
            shares[name] = _high_band_share(np.stack([p.next_frame() for _ in range(20)]), mean)
    assert shares["coarse"] < 0.8 * shares["neutral"] < 0.8 * shares["fine"]


@pytest.mark.parametrize(
    "attr, value, err",
    [
        ("speed", 3.5, ValueError),
        ("speed", float("nan"), ValueError),
        ("speed", "fast", TypeError),
        ("intensity", -0.1, ValueError),
        ("scales", (1, 2), ValueError),
        ("scales", (1, 2, -1), ValueError),
        ("weights", np.ones(3), ValueError),
    ],
)
def test_out_of_range_controls(lds_db, attr, value, err):
    with open_player(lds_db) as p:
        before = getattr(p, attr)
        with pytest.raises(err, match=attr.rstrip("s") if attr != "weights" else "weights"):
            setattr(p, attr, value)
        after = getattr(p, attr)
        assert np.array_equal(np.asarray(before), np.asarray(after))


def test_bad_arguments(lds_db):
    with pytest.raises(ValueError, match="backend must be one of"):
        open_player(lds_db, backend="cuda")
    with pytest.raises(ValueError, match="precision must be one of"):
        open_player(lds_db, precision="int4")
    with pytest.raises(ValueError, match="mode must be one of"):
        open_player(lds_db, mode="bogus")
    with open_player(lds_db) as p:
        with pytest.raises(ValueError, match="out must be uint8 with shape"):
            p.next_frame(out=np.empty((2, 2, 3), np.uint8))
        with pytest.raises(ValueError, match="C-contiguous"):
            p.next_frame(out=np.empty((32, 24, 3), np.uint8).transpose(1, 0, 2))
        with pytest.raises(ValueError, match="seed"):
            p.reseed(-1)
        with pytest.raises(ValueError, match="state must come from"):
            p.set_state({"mode": "tiles"})


def test_double_buffering_gives_the_same_frames(lds_db):
    with open_player(lds_db, seed=8) as sync, open_player(lds_db, seed=8) as pipe:
        bufs = [np.empty(pipe.shape, np.uint8) for _ in range(2)]
        pending = pipe.start_frame(bufs[0])
        for i in range(1, 12):
            nxt = pipe.start_frame(bufs[i % 2]) if i < 11 else None
            frame = pending.wait()
            np.testing.assert_array_equal(frame, sync.next_frame())
            pending = nxt
        assert pipe.frame_index == sync.frame_index == 11
