"""The engines' shared pieces: kernels called by argument name, frames delivered into the
caller's array (directly or through a copy) and left in flight by every mode."""

from __future__ import annotations

import warnings

import numpy as np
import pyopencl as cl
import pytest

from dynatex.errors import InvalidArgumentError
from dynatex.player import open_player
from dynatex.player.engines import ENGINES, Engine, open_engine
from dynatex.player.engines.base import FrameOut, Kernel
from dynatex.player.opencl import selftest
from dynatex.player.opencl.programs import build_program
from dynatex.player.pixels import FORMATS

RGB = FORMATS["RGB"].defines
BGRA = FORMATS["BGRA"].defines

MODES = [
    ("lds", {}),
    ("mixture", {}),
    ("turnpoints", {"playback": "jumps"}),
    ("tiles", {"size": (72, 40)}),
    ("evolve", {"jitter": 2.0}),
]


def test_kernel_arguments_are_the_names_of_the_signature(cl_context):
    defines = {"HALF": 0, "CHANNELS": 3, "DETAIL": 0, **RGB}
    k = Kernel(build_program(cl_context, ("pixels.cl", "projection.cl"), defines), "project")
    assert k.args[:9] == ("basis", "mean", "coef", "out", "n", "values", "stride", "frames", "width")
    with pytest.raises(TypeError, match=r"kernel 'project' has no argument 'weights' \(it has basis, mean"):
        k.set(weights=np.int32(1))


PROGRAMS = [
    (
        ("pixels.cl", "gather.cl"),
        {
            "FRAME_W": 8,
            "FRAME_PIXELS": 64,
            "NFRAMES": 3,
            "GRID": 0,
            "WRAP": 0,
            "CELL_H": 1,
            "CELL_W": 1,
            "INTERP": 1,
            "TSTEP": 1,
            "RUN": 32,
            "STACK_PAD": 256,
            "STACK_SIGNED": 0,
            "TONE_STRIDE": 384,
            "TONE_OB": 192,
            **RGB,
        },
    ),
    (("pixels.cl", "projection.cl"), {"HALF": 0, "CHANNELS": 3, "DETAIL": 1, "VH": 9, "VW": 14, **RGB}),
    (("pixels.cl", "blend.cl"), {"FRAME_VECS": 4, "ITEMS": 4, "PIXELS": 21, **RGB}),
    (("pixels.cl", "blend.cl"), {"FRAME_VECS": 4, "ITEMS": 4, "PIXELS": 21, **BGRA}),
    (("pixels.cl", "runs.cl"), {"INTERP": 1, "GAIN": 0, "WIDTH": 24, **RGB}),
    (("pixels.cl", "runs.cl"), {"INTERP": 1, "GAIN": 1, "WIDTH": 24, **BGRA}),
    ("copy.cl", {}),
]


@pytest.mark.parametrize(
    "filename, defines", PROGRAMS, ids=[f"{f} {d.get('PIXEL_BYTES', '')}".strip() for f, d in PROGRAMS]
)
def test_argument_names_read_from_the_source_are_the_drivers(cl_context, filename, defines):
    """The names engine.Kernel binds by, read from the .cl text, are those the compiler reports."""
    from dynatex.player.opencl.programs import kernel_arg_names, kernel_source

    source = kernel_source(filename)
    options = [f"-D{k}={v}" for k, v in defines.items()] + ["-cl-kernel-arg-info"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cl.CompilerWarning)  # compiler chatter, as in opencl.Program
        prog = cl.Program(cl_context, source).build(options=options, cache_dir=False)
    names = kernel_arg_names(source)
    built = prog.get_info(cl.program_info.KERNEL_NAMES).split(";")  # a file may build some kernels per define
    assert names and set(built) <= set(names)
    for name in built:
        k = cl.Kernel(prog, name)
        assert names[name] == tuple(k.get_arg_info(i, cl.kernel_arg_info.NAME) for i in range(k.num_args)), name


@pytest.mark.parametrize("direct", [True, False])
def test_frames_reach_the_callers_array_directly_or_by_copy(cl_context, direct):
    """One kernel, both delivery paths, several arrays in turn (double buffering and more):
    each array gets exactly its own frame, left in flight until its event completes."""
    from dynatex.player.opencl.programs import writes_through

    if direct and not writes_through(cl_context):
        pytest.skip("this device does not share host memory")
    queue = cl.CommandQueue(cl_context)
    prog = build_program(cl_context, ("pixels.cl", "blend.cl"), {"FRAME_VECS": 4, "ITEMS": 1, "PIXELS": 16, **RGB})
    frames = np.arange(3 * 64, dtype=np.uint8).reshape(3, 64)  # frames of 48 bytes, 64 apart
    d_frames = cl.Buffer(cl_context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=frames)
    d_params = cl.Buffer(cl_context, cl.mem_flags.READ_ONLY, 32)
    k = Kernel(prog, "blend2")
    k.set(frames=d_frames, params=d_params)
    out = FrameOut(cl_context, queue, k, "out", 48, direct=direct)
    assert out.direct == direct
    arrays = [np.zeros(48, np.uint8) for _ in range(6)]
    for i, a in enumerate(arrays):
        params = np.array([i % 3, (i + 1) % 3, 0, 0, 256 - 40 * i, 40 * i, 0, 0], np.int32)
        cl.enqueue_copy(queue, d_params, params)
        event = out.launch(a, (3,), wait=False)
        event.wait()
        want = (
            frames[i % 3, :48].astype(int) * (256 - 40 * i) + frames[(i + 1) % 3, :48].astype(int) * 40 * i + 128
        ) >> 8
        assert np.array_equal(a, want.astype(np.uint8)), i
    assert out.launch(arrays[0], (3,)) is None  # wait=True: done on return


@pytest.mark.parametrize("mode, options", MODES, ids=[m for m, _ in MODES])
def test_every_mode_leaves_its_frame_in_flight_and_double_buffers(cl_device, mode, options):
    """start_frame returns before the frame is there (an event) on every mode, and two
    alternating buffers give the same frames as next_frame."""
    db = selftest._db_path()
    with (
        open_player(db, selftest.TEXTURE, mode=mode, device=cl_device, seed=5, **options) as a,
        open_player(db, selftest.TEXTURE, mode=mode, device=cl_device, seed=5, **options) as b,
    ):
        want = [a.next_frame() for _ in range(6)]
        bufs = [np.empty(b.shape, np.uint8) for _ in range(2)]
        pending = b.start_frame(bufs[0])
        in_flight = pending.event is not None
        got = []
        for i in range(1, 7):
            nxt = b.start_frame(bufs[i % 2]) if i < 6 else None
            got.append(pending.wait().copy())
            pending = nxt
    assert in_flight
    for k, (x, y) in enumerate(zip(want, got)):
        assert np.array_equal(x, y), (mode, k)


@pytest.mark.parametrize("mode, options", MODES, ids=[m for m, _ in MODES])
def test_every_mode_draws_through_one_engine_and_closing_releases_it(cl_device, mode, options):
    """Each mode's frames come from one engine of the backend it plays on, with the engine's
    bytes per frame; closing the player with a frame in flight finishes that frame and
    releases the engine's device buffers."""
    db = selftest._db_path()
    for backend, device in (("opencl", cl_device), ("numpy", None)):
        p = open_player(db, selftest.TEXTURE, mode=mode, backend=backend, device=device, seed=5, **options)
        engine = p.engine
        assert engine.backend == backend == p.backend
        assert p.bytes_per_frame == engine.bytes_per_frame > 0
        out = np.zeros(p.shape, np.uint8)
        pending = p.start_frame(out)
        p.close()
        assert p.engine is None and pending.done
        if backend == "opencl":
            assert not [k for k in vars(engine) if k.startswith("_d_")], "device buffers left after close"
        assert out.any()


@pytest.mark.parametrize("mode, options", MODES, ids=[m for m, _ in MODES])
def test_every_engine_is_an_engine_and_draws_the_frames_the_mode_does(cl_device, mode, options):
    """Each mode's engine, on either backend, has the one interface (:class:`Engine`), and its
    ``draw`` is what the mode's frames come from: a second engine opened by :func:`open_engine`
    the same way for every engine (OpenCL on a context, the reference on none) draws them too."""
    db = selftest._db_path()
    for backend, device in (("opencl", cl_device), ("numpy", None)):
        with open_player(db, selftest.TEXTURE, mode=mode, backend=backend, device=device, **options) as p:
            assert isinstance(p.engine, Engine) and p.engine.backend == backend
            assert type(p.engine).__module__.rsplit(".", 1)[-1] in ENGINES
    with pytest.raises(InvalidArgumentError, match="engine must be one of"):
        open_engine("quilt")


def test_open_engine_chooses_the_backend_by_the_context(cl_context):
    frames = np.random.default_rng(0).integers(0, 256, (3, 5, 7, 3), dtype=np.uint8)
    outs = []
    for ctx in (cl_context, None):
        e = open_engine("blend", frames, ctx=ctx, queue=ctx and cl.CommandQueue(ctx))
        assert e.backend == ("numpy" if ctx is None else "opencl")
        out = np.empty(e.shape, np.uint8)
        assert e.draw(out, ((0, 100), (2, 156))) is None  # wait=True: the frame is there
        outs.append(out)
        e.close()
    assert np.array_equal(*outs)


_BUILD_CHILD = """
import sys, numpy as np
from dynatex.player.engines.gather import open_gather, pack_source
g = open_gather(np.zeros((3, 64, 64, 3), np.uint8), (64, 128), device=sys.argv[1], cell=(16, 16), time_step=8)
g.set_source_grid(pack_source(np.zeros((4, 8), int)))
g.render(0.5)
print("built", g.wide)
"""


def test_kernel_builds_write_nothing_to_stderr(cl_device, tmp_path):
    """A compiler that prints warnings to the process's stderr (PoCL's clang on the x86
    variant) must not write into the host application's console: built in a child process
    with empty kernel caches, stderr stays empty."""
    import os
    import subprocess
    import sys

    env = dict(
        os.environ,
        POCL_CACHE_DIR=str(tmp_path / "pocl"),
        PYOPENCL_NO_CACHE="1",
        DYNATEX_CACHE_DIR=str(tmp_path / "dynatex"),
    )
    done = subprocess.run(
        [sys.executable, "-c", _BUILD_CHILD, cl_device], capture_output=True, text=True, timeout=240, env=env
    )
    assert done.returncode == 0, done.stderr[-500:]
    assert done.stdout.startswith("built")
    assert "warning" not in done.stderr.lower(), done.stderr[-500:]
