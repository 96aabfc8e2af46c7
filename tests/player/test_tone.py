"""The tone map of projection models: the kernel against its reference, and the lookup."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from dynatex.analyzer.tone import learn_tone, to_tone
from dynatex.player.engines.projection import open_projector
from dynatex.player.engines.tone import ToneLookup
from dynatex.player.opencl.selftest import random_colour_set, random_tone
from dynatex.player.pixels import FORMATS
from dynatex.tiledb.gamut import GamutModel
from dynatex.tiledb.schema import FORMAT_VERSION

from .test_detail import _model, exact_projection


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("format", ["RGB", "BGRA"])
@pytest.mark.parametrize("detail", [False, True], ids=["alone", "with-detail"])
@pytest.mark.parametrize("size", [(23, 41), (20, 64)], ids=["pixel-by-pixel", "vectors"])
def test_kernel_equals_numpy_reference(cl_context, channels, format, detail, size):
    """A model learned on tone values projects, through the lookup, to the reference's levels bit
    for bit (sums exact in float32), k frames per pass and one at a time, with the detail and (colour)
    the colour set after it; and the levels are the lookup's, not the sums rounded."""
    rng = np.random.default_rng(channels * 10 + detail)
    h, w = size
    fmt = FORMATS[format]
    basis, mean = exact_projection(rng, h, w, channels)
    tone = random_tone(rng, channels)
    gamut = GamutModel(random_colour_set(rng)) if channels == 3 else None
    kw = dict(shape=(h, w, fmt.bytes), channels=channels, format=format, frames=4, gamut=gamut)
    kw["detail"] = _model(rng, h, w, channels) if detail else None
    engine = open_projector(basis, mean, ctx=cl_context, queue=cl.CommandQueue(cl_context), tone=tone, **kw)
    ref = open_projector(basis, mean, tone=tone, **kw)
    plain = open_projector(basis, mean, **kw)
    try:
        coefs = rng.integers(-4, 5, (4, 5)).astype(np.float32)
        engine.coefs[:] = ref.coefs[:] = plain.coefs[:] = coefs
        lay = [ref.detail.layers(3, k, 1.5) for k in (0, 4, 9, 30)] if detail else None
        got, want, rounded = (np.empty((4, h, w, fmt.bytes), np.uint8) for _ in range(3))
        engine.run(got, count=4, layers=lay)
        ref.run(want, count=4, layers=lay)
        plain.run(rounded, count=4, layers=lay)
        np.testing.assert_array_equal(got, want)
        single = np.empty((h, w, fmt.bytes), np.uint8)
        engine.coef[:] = coefs[2]
        engine.run(single, layers=None if lay is None else [lay[2]])
        np.testing.assert_array_equal(single, want[2])
        assert (want != rounded).any(axis=-1).mean() > 0.3  # the lookup, not the sums rounded
        if not detail and gamut is None:
            levels = ToneLookup(tone).levels((coefs @ basis + mean).astype(np.float32)).reshape(4, h, w, channels)
            np.testing.assert_array_equal(want[..., list(fmt.rgb)], np.broadcast_to(levels, (4, h, w, 3)))
    finally:
        engine.close()


def test_lookup_returns_each_level_from_its_tone_value():
    """Every level's own tone value maps back to that level, and values beyond the ends to 0 and 255."""
    rng = np.random.default_rng(3)
    clip = np.where(rng.random((20, 8, 8, 3)) < 0.6, 0, rng.integers(0, 256, (20, 8, 8, 3))).astype(np.uint8)
    tone = learn_tone(clip)
    lookup = ToneLookup(tone)
    levels = lookup.levels(np.ascontiguousarray(tone.forward.T).reshape(1, -1))
    np.testing.assert_array_equal(levels.reshape(256, 3), np.broadcast_to(np.arange(256)[:, None], (256, 3)))
    ends = lookup.levels(np.array([[-1e6] * 3, [1e6] * 3], np.float32))
    assert ends.tolist() == [[0, 0, 0], [255, 255, 255]]
    np.testing.assert_array_equal(lookup.levels(to_tone(clip, tone)), clip.reshape(20, -1))


def test_lookup_in_short_runs_gives_the_same_levels(monkeypatch):
    """numpy looks levels up in runs of CHUNK values: short runs give the levels of one run."""
    from dynatex.player.engines import tone as engine

    rng = np.random.default_rng(4)
    clip = np.where(rng.random((6, 8, 8, 3)) < 0.6, 0, rng.integers(0, 256, (6, 8, 8, 3))).astype(np.uint8)
    tone = learn_tone(clip)
    values = to_tone(clip, tone)
    whole = ToneLookup(tone).levels(values.copy())
    monkeypatch.setattr(engine, "CHUNK", 9)
    np.testing.assert_array_equal(ToneLookup(tone).levels(values.copy()), whole)
    np.testing.assert_array_equal(whole, clip.reshape(6, -1))


@pytest.fixture(scope="module")
def flames_db(tmp_path_factory):
    """lds and mixture of the flames clip, learned on tone values (the default) and on levels."""
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds
    from dynatex.analyzer.mixture import learn_mixture
    from dynatex.tiledb import DatabaseWriter

    from ..analyzer.test_tone import flames

    src = flames()
    clip = load_clip(src)
    paths = {}
    for tone in ("auto", "off"):
        paths[tone] = tmp_path_factory.mktemp("flames") / f"{tone}.h5"
        with DatabaseWriter(paths[tone]) as w:
            w.put_texture("flames", clip.source_info())
            w.put_method("flames", "lds", learn_lds(clip, n=10, tone=tone))
            mix = learn_mixture(clip, components=2, dim=3, pca_dim=10, neighbors=6, pmax=2, tone=tone)
            w.put_method("flames", "mixture", mix)
    return paths, src


def _energy(path, mode, src, frames=300, **kw):
    from dynatex.player import open_player

    with open_player(path, mode=mode, seed=3, **kw) as p:
        p.advance(200)
        out = np.stack([p.next_frame() for _ in range(frames)])
    flat = src.reshape(len(src), -1).astype(np.float64)
    mean = flat.mean(axis=0)
    return float(((out.reshape(frames, -1) - mean) ** 2).mean() / ((flat - mean) ** 2).mean()), out


@pytest.mark.parametrize("mode", ["lds", "mixture"])
def test_flames_played_from_the_database_keep_their_energy(flames_db, mode):
    """The tone part round-trips through the database (format 2.0) and the player maps through
    it: the flames keep more of their energy than the same model learned on levels."""
    import h5py

    from dynatex.player import open_player

    paths, src = flames_db
    with h5py.File(paths["auto"]) as f:
        assert tuple(f.attrs["format_version"]) == FORMAT_VERSION
    with open_player(paths["auto"], mode=mode, backend="numpy") as p:
        assert p.engine.tone is not None
    toned, _ = _energy(paths["auto"], mode, src, backend="numpy")
    plain, _ = _energy(paths["off"], mode, src, backend="numpy")
    assert toned > plain + 0.1
    assert 0.75 < toned < 1.3


@pytest.mark.parametrize("mode", ["lds", "mixture"])
def test_flames_on_both_backends(flames_db, mode, cl_device):
    paths, src = flames_db
    _, a = _energy(paths["auto"], mode, src, frames=40, backend="opencl", device=cl_device)
    _, b = _energy(paths["auto"], mode, src, frames=40, backend="numpy")
    diff = np.abs(a.astype(int) - b)
    assert diff.max() <= 1 and (diff > 0).mean() <= 1e-3  # the projection's documented tolerance


def test_a_not_a_number_becomes_level_zero_as_on_opencl():
    """OpenCL's clamp (fmin of fmax) takes NaN to the lower bound; the reference does the same
    instead of failing on an index far outside its table."""
    lookup = ToneLookup(random_tone(np.random.default_rng(4), 3))
    values = np.array([[np.nan, 0.0, np.inf, -np.inf, 1e30, -1e30]], np.float32)
    assert lookup.levels(values).tolist() == [
        [0.0, lookup.levels(np.zeros((1, 3), np.float32))[0, 1], 255.0, 0.0, 255.0, 0.0]
    ]
