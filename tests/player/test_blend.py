"""The blend engine (mode turnpoints' device work): OpenCL against its numpy reference, exactly."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.player.engines.blend import BlendOpenCL, blend_reference, open_blend


def _frames(t=5, h=7, w=11, seed=0):
    # 7 x 11 x 3 = 231 bytes: not a whole number of the kernel's 64-byte work-items
    return np.random.default_rng(seed).integers(0, 256, (t, h, w, 3), dtype=np.uint8)


def test_reference_is_the_rounded_weighted_sum():
    f = _frames()
    out = np.empty(f.shape[1:], np.uint8)
    blend_reference(f, ((1, 64), (3, 192)), out)
    want = (f[1].astype(int) * 64 + f[3].astype(int) * 192 + 128) >> 8
    assert np.array_equal(out, want)
    assert np.array_equal(blend_reference(f, ((4, 256),), out), f[4])


SOURCES = [((2, 256),), ((0, 200), (4, 56)), ((1, 100), (2, 100), (3, 56)), ((0, 64), (1, 64), (2, 64), (3, 64))]


@pytest.mark.parametrize("sources", SOURCES, ids=["1", "2", "3", "4"])
def test_opencl_equals_the_reference(cl_context, sources):
    import pyopencl as cl

    f = _frames()
    b = open_blend(f, ctx=cl_context, queue=cl.CommandQueue(cl_context))
    assert isinstance(b, BlendOpenCL)
    ref = blend_reference(f, sources, np.empty(f.shape[1:], np.uint8))
    out = np.zeros(f.shape[1:], np.uint8)
    event = b.render(sources, out, wait=False)
    assert event is not None
    event.wait()
    assert np.array_equal(out, ref)
    assert b.memory_bytes == 5 * 256 and b.bytes_per_frame == 2 * 231
    b.close()
    assert not hasattr(b, "_d_frames")


@pytest.mark.parametrize("fmt", ["RGB", "RGBA", "BGRA"])
@pytest.mark.parametrize("size", [(7, 11), (4, 8)], ids=["77 px", "32 px"])
def test_every_format_equals_the_reference(cl_context, fmt, size):
    """Every format from the RGB stack: whole vectors (16 pixels for RGBA and BGRA), a partial
    last work-item (77 pixels), every term count, into an array that is not 4-byte aligned
    (the kernels write it directly where the device shares host memory)."""
    import pyopencl as cl

    from dynatex.player.pixels import pixel_format

    f = _frames(h=size[0], w=size[1], seed=1)
    b = open_blend(f, ctx=cl_context, queue=cl.CommandQueue(cl_context), format=fmt)
    stack = pixel_format(fmt).from_rgb(f)
    raw = np.zeros(stack[0].size + 2, np.uint8)
    out = raw[1:-1].reshape(stack.shape[1:])  # one byte off the array's start
    for sources in SOURCES:
        ref = blend_reference(stack, sources, np.empty(stack.shape[1:], np.uint8))
        out[...] = 0
        b.render(sources, out)
        assert np.array_equal(out, ref), sources
    assert raw[0] == raw[-1] == 0  # nothing written outside the frame
    px = size[0] * size[1]
    assert b.memory_bytes == 5 * -(-px * 3 // 64) * 64  # the stack stays RGB
    assert b.bytes_per_frame == px * (3 + stack.shape[-1])
    b.close()


def test_bad_inputs_are_clear_errors():
    with pytest.raises(ValueError, match=r"frames must be uint8 \(T, H, W, 3\)"):
        open_blend(np.zeros((2, 3, 3), np.uint8))
    b = open_blend(_frames())
    out = np.empty((7, 11, 3), np.uint8)
    with pytest.raises(ValueError, match="a blend takes 1 to 4 sources, not 5"):
        b.render(tuple((i, 51) for i in range(5)), out)
    with pytest.raises(ValueError, match=r"blend source \(5, 128\) names no frame of 5"):
        b.render(((0, 128), (5, 128)), out)
    with pytest.raises(ValueError, match="blend weights must sum to 256, not 255"):
        b.render(((0, 128), (1, 127)), out)


def test_a_bad_source_never_reaches_the_device(cl_context):
    """An out-of-range frame is refused before the kernel could read past the stack."""
    import pyopencl as cl

    b = open_blend(_frames(), ctx=cl_context, queue=cl.CommandQueue(cl_context))
    for sources in (((-1, 256),), ((0, 128), (7, 128)), ((0, 64), (1, 64), (2, 64), (99, 64))):
        with pytest.raises(ValueError, match="names no frame of 5"):
            b.render(sources, np.empty((7, 11, 3), np.uint8))
    b.close()
