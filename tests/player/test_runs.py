"""The runs engine of mode ``evolve``: the run tables say what the quilt says and stay inside
the frames, and the OpenCL engine draws what the numpy reference draws, frame in flight,
for any source time function the mode gives it."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer.quilt import learn_quilt, spreading_clip
from dynatex.player.engines.runs import (
    RATE_STEP,
    SPILL,
    RunsOpenCL,
    RunsReference,
    build_runs,
    check_runs,
    cut_runs,
    open_runs,
    quantize_rate,
)


@pytest.fixture(scope="module")
def quilt():
    frames = spreading_clip(24, 32, 32)
    q = learn_quilt(frames, size=(56, 72), block=12, rank=6, lowpass=6.0, seed=1)
    assert q.blend_weight is not None and q.gain is not None
    return frames, q


def _engine_inputs(frames, q):
    sw = frames.shape[2]
    flat = np.ascontiguousarray(frames.reshape(frames.shape[0], -1, 3))
    pix = q.source_map[..., 0].astype(np.int64) * sw + q.source_map[..., 1]
    blend = (
        np.rint(q.blend_weight.astype(np.float64) * 256).astype(np.int64),
        q.blend_map[..., 0].astype(np.int64) * sw + q.blend_map[..., 1],
        q.blend_labels.astype(np.int64),
    )
    gain = np.ascontiguousarray(np.repeat(q.gain, 3, axis=2) if q.gain.shape[2] == 1 else q.gain, np.float32)
    return flat, pix, blend, gain


def _times(offsets):
    """A source time function: rate times the clock plus a per-block offset, held inside the frames."""

    def source_time(rate, blocks, t):
        local = np.full(blocks.shape, t, np.float32) if rate is None else (t * rate).astype(np.float32)
        return np.clip(local + offsets[blocks], np.float32(0), np.float32(23)).astype(np.float32)

    return source_time


def test_runs_describe_the_quilt(quilt):
    """The run tables of the kernel say exactly what the per-pixel quilt says, and a run's
    last 16-byte chunk may spill only where it stays within its row."""
    _, q = quilt
    h, w = q.labels.shape
    sw = 32
    pix = q.source_map[..., 0].astype(np.int64) * sw + q.source_map[..., 1]
    pix2 = q.blend_map[..., 0].astype(np.int64) * sw + q.blend_map[..., 1]
    wq = np.rint(q.blend_weight.astype(np.float64) * 256).astype(np.int64)
    r = build_runs(pix, q.labels, wq, pix2, q.blend_labels)
    runs = r["runs"].view(np.uint32).astype(np.int64)
    start, length = runs[:, 0], runs[:, 3] & 0x3FFFFFFF
    blend, spill = runs[:, 3] >> 31 == 1, (runs[:, 3] >> 30) & 1 == 1
    np.testing.assert_array_equal(start, np.cumsum(np.append(0, length[:-1])))  # cover every pixel, in order
    assert ((start % w) + length <= w).all()  # within a row
    np.testing.assert_array_equal(r["row_start"], np.searchsorted(start, np.arange(h + 1) * w))
    col3 = (start % w) * 3
    assert (col3[spill] + -(-length[spill] * 3 // SPILL) * SPILL <= 3 * w).all()
    assert spill.mean() > 0.9
    code = r["code"].reshape(h, w, 3)
    assert (code[..., 0] == code[..., 1]).all() and (code[..., 0] == code[..., 2]).all()
    code = code[..., 0].astype(np.int64)
    # per pixel: the primary and second source from the streams and the code
    k = np.repeat(np.arange(len(start)), length)
    x = np.arange(h * w) - start[k]
    a_pix, a_lab = runs[k, 1] + x, runs[k, 2]
    b_pix, b_lab = r["runs_b"][k, 0] + x, r["runs_b"][k, 1]
    swap = (code >> 9).ravel() == 1
    band = (wq > 0).ravel()
    np.testing.assert_array_equal(np.where(swap, b_pix, a_pix), pix.ravel())
    np.testing.assert_array_equal(np.where(swap, b_lab, a_lab), q.labels.ravel())
    np.testing.assert_array_equal((code & 0x1FF).ravel(), wq.ravel())
    np.testing.assert_array_equal(np.where(swap, a_pix, b_pix)[band], pix2.ravel()[band])
    np.testing.assert_array_equal(np.where(swap, a_lab, b_lab)[band], q.blend_labels.ravel()[band])
    assert (blend[k] | ~band).all()
    assert len(start) < h * w / 4  # runs, not pixels
    plain = build_runs(pix, q.labels, wq, pix2, q.blend_labels, merge=False)  # bands only
    assert len(plain["starts"]) > len(start) and not (plain["code"].reshape(h, w, 3)[..., 0][~(wq > 0)]).any()


@pytest.mark.parametrize("fmt", ["RGB", "RGBA", "BGRA"])
@pytest.mark.parametrize("loop", [False, True])
def test_opencl_engine_matches_reference(quilt, cl_context, loop, fmt):
    """The engine pair on its own, through its interface: same frames (float32 both sides, at
    most one grey level apart where a device contracts a multiply-add), with and without a
    rate map (short runs), the frame left in flight, the reference's pixels exact on most
    frames; a four-byte format's frames are the RGB engine's, placed (16-pixel chunks)."""
    import pyopencl as cl

    from dynatex.player.pixels import pixel_format

    frames, q = quilt
    flat, pix, blend, gain = _engine_inputs(frames, q)
    h, w = q.labels.shape
    n_blocks = q.n_blocks
    opts = {"n_blocks": n_blocks, "blend": blend, "gain": gain, "interpolate": True, "format": fmt}
    queue = cl.CommandQueue(cl_context)
    ref = open_runs(flat, (h, w), pix, q.labels.astype(np.int64), **opts)
    dev = open_runs(flat, (h, w), pix, q.labels.astype(np.int64), ctx=cl_context, queue=queue, **opts)
    rgb = open_runs(
        flat, (h, w), pix, q.labels.astype(np.int64), ctx=cl_context, queue=queue, **opts | {"format": "RGB"}
    )
    pb = pixel_format(fmt).bytes
    assert isinstance(ref, RunsReference) and isinstance(dev, RunsOpenCL)
    source_time = _times(np.random.default_rng(0).uniform(-2, 2, n_blocks).astype(np.float32))
    rate = quantize_rate(np.tile(np.linspace(0.5, 2.5, w, dtype=np.float32), (h, 1)))
    exact = total = 0
    try:
        for r in (None, rate):
            for e in (ref, dev, rgb):
                e.set_rate(r)
            for t in (0.0, 2.4, 9.75, 17.5):
                a, b = np.empty((h, w, pb), np.uint8), np.empty((h, w, pb), np.uint8)
                assert ref.start(t, a, source_time=source_time, loop=loop) is None
                event = dev.start(t, b, source_time=source_time, loop=loop, wait=False)
                event.wait()
                diff = np.abs(a.astype(int) - b)
                assert diff.max() <= 1, (r is None, t)
                c = np.empty((h, w, 3), np.uint8)
                rgb.start(t, c, source_time=source_time, loop=loop, wait=True)
                assert np.array_equal(b, pixel_format(fmt).from_rgb(c)), (r is None, t)
                exact += bool(diff.max() == 0)
                total += 1
        assert exact >= total - 2
        assert dev.n_runs > len(build_runs(pix, q.labels, *blend[:1], blend[1], blend[2])["starts"]) - 1
    finally:
        dev.close()
        rgb.close()
    assert not hasattr(dev, "_d_stack")


def test_rate_cuts_keep_every_pixel_and_name_each_rate_once(quilt):
    """Cutting the runs where the rate changes covers the same pixels, and every run's time
    slots are the (rate, block) pairs of its streams."""
    frames, q = quilt
    _, pix, blend, _ = _engine_inputs(frames, q)
    h, w = q.labels.shape
    base = build_runs(pix, q.labels, *blend, n_pixels=32 * 32)
    rate = quantize_rate(np.where(np.arange(w) < w // 3, 1.0, 2.0).astype(np.float32)[None].repeat(h, 0))
    runs, _, row_start, pair, slot_block, slot_rate = cut_runs(base, rate, (h, w), q.n_blocks)
    r = runs.view(np.uint32).astype(np.int64)
    start, length = r[:, 0], r[:, 3] & 0x3FFFFFFF
    np.testing.assert_array_equal(start, np.cumsum(np.append(0, length[:-1])))
    assert start[-1] + length[-1] == h * w and row_start[-1] == len(runs)
    np.testing.assert_array_equal(slot_block[pair[:, 0]], r[:, 2])
    np.testing.assert_array_equal(slot_rate[pair[:, 0]], rate.reshape(-1)[start])
    assert set(np.unique(slot_rate).tolist()) == {1.0, 2.0} and (slot_rate % RATE_STEP == 0).all()
    uniform = cut_runs(base, None, (h, w), q.n_blocks)
    assert uniform[5] is None and len(uniform[0]) < len(runs)


def test_run_tables_that_leave_the_frames_are_refused():
    pix = np.arange(16)[None] + 3
    runs = build_runs(pix, np.zeros((1, 16)), n_pixels=32)
    check_runs(runs, 32, 1)
    with pytest.raises(ValueError, match=r"make 1 run\(s\) read outside the source frames \(16 pixels"):
        check_runs(runs, 16, 1)
