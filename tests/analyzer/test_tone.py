"""Tone maps: a clip whose values pile at 0 and 255 is learned on Gaussianised values and keeps
its energy; other clips are learned on their levels as before."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.analyzer.tone import SATURATION_SHARE, ToneModel, gain_for, saturation_share
from dynatex.errors import InvalidArgumentError
from dynatex.player.engines.projection import open_projector
from dynatex.player.modes.mixture import MixturePlayer
from dynatex.tiledb import DatabaseWriter

from ..conftest import wave_clip


def flames(t: int = 80, h: int = 24, w: int = 32, seed: int = 0) -> np.ndarray:
    """Bright tongues on a dark background: a travelling wave through a steep sigmoid, with sensor
    noise, so that most values lie near 0 or near 255 and only the edges between."""
    wave = wave_clip(t, h, w, channels=1, seed=seed, periods=(13.0, 7.0))[..., 0].astype(np.float64)
    v = 255 / (1 + np.exp(-(wave - 128) / 4)) + np.random.default_rng(seed).normal(0, 3, wave.shape)
    return np.clip(np.stack([v, 0.8 * v + 10, 0.5 * v + 5], axis=-1), 0, 255).astype(np.uint8)


def stationary_energy(model, frames: np.ndarray, samples: int = 300) -> float:
    """Energy about the clip's mean of frames drawn from the lds model's stationary state
    distribution (projected as the player does), against the clip's own."""
    t, h, w, c = frames.shape
    rng = np.random.default_rng(1)
    states = rng.multivariate_normal(np.zeros(model.n), model.stationary_cov, samples)
    engine = open_projector(model.basis, model.mean, shape=(h, w, c), channels=c, frames=samples, tone=model.tone)
    engine.coefs[:] = states
    out = np.empty((samples, h, w, c), np.uint8)
    engine.run(out, count=samples)
    src = frames.reshape(t, -1).astype(np.float64)
    mean = src.mean(axis=0)
    return float(((out.reshape(samples, -1) - mean) ** 2).mean() / ((src - mean) ** 2).mean())


def test_saturation_share_tells_piled_up_clips():
    assert saturation_share(flames()) > 3 * SATURATION_SHARE
    assert saturation_share(wave_clip()) < SATURATION_SHARE / 10


def test_flames_keep_their_energy_on_tone_values():
    """A Gaussian model of the levels loses a third of the flames' energy at the store; the same
    model on tone values keeps nine tenths."""
    clip = flames()
    plain = learn_lds(clip, n=10, tone="off")
    toned = learn_lds(clip, n=10)
    assert plain.tone is None and toned.tone is not None
    assert toned.tone.info["saturation_share"] > SATURATION_SHARE
    assert stationary_energy(plain, clip) < 0.7
    assert 0.85 < stationary_energy(toned, clip) < 1.2


def level_variance(model, states: np.ndarray, shape: tuple[int, int, int]) -> float:
    """Mean over values of the variance over ``states`` (``(k, n)``) of the frames the player projects."""
    engine = open_projector(
        model.basis, model.mean, shape=shape, channels=shape[-1], frames=len(states), tone=model.tone
    )
    engine.coefs[:] = states
    out = np.empty((len(states), *shape), np.uint8)
    engine.run(out, count=len(states))
    return float(out.reshape(len(states), -1).astype(np.float64).var(axis=0).mean())


def test_tone_mapped_draws_keep_the_training_levels_variance():
    """A pixel of the flames is dark or bright, at the tone map's flat ends; Gaussian draws with the
    training states' covariance spend their time in the steep middle and hold less variance in
    levels. The level gain gives the draws the training reconstructions' variance there."""
    clip = flames(t=200)
    model = learn_lds(clip, n=10)
    gain = model.info["level_gain"]
    assert gain > 1.2
    rng = np.random.default_rng(1)
    draws = rng.multivariate_normal(np.zeros(model.n), model.stationary_cov, 2000)
    train = level_variance(model, model.states.T, clip.shape[1:])
    assert 0.96 < level_variance(model, draws, clip.shape[1:]) / train < 1.04
    assert level_variance(model, draws / np.sqrt(gain), clip.shape[1:]) / train < 0.92
    assert "level_gain" not in learn_lds(clip, n=10, calibrate=False).info
    assert "level_gain" not in learn_lds(wave_clip(), n=8).info


def test_a_mixture_of_the_two_ends_needs_no_gain_where_one_gaussian_does():
    """Values at the two flat ends of a map: one Gaussian of their mean and variance needs its
    variance raised to reach theirs in levels, two Gaussians at the ends (a mixture's components)
    hold it as they are."""
    steep = ToneModel(np.linspace(100.0, 200.0, 256, dtype=np.float32)[None])
    rng = np.random.default_rng(0)
    ends = np.where(rng.random((4000, 1)) < 0.5, 110.0, 190.0) + rng.normal(0, 3, (4000, 1))
    train = (ends, np.eye(1), np.zeros(1))  # the reconstructions: ends @ I + 0
    one = gain_for(steep, train, ends.mean(axis=0)[None], ends.std(axis=0)[None])
    groups = [ends[ends < 150], ends[ends >= 150]]
    means, sds = np.array([[g.mean()] for g in groups]), np.array([[g.std()] for g in groups])
    two = gain_for(steep, train, means, sds, np.array([len(g) for g in groups]))
    assert one > 2.0
    assert 0.95 < two < 1.05
    assert (
        round(
            gain_for(
                ToneModel(np.linspace(-500.0, 800.0, 256, dtype=np.float32)[None]),
                train,
                ends.mean(axis=0)[None],
                ends.std(axis=0)[None],
            ),
            2,
        )
        == 1.0
    )


def test_a_mixture_on_tone_values_is_calibrated_in_levels(tmp_path):
    clip = load_clip(flames(t=120))
    kw = dict(components=2, dim=3, pca_dim=8, neighbors=6, pmax=2, residual="on")
    model = learn_mixture(clip, **kw)
    assert 0.5 < model.info["level_gain"] < 2.0
    assert "level_gain" not in learn_mixture(clip, tone="off", **kw).info
    # the scaled local covariances, noise and residual still pass the format's checks and play
    path = tmp_path / "m.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("f", clip.source_info())
        w.put_method("f", "mixture", model)
    with MixturePlayer(path, seed=1, backend="numpy") as p:
        frames = np.stack([p.next_frame() for _ in range(20)])
    assert frames.std() > 10
    # the same model with the gain undone draws less variance in levels, further from the clip's
    g = model.info["level_gain"]
    model.local_cov = model.local_cov / g
    model.switching.local_noise = model.switching.local_noise / np.sqrt(g)
    model.residual.noise = model.residual.noise / np.sqrt(g)
    undone = tmp_path / "undone.h5"
    with DatabaseWriter(undone) as w:
        w.put_texture("f", clip.source_info())
        w.put_method("f", "mixture", model)
    played = {}
    for db in (path, undone):
        with MixturePlayer(db, seed=1, backend="numpy") as p:
            p.advance(100)
            played[db] = np.stack([p.next_frame() for _ in range(1400)]).astype(np.float64).var(axis=0).mean()
    source = clip.frames.astype(np.float64).var(axis=0).mean()
    assert g > 1.1 and played[path] > 1.03 * played[undone]
    assert abs(played[path] - source) < abs(played[undone] - source)


def test_other_clips_stay_on_their_levels():
    clip = wave_clip()
    assert learn_lds(clip, n=8).tone is None
    model = learn_lds(clip, n=8, tone="on")
    assert model.tone is not None
    assert 0.9 < stationary_energy(model, clip) < 1.1


def test_mixture_learns_on_tone_values_where_the_clip_piles_up():
    kw = dict(components=2, dim=3, pca_dim=8, neighbors=6, pmax=2)
    assert learn_mixture(flames(), **kw).tone is not None
    assert learn_mixture(flames(), tone="off", **kw).tone is None
    assert learn_mixture(wave_clip(), **kw).tone is None


@pytest.mark.parametrize("tone", ["sometimes", 1])
def test_a_bad_tone_is_named(tone):
    with pytest.raises(InvalidArgumentError, match="tone"):
        learn_lds(wave_clip(), n=4, tone=tone)


def test_a_gain_the_search_cannot_reach_is_its_bound():
    """Draws too narrow to reach the training's variance at any gain in range: the search ends at
    MAX_GAIN (a model scaled as far as it goes), not at some value in between."""
    from dynatex.analyzer.tone import MAX_GAIN

    steep = ToneModel(np.linspace(100.0, 200.0, 256, dtype=np.float32)[None])
    ends = np.where(np.arange(400)[:, None] % 2 == 0, 100.0, 200.0)
    gain = gain_for(steep, (ends, np.eye(1), np.zeros(1)), np.array([[150.0]]), np.array([[0.5]]))
    assert MAX_GAIN * 0.999 < gain <= MAX_GAIN
