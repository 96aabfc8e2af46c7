"""dynatex.benchmark: the copy bandwidth behind every roofline figure."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from dynatex.benchmark import COPY_BLOCKS, copy_bandwidth
from dynatex.player.opencl.context import variant_verified
from dynatex.player.opencl.programs import build_program

from .conftest import verified_devices


def test_copy_kernels_copy_every_byte(cl_context):
    """Both copies (plain and streaming stores) reproduce the source exactly: a bandwidth
    is only meaningful if the kernel really moved the bytes."""
    queue = cl.CommandQueue(cl_context)
    src = np.random.default_rng(0).random(16 * COPY_BLOCKS * 8, dtype=np.float32)  # 8 streaming work-items
    copies = [("plain", build_program(cl_context, "copy.cl"), src.size // 16)]
    if variant_verified(cl_context.devices[0], "copy_stream"):
        copies.append(
            (
                "stream",
                build_program(cl_context, "variants/copy_stream.cl", {"BLOCKS": COPY_BLOCKS}),
                src.size // (16 * COPY_BLOCKS),
            )
        )
    for name, prog, size in copies:
        a = cl.Buffer(cl_context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=src)
        b = cl.Buffer(cl_context, cl.mem_flags.WRITE_ONLY, src.nbytes)
        copy = prog.kernel(f"copy_{name}")
        copy.set_args(a, b)
        cl.enqueue_nd_range_kernel(queue, copy, (size,), None)
        out = np.zeros_like(src)
        cl.enqueue_copy(queue, out, b)
        queue.finish()
        np.testing.assert_array_equal(out, src, err_msg=f"copy_{name}")


def test_copy_bandwidth_is_the_fastest_copy():
    if not verified_devices():
        pytest.skip("no verified OpenCL device here: the copy bandwidth compares OpenCL copies")
    bw = copy_bandwidth(mbytes=8, repeats=1)
    assert "opencl_error" not in bw
    copies = [k for k in bw if k.startswith("opencl_") and k.endswith("_gbs") and k != "opencl_gbs"]
    assert "opencl_plain_gbs" in copies and set(copies) <= {"opencl_plain_gbs", "opencl_stream_gbs"}
    for key in ("numpy_gbs", *copies):
        assert bw[key] > 0, key
    assert bw["opencl_gbs"] == max(bw[k] for k in copies)
    assert bw["gbs"] == max(bw["numpy_gbs"], bw["opencl_gbs"])


@pytest.mark.parametrize("kw", [{"mbytes": 0}, {"repeats": 0}, {"mbytes": 2.5}])
def test_copy_bandwidth_rejects_bad_sizes(kw):
    with pytest.raises((ValueError, TypeError), match=next(iter(kw))):
        copy_bandwidth(**kw)
