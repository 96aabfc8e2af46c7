"""Quilting of spatio-temporal cuboids: the SVD and its error per rank, block comparison,
the DP cut, the quilt itself (verbatim copies, same cut for every frame, any canvas,
elongated blocks, gain), bad input, and the must-show figures on the real time-lapse clips."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.metrics import seam_visibility
from dynatex.analyzer.quilt import (
    block_errors,
    learn_quilt,
    measure_comparison_speedup,
    min_cut_path,
    pixel_time_matrix,
    rank_errors,
    spreading_clip,
    time_svd,
)
from tests.conftest import wave_clip


def render(frames, q, t):
    """Numpy gather of a quilt (no jitter, rate 1): the analyzer-side check of what it stores."""
    f = frames[t].astype(np.float32)
    out = f[q.source_map[..., 0], q.source_map[..., 1]]
    if q.blend_weight is not None:
        a = q.blend_weight[..., None]
        out = (1 - a) * out + a * f[q.blend_map[..., 0], q.blend_map[..., 1]]
    if q.gain is not None:
        out = out * q.gain
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


# -- SVD -----------------------------------------------------------------------------------------
def test_pixel_time_matrix_rows_are_time_sequences():
    f = wave_clip(6, 4, 5)
    x = pixel_time_matrix(f)
    assert x.shape == (20, 18)
    np.testing.assert_array_equal(x[7].reshape(6, 3), f[:, 1, 2])


@pytest.mark.parametrize("shape", [(40, 9), (9, 40)])
def test_time_svd_matches_numpy_svd(shape):
    x = np.random.default_rng(0).random(shape).astype(np.float32) * 100
    coef, s, err = time_svd(x, rank=4)
    s_ref = np.linalg.svd(x.astype(np.float64), compute_uv=False)
    np.testing.assert_allclose(s, s_ref, rtol=1e-4)
    # error of the rank-k truncation from the exact reconstruction
    u, sv, vt = np.linalg.svd(x.astype(np.float64), full_matrices=False)
    for k in (1, 4, len(sv)):
        xk = (u[:, :k] * sv[:k]) @ vt[:k]
        np.testing.assert_allclose(err[k - 1], np.linalg.norm(x - xk) / np.linalg.norm(x), atol=1e-5)
    # the coefficients preserve the distances of the rank-k projection
    proj = u[:, :4] * sv[:4]
    d_ref = np.linalg.norm(proj[0] - proj[5])
    assert abs(np.linalg.norm(coef[0] - coef[5]) - d_ref) < 1e-3 * max(d_ref, 1)
    assert np.all(np.diff(err) <= 1e-12) and err[-1] < 1e-3


def test_rank_errors_small_for_low_rank_clip():
    t = np.linspace(0, 1, 15)[:, None, None, None]
    f = (50 + 100 * t * np.random.default_rng(1).random((1, 8, 8, 3))).astype(np.uint8)
    err = rank_errors(f)
    assert err[3] < 0.02 < err[0]  # 50 + 100 t r(x, c): rank 4 (a constant, t per channel) plus rounding


# -- comparison and cut ---------------------------------------------------------------------------
def test_block_errors_match_brute_force():
    rng = np.random.default_rng(3)
    feats = rng.random((14, 12, 6)).astype(np.float32)
    tpl = rng.random((5, 4, 6)).astype(np.float32)
    mask = np.zeros((5, 4), bool)
    mask[:, :2] = True
    mask[:1] = True
    e = block_errors(feats, tpl, mask)
    ref = np.array(
        [[(((feats[y : y + 5, x : x + 4] - tpl) ** 2).sum(-1) * mask).sum() for x in range(9)] for y in range(10)]
    )
    np.testing.assert_allclose(e, ref, rtol=1e-4, atol=1e-4)


def test_block_errors_wide_features_in_slices():
    rng = np.random.default_rng(6)
    feats = rng.random((10, 9, 300)).astype(np.float32)
    mask = np.ones((4, 3), bool)
    e = block_errors(feats, feats[2:6, 3:6], mask)
    assert e.shape == (7, 7) and np.unravel_index(np.argmin(e), e.shape) == (2, 3) and e.min() < 1e-3
    ref = ((feats[5:9, 1:4] - feats[2:6, 3:6]) ** 2).sum()
    assert abs(e[5, 1] - ref) < 1e-3 * ref


def test_min_cut_path_is_optimal():
    rng = np.random.default_rng(4)
    err = rng.random((5, 4))
    path = min_cut_path(err)
    assert np.all(np.abs(np.diff(path)) <= 1)
    best = min(
        sum(err[i, p[i]] for i in range(5))
        for p in itertools.product(range(4), repeat=5)
        if np.all(np.abs(np.diff(p)) <= 1)
    )
    assert abs(err[np.arange(5), path].sum() - best) < 1e-12


# -- quilting --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def spread():
    return spreading_clip(20, 32, 32)


def test_quilt_copies_blocks_verbatim_and_covers_canvas(spread):
    q = learn_quilt(spread, size=(45, 70), block=12, rank=6, feather=0, seed=1)
    assert q.size == (45, 70)  # (height, width): 45 rows of 70 pixels
    assert q.source_map.shape == (45, 70, 2) and q.labels.shape == (45, 70)
    assert q.gain is None and q.blend_weight is None
    assert q.source_map[..., 0].max() < 32 and q.source_map[..., 1].max() < 32 and q.source_map.min() >= 0
    # every output pixel of block b is its source block shifted: map = source origin + (pixel - position)
    yy, xx = np.mgrid[0:45, 0:70]
    by, bx = q.block_sources[q.labels][..., 0], q.block_sources[q.labels][..., 1]
    py, px = q.block_positions[q.labels][..., 0], q.block_positions[q.labels][..., 1]
    np.testing.assert_array_equal(q.source_map[..., 0], by + yy - py)
    np.testing.assert_array_equal(q.source_map[..., 1], bx + xx - px)
    # the map is the same for every frame by construction: the whole time sequence of a source pixel is copied
    out = spread[:, q.source_map[..., 0], q.source_map[..., 1]]
    np.testing.assert_array_equal(out[:, 10, 20], spread[:, q.source_map[10, 20, 0], q.source_map[10, 20, 1]])
    assert len(np.unique(q.labels)) > 6


def test_quilt_is_deterministic_and_seeded(spread):
    a = learn_quilt(spread, size=(40, 40), block=10, rank=4, seed=3)
    b = learn_quilt(spread, size=(40, 40), block=10, rank=4, seed=3)
    c = learn_quilt(spread, size=(40, 40), block=10, rank=4, seed=4)
    np.testing.assert_array_equal(a.source_map, b.source_map)
    assert not np.array_equal(a.source_map, c.source_map)


def test_cuts_follow_low_error(spread):
    """The DP cut beats a straight cut in the middle of the overlap (summed over the whole sequence)."""
    q_cut = learn_quilt(spread, size=(64, 64), block=16, overlap=6, rank=8, feather=0, seed=0)
    out = spread[:, q_cut.source_map[..., 0], q_cut.source_map[..., 1]]
    assert seam_visibility(out, q_cut.labels).mean() < 3.0


def test_feather_band_weights(spread):
    q = learn_quilt(spread, size=(48, 48), block=12, overlap=4, feather=2, rank=4)
    w = q.blend_weight
    assert w is not None and 0 < (w > 0).mean() < 0.9 and w.max() <= 0.5
    assert set(np.unique(q.blend_labels[w > 0])) <= set(range(q.n_blocks))
    # blended pixels carry a second source different from the first
    band = w > 0
    assert np.any(q.blend_map[band] != q.source_map[band])


def test_elongated_blocks_and_any_canvas(spread):
    q = learn_quilt(spread, size=(71, 33), block=(24, 8), rank=4)
    assert q.block == (24, 8) and q.source_map.shape == (71, 33, 2)
    assert q.info["overlap_y"] > q.info["overlap_x"]
    tiny = learn_quilt(spread, size=(3, 5), block=8, rank=3)
    assert tiny.source_map.shape == (3, 5, 2) and tiny.n_blocks == 1


def test_lowpass_gain_flattens_a_gradient():
    rng = np.random.default_rng(5)
    ramp = np.linspace(80, 200, 48)[None, None, :, None]
    frames = np.clip(ramp + rng.normal(0, 8, (6, 48, 48, 3)), 0, 255).astype(np.uint8)
    q = learn_quilt(frames, size=(96, 96), block=12, rank=4, lowpass=8.0, seed=0)
    assert q.gain is not None and q.gain.shape == (96, 96, 3)
    out = render(frames, q, 3).astype(float).mean(axis=2)
    cols = out.mean(axis=0)
    raw = frames[3].astype(float).mean(axis=(0, 2))
    assert np.ptp(cols) < 0.35 * np.ptp(raw)  # the source's left-to-right ramp is gone
    q2 = learn_quilt(frames, size=(96, 96), block=12, rank=4, lowpass=8.0, restore_gradient=True, seed=0)
    cols2 = render(frames, q2, 3).astype(float).mean(axis=(0, 2))
    assert cols2[-10:].mean() - cols2[:10].mean() > 60  # restore puts the ramp back, stretched


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        (dict(block=40), ValueError, "block 40x40 .* larger than the 32x32 source"),
        (dict(block=(8, 33)), ValueError, "larger than"),
        (dict(size=(0, 10)), ValueError, r"size must be \(height, width\) with each side in 1\.\.16384"),
        (dict(size=(10, 20000)), ValueError, r"size must be \(height, width\) with each side in 1\.\.16384"),
        ({"size": (10, 20, 30)}, ValueError, r"size must be \(height, width\), two integers"),
        ({"size": (10.5, 20)}, TypeError, r"size must be \(height, width\) integers"),
        (dict(size="big"), TypeError, r"size must be \(height, width\)"),
        (dict(block=8, overlap=5), ValueError, "overlap .* at most half"),
        (dict(rank=0), ValueError, "rank must be an integer in"),
        (dict(tolerance=-1), ValueError, "tolerance"),
        (dict(lowpass=0), ValueError, "lowpass"),
        (dict(block=8, overlap=2, feather=3), ValueError, "feather must be an integer in"),
        (dict(seed=1.5), TypeError, "seed must be an integer"),
    ],
)
def test_bad_input(spread, kwargs, error, message):
    with pytest.raises(error, match=message):
        learn_quilt(spread, **kwargs)


def test_bad_frames():
    with pytest.raises(ValueError, match="uint8"):
        learn_quilt(np.zeros((4, 16, 16, 3), np.float32))
    with pytest.raises(ValueError, match="at least 2"):
        learn_quilt(np.zeros((1, 16, 16, 3), np.uint8))


def test_comparison_speedup_reports(spread):
    r = measure_comparison_speedup(spread, rank=4, block=8, trials=3)
    assert r["full_width"] == 60 and r["rank"] == 4 and r["best_agreement"] >= 2 / 3
    assert r["small_s"] > 0 and r["full_s"] > 0


def test_progress_called(spread):
    calls = []
    q = learn_quilt(spread, size=(30, 30), block=10, rank=3, progress=lambda d, t: calls.append((d, t)))
    assert calls[-1] == (q.n_blocks, q.n_blocks)


# -- must show, on the real time-lapse clips --------------------------------------------------------
@pytest.mark.clips
@pytest.mark.slow
@pytest.mark.parametrize("name, limit", [("rusting_steel", 1.2), ("melting_honey", 1.2)])
def test_real_clip_512_from_128(clips_dir, name, limit):
    """512x512 from the 128x128 source: seams (the cut label map) at most ``limit`` of the
    interior gradient energy (metrics.seam_visibility), the rank-15 error reported."""
    clip = load_clip(clips_dir / f"timevarying_{name}.gif")
    assert clip.frames.shape[1:3] == (128, 128)
    q = learn_quilt(clip, size=(512, 512))
    assert q.source_map.shape == (512, 512, 2)
    assert q.info["rank"] == 15 and q.info["rank_error"] < 0.08
    out = np.stack([render(clip.frames, q, t) for t in range(0, clip.n_frames, 9)])
    seams = seam_visibility(out, q.labels)
    assert seams.mean() <= limit, seams
