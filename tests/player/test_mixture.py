"""Mode ``mixture``: OpenCL against the numpy reference, determinism, state, controls, long-run stability."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.player import open_player
from dynatex.player.modes.mixture import MixturePlayer, nearest_distance, step_gram, step_sizes
from dynatex.tiledb import DatabaseWriter

from ..conftest import wave_clip


def _db(path, frames, **kw):
    clip = load_clip(frames)
    with DatabaseWriter(path) as w:
        w.put_texture("waves", clip.source_info())
        w.put_method("waves", "mixture", learn_mixture(clip, **kw))
    return path


@pytest.fixture(scope="module")
def mix_db(tmp_path_factory):
    return _db(
        tmp_path_factory.mktemp("mixp") / "m.h5",
        wave_clip(80, h=30, w=37),
        components=2,
        dim=4,
        pca_dim=16,
        neighbors=8,
        pmax=3,
    )


@pytest.mark.parametrize("precision", ["float32", "float16"])
def test_opencl_matches_numpy_reference(mix_db, precision, cl_device):
    with (
        MixturePlayer(mix_db, seed=5, precision=precision, backend="opencl", device=cl_device) as a,
        MixturePlayer(mix_db, seed=5, backend="numpy", precision=precision) as b,
    ):
        for _ in range(15):
            fa, fb = a.next_frame(), b.next_frame()
            diff = np.abs(fa.astype(int) - fb)
            # float32 sums in a different order: an occasional rounding step of 1.
            assert diff.max() <= 1 and (diff > 0).mean() < 0.01
        assert np.array_equal(a.global_coord, b.global_coord)


def test_grey_texture_and_output_buffer(tmp_path):
    path = _db(tmp_path / "g.h5", wave_clip(60, channels=1), components=2, dim=3, pca_dim=10, neighbors=6, pmax=2)
    with MixturePlayer(path, seed=1) as a, MixturePlayer(path, seed=1, backend="numpy") as b:
        out = np.empty(a.shape, np.uint8)
        assert a.next_frame(out=out) is out
        fb = b.next_frame()
        assert np.abs(out.astype(int) - fb).max() <= 1
        assert np.array_equal(out[..., 0], out[..., 2])


def test_seed_determinism_and_state_round_trip(mix_db):
    with (
        open_player(mix_db, mode="mixture", seed=3, backend="numpy") as p,
        MixturePlayer(mix_db, seed=3, backend="numpy") as q,
    ):
        a = [p.next_frame() for _ in range(5)]
        assert all(np.array_equal(x, q.next_frame()) for x in a)
        p.draws = 4
        state = p.get_state()
        ahead = [p.next_frame() for _ in range(5)]
        q.set_state(state)
        assert q.draws == 4 and q.frame_index == 5
        assert all(np.array_equal(x, q.next_frame()) for x in ahead)


def test_controls_are_validated(mix_db):
    with MixturePlayer(mix_db, backend="numpy") as p:
        with pytest.raises(ValueError, match=r"draws must be an integer in 1\.\.1024, not 0"):
            p.draws = 0
        with pytest.raises(TypeError, match="draws must be an integer"):
            p.draws = 2.5
        with pytest.raises(ValueError, match="intensity must be a finite number"):
            p.intensity = -1
        with pytest.raises(ValueError, match="g must be a finite vector"):
            p.render_coord(np.full(p.global_dim, np.nan))
        with pytest.raises(ValueError, match="state history must be finite"):
            p.set_state({**p.get_state(), "history": np.zeros((1, 1))})
    with pytest.raises(ValueError, match="precision must be one of"):
        MixturePlayer(mix_db, precision="int8")


def test_zero_intensity_follows_the_ar_prediction(mix_db):
    with MixturePlayer(mix_db, backend="numpy", seed=0) as p:
        p.intensity = 0.0
        h = p.get_state()["history"]
        p.advance(1)
        a = p._A
        want = p._w + sum(a[i] @ h[i] for i in range(p.order))
        assert np.allclose(p.global_coord, want)


def test_decoding_training_coordinates_reproduces_training_frames(mix_db):
    frames = wave_clip(80, h=30, w=37)
    with MixturePlayer(mix_db, backend="numpy") as p:
        src = frames.reshape(80, -1).astype(float)
        for t in (3, 40, 70):
            img = p.render_coord(p.train_coords[t]).reshape(-1).astype(float)
            err = np.sqrt(np.mean((img - src[t]) ** 2))
            other = np.sqrt(np.mean((src[(t + 20) % 80] - src[t]) ** 2))
            assert err < 0.5 * other


def test_long_run_stays_on_the_manifold(mix_db):
    with MixturePlayer(mix_db, backend="numpy", seed=2) as p:
        g = p.advance(3000, record=True)
        train = p.train_coords
        u = p.decoder.coefficients(g)
        u0 = p.decoder.coefficients(train)
        basis = p.engine._basis.astype(np.float64)
    assert np.isfinite(g).all()
    dist = nearest_distance(train, g)
    assert dist.max() < 0.5 * np.sqrt((train**2).sum(axis=1)).max()
    gram = basis @ basis.T
    energy = np.einsum("ni,ij,nj->n", u, gram, u).mean()
    energy0 = np.einsum("ni,ij,nj->n", u0, gram, u0).mean()
    assert 0.5 < energy / energy0 < 2.0


@pytest.mark.clips
def test_real_clip_long_run_beside_the_lds(clips_dir, tmp_path):
    clip = load_clip(clips_dir / "water_sea_waves_dyntex.avi", stop=150, size=(72, 88))
    m = learn_mixture(clip, components=3, dim=8)
    path = tmp_path / "w.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("w", clip.source_info())
        w.put_method("w", "mixture", m)
        w.put_method("w", "lds", learn_lds(clip, n=m.info["pca_dim"]))
    src = clip.frames.reshape(150, -1).astype(np.float64) - m.mean
    src_energy = (src**2).sum(axis=1).mean()
    with MixturePlayer(path, backend="numpy", seed=0) as p:
        g = p.advance(5000, record=True)
        u = p.decoder.coefficients(g)
        frames = [p.next_frame() for _ in range(3)]
    basis = m.stacked_basis.astype(np.float64)
    energy = np.einsum("ni,ij,nj->n", u, basis @ basis.T, u)
    assert 0.5 < energy.mean() / src_energy < 2.0 and energy.max() / src_energy < 4.0
    # Frames rendered for real carry the energy the coefficients say.
    fe = np.mean([((f.reshape(-1) - m.mean) ** 2).sum() for f in frames]) / src_energy
    assert 0.3 < fe < 3.0
    assert nearest_distance(m.global_coords, g).max() < 0.5 * np.sqrt(m.global_dim) * 3


@pytest.mark.clips
def test_real_clip_frames_step_like_the_clip(clips_dir, tmp_path):
    """Whole-frame jumps (a switch to a component that decodes a different image) are refused:
    the played frame steps keep the clip's own tail (the 64 px ocean jumped 2.5x past it)."""
    clip = load_clip(clips_dir / "small_64px" / "ocean_dyntex_64px.avi")
    path = tmp_path / "o.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("o", clip.source_info())
        w.put_method("o", "mixture", learn_mixture(clip))
    with MixturePlayer(path, backend="numpy", seed=0) as p:
        gram = step_gram(p.engine._basis)

        def steps(g):
            return np.sqrt(step_sizes(gram, np.diff(p.decoder.coefficients(g), axis=0)))

        train = np.quantile(steps(p.train_coords), 0.99)
        played = np.quantile(steps(p.advance(2000, record=True)), 0.99)
        p.draws = 1  # the plain AR process: no selection, still finite
        assert np.isfinite(p.advance(100, record=True)).all()
    assert played < 1.25 * train
