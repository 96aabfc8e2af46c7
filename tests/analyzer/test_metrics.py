"""Unit tests of dynatex.analyzer.metrics: definitions on tiny arrays, input checks, doctests."""

from __future__ import annotations

import doctest
import importlib
import json
import pkgutil

import numpy as np
import pytest

from dynatex.analyzer import metrics as m


def _noise(t=12, h=16, w=16, c=3, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (t, h, w, c)).astype(np.uint8)


def test_doctests():
    """The examples of every module of the package (one per family)."""
    failed = attempted = 0
    for info in pkgutil.iter_modules(m.__path__, m.__name__ + "."):
        r = doctest.testmod(
            importlib.import_module(info.name), extraglobs={"np": np}, optionflags=doctest.NORMALIZE_WHITESPACE
        )
        failed, attempted = failed + r.failed, attempted + r.attempted
    res = doctest.TestResults(failed, attempted)
    assert res.attempted > 20
    assert res.failed == 0


# -- check_frames -----------------------------------------------------------------------------
def test_check_frames_shapes():
    assert m.check_frames(np.zeros((3, 4, 5), np.uint8)).shape == (3, 4, 5, 1)
    assert m.check_frames(np.zeros((3, 4, 5, 3), np.float32)).shape == (3, 4, 5, 3)


@pytest.mark.parametrize(
    "bad, exc, msg",
    [
        (np.zeros((0, 4, 4, 3), np.uint8), ValueError, "empty"),
        (np.zeros((4, 4), np.uint8), ValueError, "shape"),
        (np.zeros((2, 4, 4, 2), np.uint8), ValueError, "C in"),
        (np.zeros((2, 4, 4), bool), TypeError, "numbers"),
        ("clip.avi", TypeError, "numpy array"),
    ],
)
def test_check_frames_rejects(bad, exc, msg):
    with pytest.raises(exc, match=msg):
        m.check_frames(bad, name="output")


def test_nonfinite_rejected_except_by_stability():
    f = np.full((4, 4, 4), 10.0)
    f[2, 1, 1] = np.inf
    assert m.count_nonfinite(f) == 1
    with pytest.raises(ValueError, match="NaN or inf in 1 frame"):
        m.frame_step_ratio(f, _noise(c=1, h=4, w=4))


# -- stability --------------------------------------------------------------------------------
def test_stability_self_is_one_and_decay_to_mean_is_zero():
    src = _noise(t=20)
    rep = m.stability(src, src, window=20)
    assert rep.ratios == pytest.approx([1.0])
    mean = src.astype(np.float64).mean(axis=0)
    rep0 = m.stability(np.repeat(mean[None], 10, axis=0), src, window=5)
    assert rep0.max_ratio == pytest.approx(0.0, abs=1e-6)
    assert not rep0.is_stable()


def test_stability_streams_iterables_and_counts_nonfinite():
    src = _noise(t=10).astype(np.float32)
    frames = [f for f in src] + [np.full(src.shape[1:], np.nan, np.float32)] * 3
    rep = m.stability(iter(frames), src, window=5)
    assert rep.n_frames == 13 and rep.nonfinite_frames == 3
    assert np.isnan(rep.ratios[-1])  # the last window holds only NaN frames
    assert not rep.is_stable()
    d = rep.as_dict()
    assert d["final_ratio"] is None and d["stable"] is False
    json.dumps(d)  # JSON-ready


def test_stability_errors():
    src = _noise()
    with pytest.raises(ValueError, match="shaped like the source"):
        m.stability(_noise(h=8), src)
    with pytest.raises(ValueError, match="no temporal variation"):
        m.stability(src, np.repeat(src[:1], 5, axis=0))
    with pytest.raises(ValueError, match="window must be"):
        m.stability(src, src, window=0)
    with pytest.raises(ValueError, match="empty"):
        m.stability(iter([]), src)
    with pytest.raises(ValueError, match="frame 0 has shape"):
        m.stability(iter([np.zeros((3, 3, 3))]), src)


# -- seams ------------------------------------------------------------------------------------
def test_grid_labels_offset_and_count():
    lab = m.grid_labels((10, 12), (4, 5), offset=(2, 1))
    assert lab.shape == (10, 12)
    assert lab[0, 0] == 0 and lab[1, 0] == 0 and lab[2, 0] != 0  # row boundary at y=2
    assert lab[0, 3] == 0 and lab[0, 4] != 0  # column boundary at x=4
    with pytest.raises(ValueError, match="tile"):
        m.grid_labels((10, 12), 0)


def test_seam_visibility_sees_a_step_only_on_the_boundary():
    f = np.zeros((2, 8, 8), np.uint8)
    f[:, :, 4:] = 100
    on = m.seam_visibility(f, m.grid_labels((8, 8), (8, 4)))
    off = m.seam_visibility(f, m.grid_labels((8, 8), (8, 4), offset=(0, 2)))
    assert (on > 1e6).all()
    assert (off < 1e-5).all()


def test_seam_visibility_wrap_border():
    # a horizontal ramp is seamless inside but jumps at the wrap-around border
    ramp = np.tile(np.arange(0, 64, 4, dtype=np.uint8), (3, 16, 1))
    r = m.seam_visibility(ramp, wrap=True)
    assert r.min() > 50
    # a periodic (toroidal) texture tiles without a seam; a crop of a larger texture does not
    rng = np.random.default_rng(4)
    spec = np.fft.fft2(rng.normal(0, 1, (96, 96)))
    fy, fx = np.meshgrid(np.fft.fftfreq(96), np.fft.fftfreq(96), indexing="ij")
    field = np.real(np.fft.ifft2(spec * np.exp(-(fx**2 + fy**2) / (2 * 0.06**2))))
    field = (128 + 40 * field / field.std()).clip(0, 255)
    periodic = np.repeat(field[None], 2, axis=0)
    crop = np.repeat(field[None, :64, :64], 2, axis=0)
    good, bad = m.seam_visibility(periodic, wrap=True).mean(), m.seam_visibility(crop, wrap=True).mean()
    assert 0.7 < good < 1.4
    assert bad > 3 * good


def test_seam_visibility_errors():
    f = _noise()
    with pytest.raises(ValueError, match="no boundary"):
        m.seam_visibility(f, m.grid_labels((16, 16), 64))
    with pytest.raises(ValueError, match="labels map is 8x8 but frames are 16x16"):
        m.seam_visibility(f, np.zeros((8, 8), int))
    with pytest.raises(ValueError, match="no boundary to measure"):
        m.seam_visibility(f)
    with pytest.raises(TypeError, match="labels must be"):
        m.seam_visibility(f, np.zeros((16, 16), np.float32))
    checker = np.indices((16, 16)).sum(axis=0) % 2
    with pytest.raises(ValueError, match="no interior"):
        m.seam_visibility(f, checker)


# -- temporal ---------------------------------------------------------------------------------
def test_temporal_discontinuity_definition():
    ramp = np.repeat(np.arange(0, 60, 3, dtype=np.uint8), 4).reshape(20, 2, 2)
    jump = np.concatenate([ramp[:10], ramp[15:]])  # skips 5 steps at frame 10
    assert m.temporal_discontinuity(jump, [10], source=ramp) == pytest.approx([6.0])
    assert m.temporal_discontinuity(jump, [3, 12], source=ramp) == pytest.approx([1.0, 1.0])
    # without a source, the output's own median step is the reference
    assert m.temporal_discontinuity(jump, 10) == pytest.approx([6.0])


def test_temporal_discontinuity_errors():
    f = _noise()
    with pytest.raises(ValueError, match="event 12 is outside"):
        m.temporal_discontinuity(f, [12])
    with pytest.raises(ValueError, match="event 0 is outside"):
        m.temporal_discontinuity(f, [0])
    with pytest.raises(TypeError, match="integers"):
        m.temporal_discontinuity(f, [1.5])
    with pytest.raises(ValueError, match="does not change"):
        m.temporal_discontinuity(f, [3], source=np.repeat(f[:1], 4, axis=0))


def test_frame_step_ratio():
    ramp = np.repeat(np.arange(0, 60, 3, dtype=np.uint8), 4).reshape(20, 2, 2)
    assert m.frame_step_ratio(ramp, ramp) == pytest.approx(1.0)
    assert m.frame_step_ratio(ramp[::3], ramp) == pytest.approx(3.0)
    assert m.frame_step_ratio(np.repeat(ramp[:1], 5, axis=0), ramp) == 0.0


# -- spectrum and patches ----------------------------------------------------------------------
def test_spectrum_shape_and_different_sizes():
    rng = np.random.default_rng(3)
    a = rng.normal(128, 20, (20, 40, 48)).clip(0, 255)
    b = rng.normal(128, 20, (24, 64, 32)).clip(0, 255)
    assert m.st_power_spectrum(a, cuboid=(8, 16)).shape == (5, 9)
    # two draws of the same white noise have the same spectrum, whatever their sizes
    assert m.spectrum_distance(a, b, cuboid=(8, 16), downscale=1) < 0.5
    # a smoothed version does not
    import cv2

    c = np.stack([cv2.GaussianBlur(f.astype(np.float32), (0, 0), 2) for f in b])
    assert m.spectrum_distance(c, b, cuboid=(8, 16), downscale=1) > 5


def test_spectrum_errors():
    f = _noise(t=3, h=3, w=3)
    with pytest.raises(ValueError, match="too small"):
        m.spectrum_distance(f, f)
    with pytest.raises(ValueError, match="smaller than the spectrum cuboid"):
        m.st_power_spectrum(_noise(t=4), cuboid=(8, 8))
    with pytest.raises(TypeError, match="cuboid"):
        m.spectrum_distance(_noise(), _noise(), cuboid="big")


def test_patch_distances_self_zero_and_swapped_roles():
    src = _noise(t=10, h=24, w=24, seed=1)
    assert m.patch_distances(src, src, downscale=1) == pytest.approx((0.0, 0.0), abs=1e-4)
    half = src[:5]
    coh, comp = m.patch_distances(half, src, downscale=1, n_samples=200)
    # every patch of the first half is in the source; not every source patch is in the half
    assert coh == pytest.approx(0.0, abs=1e-4)
    assert comp > 10
    assert m.patch_coherence(half, src, downscale=1, n_samples=200) == coh
    assert m.patch_completeness(half, src, downscale=1, n_samples=200) == comp


def test_patch_errors():
    with pytest.raises(ValueError, match="smaller than one patch"):
        m.patch_distances(_noise(t=2), _noise())
    with pytest.raises(ValueError, match="n_samples"):
        m.patch_distances(_noise(), _noise(), n_samples=0)
    with pytest.raises(TypeError, match="seed"):
        m.patch_distances(_noise(), _noise(), seed="x")


# -- coverage and repetition ------------------------------------------------------------------
def test_coverage():
    src = _noise(t=10)
    assert m.frame_coverage(src, src) == 1.0
    assert m.frame_coverage(src[[2, 2, 2, 5]], src) == pytest.approx(0.2)
    assert m.index_coverage(np.arange(5), 10) == 0.5
    with pytest.raises(ValueError, match="same frame size"):
        m.frame_coverage(_noise(h=8), src)
    with pytest.raises(ValueError, match="0..9"):
        m.index_coverage([3, 10], 10)
    with pytest.raises(ValueError, match="empty"):
        m.index_coverage([], 10)


def test_repetition():
    src = _noise(t=40, seed=2)
    looped = np.concatenate([src[:7]] * 6)
    assert m.repetition_lag(looped) == 7
    assert m.repetition_lag(src) is None
    prof = m.repetition_profile(looped, max_lag=20)
    assert prof.shape == (20,) and prof[6] == 0.0 and prof[13] == 0.0 and prof[:6].min() > 0.5
    assert m.repetition_lag(np.repeat(src[:1], 10, axis=0)) == 1
    with pytest.raises(ValueError, match="max_lag"):
        m.repetition_profile(src, max_lag=40)
    with pytest.raises(ValueError, match="tolerance"):
        m.repetition_lag(src, tolerance=-1)


# -- evaluate ---------------------------------------------------------------------------------
def test_evaluate_report_is_json_and_complete():
    src = _noise(t=24, h=32, w=32)
    rep = m.evaluate(src, src, labels=m.grid_labels((32, 32), 8), events=[5, 10], window=12, downscale=1)
    json.dumps(rep)
    assert rep["stability"]["stable"] is True
    assert rep["seam_visibility"]["mean"] > 0
    assert rep["temporal_discontinuity"]["events"] == [5, 10]
    assert rep["frame_coverage"] == 1.0 and rep["repetition_lag"] is None
    assert rep["patch_coherence"] == pytest.approx(0.0, abs=1e-4) and rep["spectrum_distance_db"] == 0.0


def test_evaluate_other_size_and_nonfinite():
    src = _noise(t=48, h=64, w=64)
    other = _noise(t=40, h=72, w=80, seed=5)
    rep = m.evaluate(other, src, downscale=1)
    assert rep["stability"] is None and rep["frame_coverage"] is None
    assert rep["spectrum_distance_db"] < 1.0  # same white-noise statistics
    bad = src[:24].astype(np.float32)
    bad[3, 0, 0, 0] = np.nan
    rep = m.evaluate(bad, src, window=12)
    assert rep["stability"]["nonfinite_frames"] == 1 and "patch_coherence" not in rep


def test_lattice_correlation_sees_a_tile_lattice_and_not_noise():
    rng = np.random.default_rng(1)
    tile = rng.integers(0, 256, (3, 12, 10, 3)).astype(np.uint8)
    tiled = np.tile(tile, (1, 5, 6, 1))
    assert m.lattice_correlation(tiled, (12, 10)) == pytest.approx((1.0, 1.0))
    # at another lag the same lattice is not a repeat
    assert max(m.lattice_correlation(tiled, (7, 7))) < 0.2
    # half of the cells repeat: about half the correlation
    mixed = tiled.copy()
    mixed[:, :, 30:] = rng.integers(0, 256, mixed[:, :, 30:].shape)
    assert 0.3 < m.lattice_correlation(mixed, (12, 10))[0] < 0.7
    with pytest.raises(ValueError, match="period 60x10 must be smaller"):
        m.lattice_correlation(tiled, (60, 10))


# -- double images ----------------------------------------------------------------------------------
def _moving_disc(t: int = 30, size: int = 48) -> np.ndarray:
    """A bright disc 12 pixels wide crossing a noisy background, 1.5 pixels a frame."""
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:size, 0:size]
    bg = rng.integers(60, 90, (size, size))
    out = np.empty((t, size, size), np.uint8)
    for i in range(t):
        disc = (xx - 4 - 1.5 * i) ** 2 + (yy - size / 2) ** 2 < 36
        out[i] = np.where(disc, 230, bg)
    return out


def test_double_image_zero_on_source_frames_and_high_on_far_crossfades():
    clip = _moving_disc()
    assert np.all(m.double_image(clip, clip) == 0)
    level = m.double_image_level(clip)
    assert 0.3 < level < 0.8  # in-betweens of consecutive frames: about half a step
    near = (clip[10].astype(np.float32) + clip[11]) / 2
    far = (clip[5].astype(np.float32) + clip[20]) / 2  # two half-transparent discs
    ghost = m.double_image(np.stack([near, far]), clip)
    assert ghost[0] <= level + 1e-9
    assert ghost[1] > 2 * level


def test_crossfade_double_image_matches_the_formed_frames():
    clip = _moving_disc()
    a, b, w = np.array([3, 8, 20]), np.array([4, 25, 2]), np.array([0.5, 0.25, 0.8])
    formed = (1 - w)[:, None, None] * clip[a] + w[:, None, None] * clip[b]
    assert np.allclose(m.crossfade_double_image(clip, a, b, w), m.double_image(formed, clip), atol=1e-6)
    with pytest.raises(ValueError, match="first must be frame indices in 0..29"):
        m.crossfade_double_image(clip, [30], [1], [0.5])
    with pytest.raises(ValueError, match=r"weight must lie in \[0, 1\]"):
        m.crossfade_double_image(clip, [1], [2], [1.5])
    with pytest.raises(ValueError, match="does not change"):
        m.double_image_level(np.zeros((4, 8, 8), np.uint8))


def _stripes(seed: int, t: int = 64) -> np.ndarray:
    """Stripes 8 pixels wide moving 1 pixel a frame under a little noise (its own noise per seed)."""
    rng = np.random.default_rng(seed)
    x = np.arange(64)
    bars = np.where((x[None, :] - np.arange(t)[:, None]) % 16 < 8, 200.0, 40.0)
    return np.clip(np.repeat(bars[:, None, :], 48, axis=1) + rng.normal(0, 8, (t, 48, 64)), 0, 255).astype(np.uint8)


def test_local_novelty_zero_on_the_source_low_on_the_same_texture_high_on_two_displaced_copies():
    src = _stripes(0)
    assert m.local_novelty(src, src) == 0.0
    fresh = m.local_novelty(_stripes(1), src)  # the same stripes, other noise: nothing the source lacks
    assert 0.3 < fresh < 1.15
    ghost = ((src.astype(np.float32) + np.roll(src, 5, axis=2)) / 2).astype(np.uint8)  # stripes at two places
    assert m.local_novelty(ghost, src) > 3
    with pytest.raises(ValueError, match="one frame size"):
        m.local_novelty(src[:, :32], src)
    assert m.local_novelty(src[:, :12, :12], src[:, :12, :12]) is None  # no 8x8 patch fits with its reach


def test_evaluate_reports_local_novelty_only_at_the_source_size():
    src = _stripes(0, t=32)
    assert m.evaluate(_stripes(1, t=32), src, n_samples=100)["local_novelty"] < 1.15
    assert m.evaluate(src[:, :40], src, n_samples=100)["local_novelty"] is None
