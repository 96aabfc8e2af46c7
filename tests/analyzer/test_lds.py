"""LDS learning: the noise normalisation, stability, order choice, SVD paths and memory."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.detail import workspace_bytes
from dynatex.analyzer.lds import learn_lds, stabilize, stationary_covariance

from ..conftest import wave_clip


def _known_lds(tau=400, n=6, h=16, w=16, seed=0):
    """Frames from a known stable LDS with orthonormal C (grey, values well inside 0..255)."""
    rng = np.random.default_rng(seed)
    ang = rng.uniform(0.2, 1.2, n // 2)
    a = np.zeros((n, n))
    for i, t in enumerate(ang):
        r = 0.93
        a[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = r * np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    c = np.linalg.qr(rng.standard_normal((h * w, n)))[0]
    x = np.zeros(n)
    xs = []
    for _ in range(tau):
        x = a @ x + rng.standard_normal(n) * 20
        xs.append(x)
    y = 128 + np.array(xs) @ c.T
    return np.clip(np.rint(y), 0, 255).astype(np.uint8).reshape(tau, h, w, 1), a


def test_noise_normalisation_matches_training_covariance():
    frames, a_true = _known_lds()
    m = learn_lds(frames, n=6, calibrate=False)
    train = m.states @ m.states.T / m.states.shape[1]
    # With the 1/sqrt(tau-1) factor the model's stationary covariance is the training one.
    assert abs(np.trace(m.stationary_cov) / np.trace(train) - 1) < 0.1
    np.testing.assert_allclose(
        np.sort(np.abs(np.linalg.eigvals(m.A))), np.sort(np.abs(np.linalg.eigvals(a_true))), atol=0.03
    )
    assert m.info["q_gain"] == 1.0 and m.info["poles_clipped"] == 0


def test_stability_enforced_and_reported():
    m = learn_lds(wave_clip(t=120, h=16, w=16), n=8, max_radius=0.97)
    assert m.info["spectral_radius"] <= 0.97 + 1e-9
    assert m.info["spectral_radius_raw"] > 0.97
    assert m.info["poles_clipped"] >= 2
    np.testing.assert_allclose(
        m.stationary_cov, m.A @ m.stationary_cov @ m.A.T + m.B @ m.B.T, atol=1e-6 * np.abs(m.stationary_cov).max()
    )


def test_stabilize_and_lyapunov_helpers():
    a = np.array([[1.02, 0.1], [0.0, 0.5]])
    s, radius, moved = stabilize(a, 0.9)
    assert radius == pytest.approx(1.02) and moved == 1
    assert np.max(np.abs(np.linalg.eigvals(s))) == pytest.approx(0.9)
    q = np.eye(2)
    p = stationary_covariance(s, q)
    np.testing.assert_allclose(p, s @ p @ s.T + q, atol=1e-9)


def test_auto_order_and_energy():
    m = learn_lds(wave_clip(t=80, h=16, w=16), n="auto", energy=0.95)
    assert 2 <= m.n <= 50 and m.info["n_auto"]
    assert m.info["energy_captured"] >= 0.95
    smaller = learn_lds(wave_clip(t=80, h=16, w=16), n="auto", energy=0.5)
    assert smaller.n < m.n


def test_singular_values_stored_descending():
    m = learn_lds(wave_clip(t=50, h=12, w=12), n=5)
    sv = m.singular_values
    assert sv.shape[0] >= 5 and np.all(np.diff(sv) <= 1e-6)


def test_randomized_svd_spans_the_same_subspace():
    frames = wave_clip(t=90, h=16, w=20)
    g = learn_lds(frames, n=6, svd="gram")
    r = learn_lds(frames, n=6, svd="randomized", seed=1)
    # The two travelling waves span four well-separated components; the rest is noise.
    overlap = np.linalg.svd(g.basis[:4] @ r.basis[:4].T, compute_uv=False)
    assert overlap.min() > 0.99
    np.testing.assert_allclose(g.singular_values[:4], r.singular_values[:4], rtol=1e-3)


def test_memory_holds_one_float32_copy_of_the_clip():
    frames = wave_clip(t=60, h=64, w=64)
    clip_f32 = frames.size * 4
    n = 10
    tracemalloc.start()
    try:
        learn_lds(frames, n=n)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    basis = n * frames[0].size * 4
    detail = workspace_bytes(frames.shape)  # bounded: the noise volume's FFTs, a few residual chunks
    assert peak < clip_f32 + 3 * basis + detail + 2**20, (peak, clip_f32)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"n": 60}, "n=60 is larger than the clip allows: it has 40 frames"),
        ({"n": 0}, r"n must be an integer in 1\.\..* or one of 'auto', not 0"),
        ({"n": "many"}, r"n must be an integer in 1\.\..* or one of 'auto', not 'many'"),
        ({"n": 5, "k": 6}, "k must be an integer in 1..n=5"),
        ({"svd": "qr"}, "svd must be one of"),
        ({"energy": 1.5}, r"energy must be a finite number in \(0, 1\]"),
        ({"max_radius": 1.0}, r"max_radius must be a finite number in \(0, 1\)"),
    ],
)
def test_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match=message):
        learn_lds(wave_clip(t=40, h=8, w=8), **kwargs)


def test_degenerate_clips():
    with pytest.raises(ValueError, match="clip is constant"):
        learn_lds(np.full((20, 8, 8, 3), 77, np.uint8), n=3)
    with pytest.raises(ValueError, match="at least 3"):
        learn_lds(wave_clip(t=2, h=8, w=8), n=1)
    two_frames_alternating = np.concatenate([wave_clip(t=2, h=8, w=8)] * 10)
    with pytest.raises(ValueError, match="exceeds the clip's rank"):
        learn_lds(two_frames_alternating, n=5)


@pytest.mark.clips
def test_real_clip_analysis(clips_dir):
    clip = load_clip(clips_dir / "water_sea_waves_dyntex.avi", stop=100, size=(144, 176))
    m = learn_lds(clip)
    assert m.n == 50 and m.info["spectral_radius"] < 1
    assert m.mean.shape == (176 * 144 * 3,)


def test_weak_components_have_unit_rows_and_the_database_accepts_them(tmp_path):
    """A clip of nearly rank 2 learned with n = 3: the third row, v.T Y / s summed in float32
    with s 200 times below the first, came out 0.2% too long and the format refused it."""
    from dynatex.tiledb import DatabaseWriter, TileDB

    t = np.arange(20)[:, None, None, None]
    x = np.arange(12)[None, None, :, None]
    clip = np.repeat(
        (128 + 60 * np.sin(0.3 * t + 0.5 * x + 0 * np.arange(8)[None, :, None, None])).astype(np.uint8), 3, axis=3
    )
    model = learn_lds(load_clip(clip), n=3)
    norms = np.sqrt((model.basis.astype(np.float64) ** 2).sum(axis=1))
    assert np.abs(norms - 1).max() < 1e-5
    with DatabaseWriter(tmp_path / "w.h5") as w:
        w.put_texture("w", load_clip(clip).source_info())
        w.put_method("w", "lds", model)
    with TileDB(tmp_path / "w.h5") as db:
        assert db.texture("w").read("lds").basis.shape[0] == 3
