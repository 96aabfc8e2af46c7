"""Players say what is wrong: a closed player, an OpenCL player across ``os.fork()``, several
threads on one player (serialised: every frame produced once), and controls that accept every
value of their declared range."""

from __future__ import annotations

import collections
import hashlib
import os
import threading

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.tiles import learn_tiles
from dynatex.checks import Range
from dynatex.errors import DynatexError
from dynatex.player import PlayerClosedError, open_player
from dynatex.player.modes.tiles import TilesPlayer
from dynatex.tiledb import DatabaseWriter

from ..conftest import wave_clip


@pytest.fixture(scope="module")
def tiles_db(tmp_path_factory):
    clip = load_clip(wave_clip(60, 40, 48))
    path = tmp_path_factory.mktemp("guards") / "tiles.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("waves", clip.source_info())
        w.put_method("waves", "tiles", learn_tiles(clip, tile=16, n_tiles=3, min_loop=20))
    return path


def _digest(frame: np.ndarray) -> str:
    return hashlib.sha1(frame.tobytes()).hexdigest()


@pytest.mark.parametrize("call", ["next_frame", "start_frame", "get_state"])
def test_a_closed_player_says_so(lds_db, call):
    p = open_player(lds_db, backend="numpy")
    p.close()
    p.close()  # closing twice is fine
    args = (np.empty(p.shape, np.uint8),) if call == "start_frame" else ()
    with pytest.raises(PlayerClosedError, match=r"close\(\)") as err:
        getattr(p, call)(*args)
    assert isinstance(err.value, DynatexError) and isinstance(err.value, RuntimeError)


def _in_forked_child(player) -> tuple[int, str]:
    """Run ``player.next_frame()`` in a forked child; its exit code and what it reported."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover (the child)
        os.close(read)
        try:
            player.next_frame()
            message, code = "frame", 0
        except Exception as exc:  # noqa: BLE001 - reported to the parent
            message, code = f"{type(exc).__name__}: {exc}", 3
        os.write(write, message.encode())
        os._exit(code)
    os.close(write)
    with os.fdopen(read) as f:
        message = f.read()
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), message


@pytest.mark.skipif(not hasattr(os, "fork"), reason="os.fork is POSIX")
def test_an_opencl_player_in_a_forked_child_raises_at_once(lds_db, cl_device):
    with open_player(lds_db, backend="opencl", device=cl_device) as p:
        p.next_frame()
        code, message = _in_forked_child(p)
        assert code == 3 and message.startswith("PlayerForkedError") and "os.fork()" in message
        p.next_frame()  # the parent's player goes on


@pytest.mark.skipif(not hasattr(os, "fork"), reason="os.fork is POSIX")
def test_a_numpy_player_goes_on_in_a_forked_child(lds_db):
    with open_player(lds_db, backend="numpy") as p:
        assert _in_forked_child(p) == (0, "frame")


def _threads_frames(player, threads: int, each: int) -> collections.Counter:
    got: collections.Counter = collections.Counter()
    lock = threading.Lock()

    def work() -> None:
        for _ in range(each):
            h = _digest(player.next_frame())
            with lock:
                got[h] += 1

    workers = [threading.Thread(target=work) for _ in range(threads)]
    for t in workers:
        t.start()
    for t in workers:
        t.join()
    return got


def _check_threads(db, mode: str, **kw) -> None:
    with open_player(db, mode=mode, seed=3, **kw) as ref:
        want = collections.Counter(_digest(ref.next_frame()) for _ in range(120))
    with open_player(db, mode=mode, seed=3, **kw) as p:
        got = _threads_frames(p, 4, 30)
        assert p.frame_index == 120
    assert got == want


@pytest.mark.parametrize("mode", ["lds", "tiles"])
def test_threads_sharing_a_numpy_player_each_get_distinct_frames(request, mode):
    _check_threads(request.getfixturevalue(f"{mode}_db"), mode, backend="numpy")


@pytest.mark.parametrize("mode", ["lds", "tiles"])
def test_threads_sharing_an_opencl_player_each_get_distinct_frames(request, mode, cl_device):
    _check_threads(request.getfixturevalue(f"{mode}_db"), mode, backend="opencl", device=cl_device)


def test_tiles_controls_accept_their_whole_declared_range(tiles_db):
    with TilesPlayer(tiles_db, backend="numpy", size=(40, 48)) as p:
        for name, control in p.controls().items():
            kind = control.param.kind
            if isinstance(kind, Range) and kind.kind is float and not (kind.low_open or kind.high_open):
                for value in (kind.low, kind.high):
                    setattr(p, name, value)
                    assert getattr(p, name) == value
                    p.next_frame()
        p.max_shift = 2 * p.loop_length  # beyond the loop: the offsets wrap around it
        p.next_frame()
