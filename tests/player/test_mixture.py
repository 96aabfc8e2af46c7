"""Mode ``mixture``: OpenCL against the numpy reference, determinism, state, controls, long-run
stability; with the switching dynamics (format 1.6) and as analysed before them."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.lds import learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.player import open_player
from dynatex.player.modes.mixture import MixturePlayer, nearest_distance, step_gram, step_sizes
from dynatex.tiledb import DatabaseWriter
from dynatex.tiledb.mixture import scalar_ar_gain

from ..conftest import wave_clip


def _db(path, frames, *, switching=True, **kw):
    """A database of ``frames``; ``switching=False`` writes it as before format 1.6 (no switching
    dynamics). The residual process is learned whether the detail is refused or not."""
    clip = load_clip(frames)
    model = learn_mixture(clip, residual="on", **kw)
    if not switching:
        model.switching = None
    with DatabaseWriter(path) as w:
        w.put_texture("waves", clip.source_info())
        w.put_method("waves", "mixture", model)
    return path


def _train_coefficients(m):
    z = m.local_coords
    return (np.concatenate([np.ones(z.shape[:2] + (1,)), z], axis=2) * m.responsibilities[:, :, None]).reshape(
        len(z), -1
    )


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


@pytest.fixture(scope="module")
def ar_db(tmp_path_factory):
    """The same texture as analysed before format 1.6: the AR process on the global coordinates."""
    return _db(
        tmp_path_factory.mktemp("mixa") / "a.h5",
        wave_clip(80, h=30, w=37),
        switching=False,
        components=2,
        dim=4,
        pca_dim=16,
        neighbors=8,
        pmax=3,
    )


@pytest.fixture(params=["switching", "ar"])
def any_db(request, mix_db, ar_db):
    return mix_db if request.param == "switching" else ar_db


@pytest.mark.parametrize("precision", ["float32", "float16"])
def test_opencl_matches_numpy_reference(any_db, precision, cl_device):
    with (
        MixturePlayer(any_db, seed=5, precision=precision, backend="opencl", device=cl_device) as a,
        MixturePlayer(any_db, seed=5, backend="numpy", precision=precision) as b,
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


def test_seed_determinism_and_state_round_trip(any_db):
    with (
        open_player(any_db, mode="mixture", seed=3, backend="numpy") as p,
        MixturePlayer(any_db, seed=3, backend="numpy") as q,
    ):
        a = [p.next_frame() for _ in range(5)]
        assert all(np.array_equal(x, q.next_frame()) for x in a)
        p.intensity = 0.5
        if p.switching is None:
            p.draws = 4
        state = p.get_state()
        ahead = [p.next_frame() for _ in range(5)]
        q.set_state(state)
        assert q.intensity == 0.5 and q.frame_index == 5
        assert q.switching is not None or q.draws == 4
        assert all(np.array_equal(x, q.next_frame()) for x in ahead)


def test_draws_is_offered_only_without_switching_dynamics(mix_db, ar_db):
    """``draws`` has no effect on the switching process: such a texture leaves it out of its controls and
    state and refuses it; the older model offers it."""
    assert "draws" in MixturePlayer.controls()
    with MixturePlayer(mix_db, backend="numpy") as p:
        assert "draws" not in p.controls() and "draws" not in p.get_state()
        with pytest.raises(ValueError, match="does not offer the control draws: it has no effect"):
            p.draws = 4
    with pytest.raises(ValueError, match="does not offer the control draws"):
        MixturePlayer(mix_db, backend="numpy", draws=4)
    with MixturePlayer(ar_db, backend="numpy", draws=4) as p:
        assert "draws" in p.controls() and p.get_state()["draws"] == 4


def test_controls_are_validated(mix_db, ar_db):
    with MixturePlayer(ar_db, backend="numpy") as p:
        with pytest.raises(ValueError, match=r"draws must be an integer in 1\.\.1024, not 0"):
            p.draws = 0
        with pytest.raises(TypeError, match="draws must be an integer"):
            p.draws = 2.5
    with MixturePlayer(mix_db, backend="numpy") as p:
        with pytest.raises(ValueError, match="intensity must be a finite number"):
            p.intensity = -1
        with pytest.raises(ValueError, match="g must be a finite vector"):
            p.render_coord(np.full(p.global_dim, np.nan))
        with pytest.raises(ValueError, match="state must have component in 0..1"):
            p.set_state({**p.get_state(), "local": np.zeros((1, 1))})
        with pytest.raises(ValueError, match="state of a switching mixture is missing"):
            p.set_state({k: v for k, v in p.get_state().items() if k != "fade_from"})
        with pytest.raises(ValueError, match="must be finite"):
            p.set_state({**p.get_state(), "local": np.full_like(p.get_state()["local"], np.inf)})
    with MixturePlayer(ar_db, backend="numpy") as p:
        with pytest.raises(ValueError, match="state history must be finite"):
            p.set_state({**p.get_state(), "history": np.zeros((1, 1))})
    with pytest.raises(ValueError, match="precision must be one of"):
        MixturePlayer(mix_db, precision="int8")


def test_zero_intensity_follows_each_components_prediction(mix_db):
    with MixturePlayer(mix_db, backend="numpy", seed=0) as p:
        p.intensity = 0.0
        h = p.get_state()["local"]
        p.advance(1)
        a = p.switching.local_ar
        want = np.einsum("spij,psj->si", a, h)
        assert np.allclose(p.get_state()["local"][0], want)
        assert not np.allclose(want, h[0])


def test_zero_intensity_follows_the_ar_prediction(ar_db):
    with MixturePlayer(ar_db, backend="numpy", seed=0) as p:
        p.intensity = 0.0
        h = p.get_state()["history"]
        p.advance(1)
        a = p.process.ar
        want = p.process.intercept + sum(a[i] @ h[i] for i in range(p.order))
        assert np.allclose(p.global_coord, want)


def test_decoding_training_coordinates_reproduces_training_frames(any_db):
    frames = wave_clip(80, h=30, w=37)
    with MixturePlayer(any_db, backend="numpy") as p:
        src = frames.reshape(80, -1).astype(float)
        for t in (3, 40, 70):
            img = p.render_coord(p.train_coords[t]).reshape(-1).astype(float)
            err = np.sqrt(np.mean((img - src[t]) ** 2))
            other = np.sqrt(np.mean((src[(t + 20) % 80] - src[t]) ** 2))
            assert err < 0.5 * other


def test_long_run_stays_on_the_manifold(ar_db):
    with MixturePlayer(ar_db, backend="numpy", seed=2) as p:
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


def test_switching_long_run_keeps_the_clips_occupancy_and_energy(mix_db):
    """The chain visits the components as the training frames do, each component's process
    keeps its covariance, so the long run's energy is the clip's; switches are cross-faded, whole
    (on this two-component wave a visit lasts about as long as a fade: a third of the frames fade,
    each step up to twice the typical one, so the mean step may reach 1.7 times the clip's)."""
    with MixturePlayer(mix_db, backend="numpy", seed=4) as p:
        m = p.texture.read("mixture")
        j = m.components * (m.dim + 1)
        u = p.advance(20000, record=True)
        gram = p.process.gram
    assert u.shape == (20000, j + m.residual.ar.shape[0]) and np.isfinite(u).all()
    u = u[:, :j]  # the components' coefficients (the residual's axes follow)
    r = u.reshape(len(u), m.components, -1)[:, :, 0]
    assert np.allclose(r.sum(axis=1), 1) and r.min() >= 0
    occupancy = np.bincount(r.argmax(axis=1), minlength=m.components) / len(r)
    assert np.abs(occupancy - m.responsibilities.mean(axis=0)).max() < 0.1
    ut = _train_coefficients(m)
    energy = np.einsum("ni,ij,nj->n", u, gram, u).mean() / np.einsum("ni,ij,nj->n", ut, gram, ut).mean()
    assert 0.8 < energy < 1.25
    steps = step_sizes(gram, np.diff(u, axis=0))
    assert 0.7 < steps.mean() / step_sizes(gram, np.diff(ut, axis=0)).mean() < 1.7
    # a switch's jump is spread over the frames of its cross-fade
    fading = r[1:].max(axis=1) < 1 - 1e-9
    assert 0.02 < fading.mean() < 0.5 and steps[fading].mean() < 2 * steps[~fading].mean()
    # the chain waits for a fade to end: each fade runs from one whole component to another
    pure = np.flatnonzero(r.max(axis=1) > 1 - 1e-9)
    for a, b in zip(pure[:-1], pure[1:]):
        if b - a > 1:
            ra, rb = r[a], r[b]
            assert not np.array_equal(ra, rb), (a, b)
            t = (r[a + 1 : b] - ra) @ (rb - ra) / ((rb - ra) @ (rb - ra))
            assert np.allclose(r[a + 1 : b], ra + t[:, None] * (rb - ra)), (a, b)


def test_residual_process_adds_the_residuals_energy_at_its_pace(mix_db, tmp_path):
    """Each residual axis keeps its stationary variance; the frames' coefficients are the components'
    plus the axes' through the part's gain, over the stacked rows and the extra ones; a database
    without the part (as written before it) plays the components alone."""
    with MixturePlayer(mix_db, backend="numpy", seed=6) as p:
        m = p.texture.read("mixture")
        res, j = m.residual, len(m.stacked_basis)
        assert p.engine._basis.shape[0] == j + len(res.rows)
        v = p.advance(20000, record=True)
        coef = np.empty(p.engine._basis.shape[0])
        p._coefficients(v[-1], coef)
        p.intensity = 0.0
        still = p.advance(50, record=True)[:, j:]
    y = v[:, j:]
    stationary = res.noise**2 * np.array([scalar_ar_gain(a) for a in res.ar])
    assert np.allclose(y.var(axis=0), stationary, rtol=0.1)
    assert np.allclose(coef, np.concatenate([v[-1, :j], np.zeros(len(res.rows))]) + v[-1, j:] @ res.gain)
    lag1 = (y[1:] * y[:-1]).mean(axis=0) / y.var(axis=0)
    assert np.allclose(lag1, res.ar[:, 0] / (1 - res.ar[:, 1]), atol=0.05)  # AR(2)'s lag-1 correlation
    assert np.abs(still[-1]).max() < 1e-3 * np.sqrt(stationary.max())  # intensity 0: the axes decay
    path = tmp_path / "no_residual.h5"
    path.write_bytes(mix_db.read_bytes())
    with h5py.File(path, "r+") as f:
        del f["textures/waves/mixture/residual"]
    with MixturePlayer(path, backend="numpy", seed=6) as p:
        assert p.residual is None and p.engine._basis.shape[0] == j
        assert p.advance(3, record=True).shape == (3, j) and "residual" not in p.get_state()


def test_residual_plays_the_same_frames_with_lookahead(mix_db):
    with (
        MixturePlayer(mix_db, backend="numpy", seed=8) as a,
        MixturePlayer(mix_db, backend="numpy", seed=8, lookahead=4) as b,
    ):
        for i in range(11):
            assert np.abs(a.next_frame().astype(int) - b.next_frame()).max() <= 1, i
        assert np.array_equal(a.get_state()["residual"], b.get_state()["residual"])


def test_residual_state_is_checked(mix_db):
    with MixturePlayer(mix_db, backend="numpy", seed=2) as p, MixturePlayer(mix_db, backend="numpy", seed=2) as q:
        p.advance(10)
        state = p.get_state()
        assert state["residual"].shape == (2, p.residual.dim)
        q.set_state({**state, "residual": state["residual"] * 0})
        assert np.array_equal(q.get_state()["residual"], state["residual"] * 0)
        for bad in (state["residual"][:1], state["residual"] * np.nan):
            with pytest.raises(ValueError, match=r"state residual must be finite with shape \(2, \d+\)"):
                q.set_state({**state, "residual": bad})
        with pytest.raises(ValueError, match="state of a switching mixture is missing or malformed") as e:
            q.set_state({**state, "residual": "much"})
        assert "\n" not in str(e.value)
        q.set_state({k: v for k, v in state.items() if k != "residual"})  # a state saved before the part
        assert not q.get_state()["residual"].any()


def test_residual_starts_from_its_stationary_distribution(mix_db):
    """The axes' first history is a draw of their stationary process (no warm-up from zero)."""
    with MixturePlayer(mix_db, backend="numpy", seed=3) as p:
        res = p.residual
        assert p.get_state()["residual"].any()
        draws = np.stack([p.residual.stationary(p._rng) for _ in range(4000)])  # (N, order, m)
    stationary = res.noise**2 * np.array([scalar_ar_gain(a) for a in res.ar])
    assert np.allclose(draws[:, 0].var(axis=0), stationary, rtol=0.1)
    lag1 = (draws[:, 0] * draws[:, 1]).mean(axis=0) / stationary
    assert np.allclose(lag1, res.ar[:, 0] / (1 - res.ar[:, 1]), atol=0.06)


def test_database_without_switching_dynamics_plays_the_global_ar(ar_db, mix_db):
    with MixturePlayer(ar_db, backend="numpy", seed=1) as a, MixturePlayer(mix_db, backend="numpy", seed=1) as b:
        assert a.switching is None and b.switching is not None
        assert a.advance(5, record=True).shape == (5, a.global_dim)
        assert b.advance(5, record=True).shape == (5, b.components * (b.dim + 1) + b.residual.dim)
        assert "history" in a.get_state() and "local" in b.get_state()
        assert a.global_coord.shape == b.global_coord.shape == (a.global_dim,)


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
        u = p.advance(5000, record=True)[:, : len(m.stacked_basis)]  # the components' coefficients
        frames = [p.next_frame() for _ in range(3)]
    basis = m.stacked_basis.astype(np.float64)
    energy = np.einsum("ni,ij,nj->n", u, basis @ basis.T, u)
    assert 0.5 < energy.mean() / src_energy < 2.0 and energy.max() / src_energy < 4.0
    # Frames rendered for real carry the energy the coefficients say.
    fe = np.mean([((f.reshape(-1) - m.mean) ** 2).sum() for f in frames]) / src_energy
    assert 0.3 < fe < 3.0


@pytest.mark.clips
def test_real_clip_frames_step_like_the_clip(clips_dir, tmp_path):
    """Whole-frame jumps (a switch to a component that decodes a different image) are refused:
    the played frame steps keep the clip's own tail (the 64 px ocean jumped 2.5x past it)."""
    clip = load_clip(clips_dir / "small_64px" / "ocean_dyntex_64px.avi")
    path = tmp_path / "o.h5"
    model = learn_mixture(clip)
    with DatabaseWriter(path) as w:
        w.put_texture("o", clip.source_info())
        w.put_method("o", "mixture", model)
    j = len(model.stacked_basis)
    with MixturePlayer(path, backend="numpy", seed=0) as p:
        gram = step_gram(p.engine._basis[:j])
        train = np.quantile(np.sqrt(step_sizes(gram, np.diff(_train_coefficients(model), axis=0))), 0.99)
        played = np.quantile(np.sqrt(step_sizes(gram, np.diff(p.advance(2000, record=True)[:, :j], axis=0))), 0.99)
    assert played < 1.25 * train
    model.switching = None  # as analysed before format 1.6
    with DatabaseWriter(path) as w:
        w.put_method("o", "mixture", model)
    with MixturePlayer(path, backend="numpy", seed=0) as p:
        gram = step_gram(p.engine._basis)

        def steps(g):
            return np.sqrt(step_sizes(gram, np.diff(p.decoder.coefficients(g), axis=0)))

        train = np.quantile(steps(p.train_coords), 0.99)
        played = np.quantile(steps(p.advance(2000, record=True)), 0.99)
        p.draws = 1  # the plain AR process: no selection, still finite
        assert np.isfinite(p.advance(100, record=True)).all()
    assert played < 1.25 * train
