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
            sums = (coefs @ basis + mean).reshape(4, h * w, channels)
            levels = ToneLookup(tone).levels(sums.astype(np.float32)).reshape(4, h, w, channels)
            np.testing.assert_array_equal(want[..., list(fmt.rgb)], np.broadcast_to(levels, (4, h, w, 3)))
    finally:
        engine.close()


def test_lookup_returns_each_level_from_its_tone_value():
    """Every level's own tone value maps back to that level, and values beyond the ends to 0 and 255."""
    rng = np.random.default_rng(3)
    clip = np.where(rng.random((20, 8, 8, 3)) < 0.6, 0, rng.integers(0, 256, (20, 8, 8, 3))).astype(np.uint8)
    tone = learn_tone(clip)
    lookup = ToneLookup(tone)
    levels = lookup.levels(np.ascontiguousarray(tone.forward.T))
    np.testing.assert_array_equal(levels, np.broadcast_to(np.arange(256)[:, None], (256, 3)))
    ends = lookup.levels(np.array([[-1e6] * 3, [1e6] * 3], np.float32))
    assert ends.tolist() == [[0, 0, 0], [255, 255, 255]]
    values = to_tone(clip, tone).reshape(20, -1, 3)
    np.testing.assert_array_equal(lookup.levels(values), clip.reshape(20, -1, 3))
