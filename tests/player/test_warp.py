"""Motion-compensated crossfades: the warp kernel against its numpy reference, exactly, and what the
warp does to a moving object."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.player.engines.blend import blend_reference, open_blend
from dynatex.player.engines.warp import WarpBlend, warp_reference
from dynatex.tiledb.turnpoints import FlowModel, flow_grid


def _frames(t=4, h=13, w=21, seed=0):
    # 13 x 21: neither side a multiple of the grid step, so the last grid cells are partial
    return np.random.default_rng(seed).integers(0, 256, (t, h, w, 3), dtype=np.uint8)


def _flow(h, w, step, pairs, seed=1, scale=80):
    rng = np.random.default_rng(seed)
    grid = flow_grid(h, w, step)
    flows = rng.integers(-scale, scale + 1, (len(pairs), *grid, 2)).astype(np.int16)
    return FlowModel(pairs=np.array(pairs, np.int32), flows=flows, step=step)


def test_zero_flow_is_the_plain_crossfade():
    f = _frames()
    zero = np.zeros(flow_grid(13, 21, 4) + (2,), np.int16)
    for wa in (0, 51, 128, 205, 256):
        out = warp_reference(f, 0, 2, wa, 256 - wa, zero, 2, np.empty(f.shape[1:], np.uint8))
        assert np.array_equal(out, blend_reference(f, ((0, wa), (2, 256 - wa)), np.empty_like(out)))


def test_a_bar_slides_instead_of_showing_twice():
    """A bar 3 pixels wide moves 8 pixels: the plain crossfade shows two half-bright bars, the warp one bar
    between them at full brightness."""
    f = np.zeros((2, 8, 40, 3), np.uint8)
    f[0, :, 10:13] = f[1, :, 18:21] = 240
    grid = np.zeros(flow_grid(8, 40, 4) + (2,), np.int16)
    grid[..., 0] = 8 * 16
    out = warp_reference(f, 0, 1, 128, 128, grid, 2, np.empty((8, 40, 3), np.uint8))
    plain = blend_reference(f, ((0, 128), (1, 128)), np.empty_like(out))
    assert np.flatnonzero(plain[4, :, 0] > 100).tolist() == [10, 11, 12, 18, 19, 20]
    assert np.flatnonzero(out[4, :, 0] > 200).tolist() == [14, 15, 16]
    # a quarter of the way: the bar 2 pixels on from frame 0's
    out = warp_reference(f, 0, 1, 192, 64, grid, 2, out)
    assert np.flatnonzero(out[4, :, 0] > 200).tolist() == [12, 13, 14]


def test_engine_warps_stored_pairs_either_way_and_blends_the_rest():
    f = _frames()
    flow = _flow(13, 21, 4, [(1, 3)])
    engine = WarpBlend(open_blend(f), flow)
    out = np.empty(f.shape[1:], np.uint8)
    engine.render(((1, 154), (3, 102)), out)
    first = warp_reference(f, 1, 3, 154, 102, flow.flows[0], 2, np.empty_like(out))
    assert np.array_equal(out, first)
    # the pair the other way round: the same picture (the formula is symmetric; the roles are swapped back)
    out[...] = 0
    engine.render(((3, 102), (1, 154)), out)
    assert np.array_equal(out, first)
    assert engine.warped == 2
    for sources in (((0, 128), (1, 128)), ((1, 256),), ((1, 100), (3, 100), (0, 56))):
        engine.render(sources, out)
        assert np.array_equal(out, blend_reference(f, sources, np.empty_like(out)))
    assert engine.warped == 2


@pytest.mark.parametrize("fmt", ["RGB", "BGRA"])
@pytest.mark.parametrize("step", [4, 8])
def test_opencl_equals_the_reference(cl_context, fmt, step):
    import pyopencl as cl

    from dynatex.player.pixels import pixel_format

    f = _frames()
    flow = _flow(13, 21, step, [(0, 2), (3, 1)], scale=400)  # up to 25 px: samples leave the frame
    queue = cl.CommandQueue(cl_context)
    engine = WarpBlend(open_blend(f, ctx=cl_context, queue=queue, format=fmt), flow, ctx=cl_context, queue=queue)
    stack = pixel_format(fmt).from_rgb(f)
    for sources, (a, b, wa, wb, k, sign) in (
        (((0, 205), (2, 51)), (0, 2, 205, 51, 0, 1)),
        (((1, 128), (3, 128)), (3, 1, 128, 128, 1, 1)),
        (((1, 51), (3, 205)), (3, 1, 205, 51, 1, 1)),
    ):
        out = np.zeros(stack.shape[1:], np.uint8)
        engine.render(sources, out)
        ref = warp_reference(stack, a, b, wa, wb, sign * flow.flows[k], step.bit_length() - 1, np.empty_like(out))
        assert np.array_equal(out, ref), sources
    assert engine.warped == 3
    engine.close()


def test_bad_flows_are_clear_errors():
    f = _frames()
    with pytest.raises(ValueError, match="do not fit frames of 13x21"):
        WarpBlend(open_blend(f), _flow(12, 21, 4, [(0, 1)]))
    with pytest.raises(ValueError, match="flow pairs name frames outside 0..3"):
        WarpBlend(open_blend(f), _flow(13, 21, 4, [(0, 4)]))
