"""Mode ``turnpoints``: OpenCL against the numpy reference, the walk's rules, state, controls,
and the must-show long runs on real clips (no dead end, coverage, frame difference at events)."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.metrics import double_image, double_image_level, index_coverage, temporal_discontinuity
from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip
from dynatex.player import open_player
from dynatex.player.modes.turnpoints import EVENT_JUMP, EVENT_TURN, PLAYBACKS, TurnPointPlayer
from dynatex.tiledb import DatabaseWriter, MethodNotFoundError


def make_db(path, frames, **kwargs):
    clip = load_clip(frames)
    model = learn_turnpoints(clip, **kwargs)
    with DatabaseWriter(path) as w:
        w.put_texture("t", clip.source_info())
        w.put_frames("t", clip.frames)
        w.put_method("t", "turnpoints", model)
    return path, model, clip


@pytest.fixture(scope="module")
def pend_db(tmp_path_factory):
    return make_db(tmp_path_factory.mktemp("tp") / "pend.h5", pendulum_clip(90, 40)[0])


@pytest.mark.parametrize("playback", PLAYBACKS)
def test_opencl_matches_numpy_exactly(pend_db, cl_device, playback):
    path = pend_db[0]
    with (
        TurnPointPlayer(path, backend="numpy", playback=playback, seed=5) as ref,
        TurnPointPlayer(path, backend="opencl", device=cl_device, playback=playback, seed=5) as cl,
    ):
        blended, terms = 0, set()
        for k in range(160):
            if k % 40 == 0:
                ref.speed = cl.speed = [1.0, 0.37, 2.5, 1.6][k // 40]
                ref.crossfade = cl.crossfade = [4, 2, 8, 0][k // 40]
            a, b = ref.next_frame(), cl.next_frame()
            assert np.array_equal(a, b), k
            assert ref.last_sources == cl.last_sources
            blended += len(ref.last_sources) > 1
            terms.add(len(ref.last_sources))
        assert blended > 20  # the blend kernels were exercised, not only copies
        if playback != "turns":
            assert max(terms) > 2  # a crossfade at a fractional speed: the four-term kernel


def test_blend_arithmetic(pend_db):
    """Weights are integers summing to 256; a blend is (sum w f + 128) >> 8 per byte."""
    path, _, clip = pend_db
    with TurnPointPlayer(path, backend="numpy", seed=0) as p:
        p.speed = 0.25
        for _ in range(3):
            frame = p.next_frame()
        src = p.last_sources
        assert sum(w for _, w in src) == 256 and len(src) == 2
        acc = sum(clip.frames[f].astype(np.int32) * w for f, w in src) + 128
        assert np.array_equal(frame, (acc >> 8).astype(np.uint8))


def test_deterministic_per_seed(pend_db):
    path = pend_db[0]
    runs = []
    for seed in (3, 3, 4):
        with TurnPointPlayer(path, backend="numpy", seed=seed) as p:
            runs.append(p.advance(2000)[0])
    assert np.array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])


def test_state_round_trip(pend_db):
    path = pend_db[0]
    with TurnPointPlayer(path, backend="numpy", seed=9) as p:
        p.speed = 1.3
        p.advance(333)
        state = p.get_state()
        expect = [p.next_frame() for _ in range(50)]
        with TurnPointPlayer(path, backend="numpy", seed=0) as q:
            q.set_state(state)
            got = [q.next_frame() for _ in range(50)]
    assert all(np.array_equal(a, b) for a, b in zip(expect, got))
    with TurnPointPlayer(path, backend="numpy", playback="turns") as q:
        with pytest.raises(ValueError, match="playback"):
            q.set_state(state)


def test_turns_only_walk_follows_the_seed(pend_db):
    path, model, _ = pend_db
    with TurnPointPlayer(path, backend="numpy", playback="turns", seed=1) as p:
        p_max = model.p_max
        start = p.probabilities
        inner = model.turn_points[1:-1]
        assert np.allclose(start[inner], p_max[inner] / 2)  # eq. 6
        assert start[model.first_turn] == start[model.last_turn] == 1.0
        idx, ev = p.advance(5000)
        assert np.all(np.abs(np.diff(idx)) == 1)  # only steps and reversals
        turned_at = idx[np.flatnonzero(ev == EVENT_TURN) - 1]
        assert set(turned_at.tolist()) <= set(model.turn_points.tolist())
        assert idx.min() >= 0 and idx[100:].max() <= model.last_turn  # never beyond the last turn
        assert idx[100:].min() >= model.first_turn
        probs = p.probabilities
        assert np.all(probs <= p_max + 1e-12) and np.all(probs >= 0)  # eq. 7 bounds
        # every inner turn point both turned and was passed: the adaptive rule spreads the turns
        for tp in inner:
            visits = np.flatnonzero(idx[:-1] == tp)
            turns = ev[visits + 1] == EVENT_TURN
            assert turns.any() and (~turns).any(), tp


def test_jumps_only_is_forward_along_kept_transitions(pend_db):
    path, model, _ = pend_db
    allowed = set(zip(model.src.tolist(), model.dst.tolist()))
    with TurnPointPlayer(path, backend="numpy", playback="jumps", seed=2) as p:
        p.crossfade = 0
        idx, ev = p.advance(5000)
        assert p.dead_ends == 0
    steps = np.diff(idx)
    jumps = np.flatnonzero(steps != 1)
    assert jumps.size > 50
    assert np.all(ev[jumps + 1] == EVENT_JUMP)
    assert all((int(idx[k]), int(idx[k + 1])) in allowed for k in jumps)
    assert idx.max() <= model.exit_frame


@pytest.mark.parametrize("playback", PLAYBACKS)
def test_ten_thousand_frames_no_dead_end(pend_db, playback):
    path, model, _ = pend_db
    with TurnPointPlayer(path, backend="numpy", playback=playback, seed=11) as p:
        idx, _ = p.advance(10000)
        assert p.dead_ends == 0
    assert idx.min() >= 0 and idx.max() < model.n_frames
    if playback == "hybrid":
        assert index_coverage(idx, model.n_frames) >= 0.9


def test_speed_zero_freezes_and_speed_four_skips(pend_db):
    path = pend_db[0]
    with TurnPointPlayer(path, backend="numpy", playback="turns", seed=1) as p:
        p.advance(10)
        p.speed = 0.0
        a, b = p.next_frame(), p.next_frame()
        assert np.array_equal(a, b)
        p.speed = 4.0
        idx, _ = p.advance(200)
        assert np.all(np.abs(np.diff(idx)) <= 4) and np.mean(np.abs(np.diff(idx))) > 2


def test_controls_are_validated(pend_db):
    with TurnPointPlayer(pend_db[0], backend="numpy") as p:
        with pytest.raises(ValueError, match="speed"):
            p.speed = 4.5
        with pytest.raises(ValueError, match="speed"):
            p.speed = -1
        with pytest.raises(ValueError, match="crossfade"):
            p.crossfade = 17
        with pytest.raises(TypeError, match="crossfade"):
            p.crossfade = 1.5
        with pytest.raises(ValueError, match="increment"):
            p.increment = 2
    with pytest.raises(ValueError, match="playback"):
        TurnPointPlayer(pend_db[0], backend="numpy", playback="random")
    with pytest.raises(ValueError, match="start"):
        TurnPointPlayer(pend_db[0], backend="numpy", start=89)


def test_missing_tables_or_frames(tmp_path, pend_db):
    clip = pend_db[2]
    bare = tmp_path / "bare.h5"
    with DatabaseWriter(bare) as w:
        w.put_texture("t", clip.source_info())
        w.put_method("t", "turnpoints", pend_db[1])  # tables without stored frames
    with pytest.raises(MethodNotFoundError, match="stores no frames"):
        TurnPointPlayer(bare, backend="numpy")
    lone = tmp_path / "lone.h5"
    with DatabaseWriter(lone) as w:
        w.put_texture("t", clip.source_info())
    with pytest.raises(MethodNotFoundError, match="no 'turnpoints' data"):
        open_player(lone, mode="turnpoints", backend="numpy")


def test_memory_cost_is_reported(pend_db, cl_context):
    with TurnPointPlayer(pend_db[0]) as p:
        flows = 0 if p.model.flow is None else p.model.flow.flows.nbytes  # the warp's flows, where stored
        assert p.memory_bytes == 90 * ((40 * 40 * 3 + 63) // 64) * 64 + flows


def _long_run(path, clip, playback="hybrid", frames=10000, seed=1):
    """Play ``frames`` frames; return source indices, events and the frame-difference ratios at events."""
    with TurnPointPlayer(path, backend="numpy", playback=playback, seed=seed) as p:
        prev = p.next_frame()
        cur = np.empty_like(prev)
        idx, pairs = [p.source_index], []
        for _ in range(frames - 1):
            p.next_frame(cur)
            idx.append(p.source_index)
            if p.last_event:
                pairs.append(np.stack([prev, cur]))
            prev, cur = cur, prev
        dead = p.dead_ends
    ratios = []
    for b in range(0, len(pairs), 256):
        batch = np.concatenate(pairs[b : b + 256])
        ratios.append(temporal_discontinuity(batch, list(range(1, len(batch), 2)), source=clip.frames))
    return np.array(idx), np.concatenate(ratios), dead


@pytest.mark.clips
@pytest.mark.parametrize("name", ["pendulum_clock_schoedl.mov", "small_64px/fire_dyntex_64px.avi"])
def test_real_clip_must_show(tmp_path, clips_dir, name):
    clip = load_clip(clips_dir / name)
    path, model, _ = make_db(tmp_path / "real.h5", clip.frames)
    idx, ratios, dead = _long_run(path, clip)
    assert dead == 0  # 10,000 frames, no dead end
    assert index_coverage(idx, clip.n_frames) >= 0.9  # >= 90% of the source frames used
    assert ratios.size > 100  # reversals and jumps happened
    assert ratios.mean() <= 1.5, ratios.mean()  # events look like ordinary steps


@pytest.mark.clips
def test_real_pendulum_jumps_show_no_double_images(tmp_path, clips_dir):
    """Every output frame, crossfades at jumps included, within the clip's own level of double
    images (that of the mean of two consecutive frames)."""
    clip = load_clip(clips_dir / "pendulum_clock_schoedl.mov")
    path, _, _ = make_db(tmp_path / "clock.h5", clip.frames)
    with TurnPointPlayer(path, backend="numpy", seed=0) as p:
        frames, events = [], []
        for _ in range(400):
            frames.append(p.next_frame())
            events.append(p.last_event)
    assert np.count_nonzero(np.array(events) & EVENT_JUMP) >= 5  # jumps were taken
    assert double_image(np.stack(frames), clip.frames).max() <= double_image_level(clip.frames)
