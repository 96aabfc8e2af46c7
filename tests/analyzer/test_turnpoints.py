"""Turn-point and transition analysis: the seed's equations, known extremes, transitions, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.flow import PairFlows, warped_crossfade_ghost
from dynatex.analyzer.metrics import DoubleImages, double_image_level
from dynatex.analyzer.turnpoints import (
    CROSSFADE,
    crossfade_ghost,
    distance_matrix,
    filtered_distances,
    frame_features,
    learn_turnpoints,
    local_maxima,
    pendulum_clip,
    plot_turnpoints,
    symmetry_scores,
    symmetry_weights,
)


@pytest.fixture(scope="module")
def pendulum():
    return pendulum_clip(120, 48)


def test_binomial_weights_follow_eq2():
    # C(2(n-s), n-r) for r = 1..n
    assert symmetry_weights(5, 0).tolist() == [math.comb(10, 4 - k) for k in range(5)]
    assert symmetry_weights(5, 2).tolist() == [math.comb(6, 5 - r) for r in range(1, 6)]
    with pytest.raises(ValueError, match="s must satisfy"):
        learn_turnpoints(pendulum_clip(30, 16)[0], n=4, s=2)


def test_symmetry_scores_eq2_eq3_by_hand():
    rng = np.random.default_rng(1)
    d = rng.uniform(1, 2, (12, 12))
    d = (d + d.T) / 2
    np.fill_diagonal(d, 0)
    raw, sym = symmetry_scores(d, n=2, s=0, min_pairs=2)
    w = symmetry_weights(2, 0)
    expect = np.zeros(12)
    for i in range(2, 10):
        expect[i] = w[0] * d[i - 1, i + 1] + w[1] * d[i - 2, i + 2]
    assert np.allclose(raw, expect)
    assert np.allclose(sym[2:10], 1 - expect[2:10] / expect.max())
    assert sym[:2].tolist() == [0, 0] and sym[10:].tolist() == [0, 0]


def test_local_maxima_eq4_keeps_one_per_range():
    v = np.array([0.1, 0.5, 0.2, 0.6, 0.1, 0.0, 0.3, 0.3, 0.1])
    out = local_maxima(v, 2)
    assert np.flatnonzero(out).tolist() == [3, 6]  # 0.5 is within 2 of 0.6; first of tied 0.3s
    assert out[3] == 0.6


def test_generated_pendulum_extremes_found_within_one_frame(pendulum):
    frames, extremes = pendulum
    model = learn_turnpoints(frames)
    found = model.turn_points
    detectable = extremes[
        (extremes >= model.info["min_pairs"]) & (extremes <= len(frames) - 1 - model.info["min_pairs"])
    ]
    assert len(found) == len(detectable)
    assert np.all(np.abs(found - detectable) <= 1.0), (found, detectable)
    # eq. 5 and the outermost rule
    assert model.p_max[found[0]] == 1.0 and model.p_max[found[-1]] == 1.0
    inner = found[1:-1]
    assert np.allclose(model.p_max[inner], model.reduced[inner] / 2)
    assert np.all(model.p_max[np.setdiff1d(np.arange(len(frames)), found)] == 0)


def test_transitions_jump_by_a_period_and_never_dead_end(pendulum):
    frames, _ = pendulum
    model = learn_turnpoints(frames)
    assert model.src.size > 0
    # the pendulum repeats every 26.4 frames: a good jump replaces src+1 by a frame a whole period away
    gap = (model.dst - (model.src + 1)).astype(float)
    assert np.all(np.abs(np.abs(gap) / 26.4 - np.round(np.abs(gap) / 26.4)) < 0.15), gap
    e = model.exit_frame
    assert np.any((model.src == e) & (model.dst < e))
    assert model.src.max() <= e and model.dst.max() <= e
    assert np.isclose(model.prob[model.src == e].sum(), 1.0)
    sums = np.bincount(model.src, weights=model.prob)
    assert sums.max() <= 1 + 1e-9
    # probabilities fall off with the future cost at each source frame
    for i in np.unique(model.src):
        sel = model.src == i
        order = np.argsort(model.future_cost[sel])
        assert np.all(np.diff(model.prob[sel][order]) <= 1e-12)


def test_jumps_whose_crossfade_shows_double_images_are_not_taken():
    # two swings of different amplitude: a jump between them crossfades the bob at two places
    a, _ = pendulum_clip(60, 48, amplitude=0.6)
    b, _ = pendulum_clip(60, 48, amplitude=0.45, phase=10.3, seed=1)
    frames = np.concatenate([a, b])
    level = double_image_level(frames)
    loose = learn_turnpoints(frames, max_ghost=0)
    assert "ghost_level" not in loose.info
    assert crossfade_ghost(frames, loose.src, loose.dst).max() > level  # the check has work to do
    model = learn_turnpoints(frames, warp="off")
    assert model.info["ghost_level"] == pytest.approx(level)
    assert model.src.size > 10 and model.flow is None
    assert crossfade_ghost(frames, model.src, model.dst).max() <= level
    e = model.exit_frame  # forward play still never runs off the end
    assert np.any((model.src == e) & (model.dst < e)) and model.src.max() <= e
    # motion-compensated: a jump whose plain crossfade shows two bobs is kept when its warp does not
    warped = learn_turnpoints(frames)
    plain = crossfade_ghost(frames, warped.src, warped.dst)
    ghosts = DoubleImages(frames)
    flows = PairFlows(frames)
    moved = warped_crossfade_ghost(flows, ghosts, warped.src, warped.dst, CROSSFADE)
    assert np.minimum(plain, moved).max() <= level
    rescued = plain > level
    assert rescued.any() and warped.info["n_warped"] >= rescued.sum()
    stored = {tuple(p) for p in warped.flow.pairs.tolist()}
    for i, j in zip(warped.src[rescued], warped.dst[rescued]):
        assert (min(i + 1, j), max(i + 1, j)) in stored


def test_filtered_distances_average_along_diagonals():
    d = np.arange(100, dtype=float).reshape(10, 10)
    f = filtered_distances(d, 1)  # taps -1, 0 with weights 1/2, 1/2
    assert f[4, 6] == pytest.approx((d[3, 5] + d[4, 6]) / 2)
    assert np.isinf(f[0, 5]) and np.isfinite(f[1, 5])


def test_reduced_distances_close_to_full_resolution(pendulum):
    frames, _ = pendulum
    big = np.repeat(np.repeat(frames[:20], 4, axis=1), 4, axis=2)  # 192 x 192
    model = learn_turnpoints(big, feature_size=48, n=3, min_symmetry=0.1)
    assert model.info["distance_correlation"] > 0.99
    assert model.info["distance_rel_error"] < 0.05
    full = distance_matrix(big.reshape(20, -1).astype(np.float32))
    red = distance_matrix(frame_features(big, 48))
    assert np.corrcoef(full.ravel(), red.ravel())[0, 1] > 0.99


@pytest.mark.clips
def test_real_pendulum_turn_points(clips_dir):
    clip = load_clip(clips_dir / "pendulum_clock_schoedl.mov")
    model = learn_turnpoints(clip)
    # the clip's swing slows to a stop (smallest consecutive differences) near frames 1-2, 12, 22-23, 33
    assert model.turn_points.tolist() == [2, 12, 23, 33]
    assert model.info["distance_correlation"] > 0.95
    # every jump's crossfade within the clip's own level of double images; the clip's end still used
    assert crossfade_ghost(clip.frames, model.src, model.dst).max() <= model.info["ghost_level"]
    assert model.exit_frame >= 40


def test_plot_writes_png(tmp_path, pendulum):
    path = plot_turnpoints(learn_turnpoints(pendulum[0][:60]), str(tmp_path / "tp.png"), title="pendulum")
    with open(path, "rb") as f:
        data = f.read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"n": 0}, r"n must be an integer in 1\.\."),
        ({"n": 2.5}, "n must be an integer"),
        ({"r": 0}, r"r must be an integer in 1\.\."),
        ({"min_symmetry": 1.0}, r"min_symmetry must be a finite number in \[0, 1\)"),
        ({"alpha": 1.0}, r"alpha must be a finite number in \(0, 1\)"),
        ({"sigma": -1}, "sigma must be a finite number in"),
        ({"min_pairs": 9}, "min_pairs must be in 1..n=4"),
        ({"max_cost": 0}, "max_cost must be a finite number in"),
        ({"max_ghost": -1}, "max_ghost must be a finite number in"),
    ],
)
def test_bad_parameters(pendulum, kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        learn_turnpoints(pendulum[0][:40], **kwargs)


def test_clip_too_short_for_n():
    frames = pendulum_clip(8, 16)[0]
    with pytest.raises(ValueError, match=r"8 frames, too short for n=4.*2n\+1 = 9"):
        learn_turnpoints(frames, n=4)


def test_not_frames():
    with pytest.raises(ValueError, match="uint8"):
        learn_turnpoints(np.zeros((20, 8, 8, 3), np.float32))


def test_too_few_turn_points():
    frames = np.repeat(np.arange(30, dtype=np.uint8)[:, None, None, None] * 8, 8, axis=1).repeat(8, axis=2)
    with pytest.raises(ValueError, match="turn point"):
        learn_turnpoints(np.repeat(frames, 3, axis=3), min_symmetry=0.9)
