"""Calibration: every metric separates good from bad output in the expected direction, with margin.

Cases (issue 3): the source against itself (good) versus frames shuffled in time, a frozen
frame, a 10-frame segment looped; uncut pasted blocks versus the same blocks with a
min-error cut (seams); a decaying noiseless LDS (stability). Each runs on generated clips
and on real clips from ``../shared/data/clips`` (downscaled, short ranges, to stay fast).
"""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer import metrics as m

# real clips used here, with the load options that keep them small
REAL = {
    "water": ("water_sea_waves_dyntex.avi", dict(stop=60, size=(144, 176))),
    "steam": ("steam_vapour_pot_128px.avi", dict(stop=64)),
}
SEAM_REAL = {
    "water": ("water_sea_waves_dyntex.avi", dict(stop=10, size=(144, 176))),
    "grass": ("grass_straw_wind_dyntex.avi", dict(stop=10, size=(144, 176))),
}


# -- generated clips -----------------------------------------------------------------------------
def drifting_texture(t: int = 48, h: int = 64, w: int = 64, seed: int = 0) -> np.ndarray:
    """Two layers of smooth noise drifting at different velocities, plus a flickering fine layer."""
    import cv2

    rng = np.random.default_rng(seed)
    pad = 2 * t

    def layer(sigma: float) -> np.ndarray:
        f = cv2.GaussianBlur(rng.normal(0, 1, (h + 2 * pad, w + 2 * pad)).astype(np.float32), (0, 0), sigma)
        return f / f.std()

    a, b = layer(4.0), layer(2.0)
    frames = np.empty((t, h, w, 3), np.float32)
    for i in range(t):
        la = a[pad + i : pad + i + h, pad + (2 * i) // 3 : pad + (2 * i) // 3 + w]
        lb = b[pad - i : pad - i + h, pad + i // 2 : pad + i // 2 + w]
        v = 128 + 35 * la + 20 * lb * np.cos(0.2 * i)
        frames[i] = v[..., None] * np.array([1.0, 0.9, 0.75], np.float32)
    return np.rint(frames).clip(0, 255).astype(np.uint8)


def lds_clip(
    n_frames: int, *, decay: float, noise: bool, x0: np.ndarray | None = None, seed: int = 0, quantize: bool = True
):
    """A tiny LDS in numpy: ``x <- decay * R x (+ noise)``, frames ``= C x + mean`` (32x32 RGB).

    ``R`` is a fixed rotation (20 pole pairs); the noise keeps the state at unit variance
    when ``decay < 1``. Returns (frames, last state).
    """
    n, hw = 40, 32
    basis_rng = np.random.default_rng(1234)  # the same model for every call
    c_mat = np.linalg.qr(basis_rng.normal(size=(hw * hw, n)))[0] * 30.0 * np.sqrt(hw * hw / n)
    mean = 128 + 20 * np.sin(np.linspace(0, 3 * np.pi, hw * hw))
    rot = np.zeros((n, n))
    for k, ang in enumerate(np.linspace(0.05, 1.5, n // 2)):
        cs, sn = np.cos(ang), np.sin(ang)
        rot[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = [[cs, -sn], [sn, cs]]
    rng = np.random.default_rng(seed)
    x = rng.normal(size=n) if x0 is None else x0.copy()
    q = np.sqrt(max(0.0, 1 - decay**2))
    out = np.empty((n_frames, hw, hw, 3), np.float64)
    for i in range(n_frames):
        x = decay * rot @ x + (q * rng.normal(size=n) if noise else 0.0)
        out[i] = (c_mat @ x + mean).reshape(hw, hw)[..., None]
    frames = np.rint(out).clip(0, 255).astype(np.uint8) if quantize else out.astype(np.float32)
    return frames, x


def variants(src: np.ndarray, seed: int = 0) -> dict[str, np.ndarray]:
    t = src.shape[0]
    rng = np.random.default_rng(seed)
    return {
        "self": src,
        "shuffled": src[rng.permutation(t)],
        "frozen": src[np.full(t, t // 2)],
        "loop10": src[np.arange(t) % 10],
    }


# -- quilting (for the seam calibration) ----------------------------------------------------------
def _min_cut_path(err: np.ndarray) -> np.ndarray:
    """Column, per row, of the vertical path of least summed ``err`` (dynamic programming)."""
    h, w = err.shape
    cost = err.copy()
    for y in range(1, h):
        prev = cost[y - 1]
        left = np.concatenate([[np.inf], prev[:-1]])
        right = np.concatenate([prev[1:], [np.inf]])
        cost[y] += np.minimum(np.minimum(left, prev), right)
    path = np.empty(h, int)
    path[-1] = int(np.argmin(cost[-1]))
    for y in range(h - 2, -1, -1):
        lo = max(0, path[y + 1] - 1)
        path[y] = lo + int(np.argmin(cost[y, lo : min(w, path[y + 1] + 2)]))
    return path


def quilt(src: np.ndarray, *, n: int = 4, block: int = 32, overlap: int = 10, candidates: int = 40, seed: int = 0):
    """Spatio-temporal image quilting of ``src`` with blocks carried through all frames.

    Blocks are chosen once (best of ``candidates`` random blocks by overlap error) and then
    assembled twice: pasted over each other without a cut (straight seams at block edges),
    and with a minimum-error boundary cut in each overlap (the same cut for every frame).
    Returns ``(uncut, uncut_labels, cut, cut_labels)``; labels give each pixel's block.
    """
    rng = np.random.default_rng(seed)
    t, h, w, c = src.shape
    step = block - overlap
    size = step * (n - 1) + block
    srcf = src.astype(np.float32)
    cut = np.zeros((t, size, size, c), np.float32)
    cut_lab = np.full((size, size), -1, np.int32)
    unc = np.zeros_like(cut)
    unc_lab = np.full((size, size), -1, np.int32)
    for i in range(n):
        for j in range(n):
            y0, x0 = i * step, j * step
            region = cut[:, y0 : y0 + block, x0 : x0 + block]
            known = cut_lab[y0 : y0 + block, x0 : x0 + block] >= 0
            best = None
            for _ in range(candidates if (i or j) else 1):
                sy, sx = rng.integers(0, h - block + 1), rng.integers(0, w - block + 1)
                blk = srcf[:, sy : sy + block, sx : sx + block]
                e = float((((blk - region) ** 2).sum(axis=(0, 3)) * known).sum())
                if best is None or e < best[0]:
                    best = (e, blk)
            blk = best[1]
            unc[:, y0 : y0 + block, x0 : x0 + block] = blk
            unc_lab[y0 : y0 + block, x0 : x0 + block] = i * n + j
            err = ((blk - region) ** 2).sum(axis=(0, 3))
            take = np.ones((block, block), bool)
            if j:
                take &= np.arange(block)[None, :] >= _min_cut_path(err[:, :overlap])[:, None]
            if i:
                take &= np.arange(block)[:, None] >= _min_cut_path(err[:overlap, :].T)[None, :]
            region[:, take] = blk[:, take]
            cut_lab[y0 : y0 + block, x0 : x0 + block][take] = i * n + j
    q = lambda a: np.rint(a).clip(0, 255).astype(np.uint8)  # noqa: E731
    return q(unc), unc_lab, q(cut), cut_lab


# -- fixtures -----------------------------------------------------------------------------------
@pytest.fixture(
    scope="module",
    params=[
        "generated",
        pytest.param("water", marks=pytest.mark.clips),
        pytest.param("steam", marks=pytest.mark.clips),
    ],
)
def clip(request) -> np.ndarray:
    if request.param == "generated":
        return drifting_texture()
    clips_dir = request.getfixturevalue("clips_dir")
    name, opts = REAL[request.param]
    return load_clip(clips_dir / name, **opts).frames


@pytest.fixture(scope="module")
def cases(clip) -> dict[str, np.ndarray]:
    return variants(clip)


@pytest.fixture(scope="module")
def patches(cases) -> dict[str, tuple[float, float]]:
    src = cases["self"]
    return {k: m.patch_distances(v, src, n_samples=500) for k, v in cases.items()}


# -- temporal metrics: source vs shuffled ------------------------------------------------------------
def test_frame_step_ratio_separates_shuffled(cases):
    src = cases["self"]
    good, bad = m.frame_step_ratio(src, src), m.frame_step_ratio(cases["shuffled"], src)
    assert good == pytest.approx(1.0)
    assert bad > 1.3 * good
    assert m.frame_step_ratio(cases["frozen"], src) < 0.05


def test_temporal_discontinuity_separates_shuffled_and_loop_wraps(cases):
    src = cases["self"]
    t = src.shape[0]
    every = list(range(1, t))
    good = m.temporal_discontinuity(src, every, source=src).mean()
    bad = m.temporal_discontinuity(cases["shuffled"], every, source=src).mean()
    assert 0.8 < good < 1.3
    assert bad > 1.4 * good
    wraps = list(range(10, t, 10))
    good_w = m.temporal_discontinuity(src, wraps, source=src).mean()
    bad_w = m.temporal_discontinuity(cases["loop10"], wraps, source=src).mean()
    assert bad_w > 1.4 * good_w


def test_spectrum_distance_separates(cases):
    src = cases["self"]
    good = m.spectrum_distance(src, src)
    assert good == 0.0
    assert m.spectrum_distance(cases["shuffled"], src) > 2.0
    assert m.spectrum_distance(cases["frozen"], src) > 5.0
    assert m.spectrum_distance(cases["loop10"], src) > 0.5
    # a different stretch of the same texture is close
    half = src.shape[0] // 2
    assert m.spectrum_distance(src[half:], src[:half]) < m.spectrum_distance(cases["shuffled"], src)


def test_patch_coherence_and_completeness_separate(patches):
    good_coh, good_comp = patches["self"]
    assert good_coh == pytest.approx(0.0, abs=1e-3) and good_comp == pytest.approx(0.0, abs=1e-3)
    for bad in ("shuffled", "frozen"):
        coh, comp = patches[bad]
        assert coh > 1.0 and comp > 1.0, bad
    # a short loop is made of source patches (coherent) but misses most of the source (incomplete)
    coh, comp = patches["loop10"]
    assert comp > 2.0 * coh
    assert coh < patches["shuffled"][0]


# -- coverage and repetition ------------------------------------------------------------------------
def test_frame_coverage_separates_frozen(cases):
    src = cases["self"]
    t = src.shape[0]
    assert m.frame_coverage(src, src) == 1.0
    assert m.frame_coverage(cases["frozen"], src) == pytest.approx(1.0 / t)
    assert m.frame_coverage(cases["loop10"], src) == pytest.approx(10.0 / t)


def test_repetition_lag_finds_the_loop(cases):
    src = cases["self"]
    assert m.repetition_lag(src, source=src) is None
    assert m.repetition_lag(cases["shuffled"], source=src) is None
    assert m.repetition_lag(cases["loop10"], source=src) == 10
    assert m.repetition_lag(cases["frozen"], source=src) == 1
    # the margin: at lag 10 the loop is (near) exact while the source is far from repeating
    assert m.repetition_profile(src, source=src).min() > 0.5
    assert m.repetition_profile(cases["loop10"], source=src)[9] < 0.05


# -- seams: uncut blocks vs the same blocks with a min-error cut ----------------------------------------
def _seam_case(src: np.ndarray, label: str):
    ratios = []
    for seed in range(3):
        unc, unc_lab, cut, cut_lab = quilt(src, seed=seed)
        ratios.append((m.seam_visibility(unc, unc_lab).mean(), m.seam_visibility(cut, cut_lab).mean()))
    unc_r, cut_r = np.mean(ratios, axis=0)
    grid = m.grid_labels(src.shape[1:3], 22, offset=(3, 3))
    src_r = m.seam_visibility(src, grid).mean()
    assert 0.75 < src_r < 1.3, label  # no seam: the source under an arbitrary grid
    assert unc_r > 1.3 * cut_r, label  # the cut hides the seams, clearly
    assert cut_r > src_r, label
    for u, c in ratios:  # and it does for every draw
        assert u > c, label
    return unc_r, cut_r, src_r


def test_seams_generated():
    _seam_case(drifting_texture(t=10, h=96, w=96, seed=3), "generated")


@pytest.mark.clips
@pytest.mark.parametrize("key", sorted(SEAM_REAL))
def test_seams_real(clips_dir, key):
    name, opts = SEAM_REAL[key]
    _seam_case(load_clip(clips_dir / name, **opts).frames, key)


# -- stability: decaying noiseless LDS ---------------------------------------------------------------
def test_stability_decaying_lds():
    source, x_last = lds_clip(200, decay=0.95, noise=True, seed=0)
    good, _ = lds_clip(400, decay=0.95, noise=True, x0=x_last, seed=1)
    decayed, _ = lds_clip(400, decay=0.95, noise=False, x0=x_last)
    rep_self = m.stability(source, source, window=100)
    rep_good = m.stability(good, source, window=100)
    rep_bad = m.stability(decayed, source, window=100)
    assert rep_self.is_stable() and rep_good.is_stable()
    assert 0.5 < rep_good.min_ratio and rep_good.max_ratio < 2.0
    assert rep_bad.final_ratio < 0.05 * rep_good.min_ratio
    assert not rep_bad.is_stable()
    # in a stream (frames never stacked) the same numbers come out
    streamed = m.stability(iter(decayed), source, window=100)
    np.testing.assert_allclose(streamed.ratios, rep_bad.ratios)


def test_stability_blow_up_and_nan():
    source, x_last = lds_clip(200, decay=0.95, noise=True, seed=0)
    grows, _ = lds_clip(300, decay=1.02, noise=False, x0=x_last, quantize=False)
    rep = m.stability(grows, source, window=100)
    assert rep.max_ratio > 100 and rep.nonfinite_frames == 0 and not rep.is_stable()
    grows[200:] = np.nan
    rep = m.stability(grows, source, window=100)
    assert rep.nonfinite_frames == 100 and np.isnan(rep.ratios[-1]) and not rep.is_stable()


@pytest.mark.clips
def test_stability_real_clip_decay(clips_dir):
    name, opts = REAL["water"]
    src = load_clip(clips_dir / name, **opts).frames
    mean = src.astype(np.float32).mean(axis=0)
    t = np.arange(src.shape[0], dtype=np.float32)[:, None, None, None]
    decayed = np.rint(mean + 0.9**t * (src - mean)).clip(0, 255).astype(np.uint8)
    good = m.stability(src[::-1], src, window=20)  # played backwards: same energy
    bad = m.stability(decayed, src, window=20)
    assert good.is_stable() and good.min_ratio > 0.7
    assert bad.final_ratio < 0.05
