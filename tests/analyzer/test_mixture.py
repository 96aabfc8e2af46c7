"""Subspace-mixture learning: MPPCA, global coordination constraints, Schwarz's criterion, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.mixture import (
    coefficient_matrix,
    coordinate,
    fit_ar,
    fit_mppca,
    fit_residual,
    fit_switching,
    learn_mixture,
    lle_weights,
)
from dynatex.tiledb.mixture import companion_radius, scalar_ar_gain

from ..conftest import wave_clip


@pytest.fixture(scope="module")
def model():
    return learn_mixture(wave_clip(90, periods=(17.0, 11.0, 7.0)), components=3, dim=4, pca_dim=20, neighbors=8, pmax=4)


def test_model_shapes_and_invariants(model):
    t, s, d, dg = 90, 3, 4, 4
    assert model.stacked_basis.shape == (s * (d + 1), 24 * 32 * 3)
    assert model.responsibilities.shape == (t, s) and model.local_coords.shape == (t, s, d)
    assert np.allclose(model.responsibilities.sum(axis=1), 1)
    assert np.isclose(model.weights.sum(), 1) and (model.sigma2 > 0).all()
    for arr in (model.stacked_basis, model.coord_map, model.global_coords, model.ar_coefs):
        assert np.isfinite(arr).all()
    # Loadings are orthonormal within each component (they live in an orthonormal PCA space).
    rows = model.stacked_basis.reshape(s, d + 1, -1)[:, 1:].astype(np.float64)
    for k in range(s):
        assert np.allclose(rows[k] @ rows[k].T, np.eye(d), atol=1e-4)
    # Coordination constraints: centred, unit covariance.
    g = model.global_coords
    assert np.abs(g.mean(axis=0)).max() < 1e-8
    assert np.allclose(g.T @ g / t, np.eye(dg), atol=1e-6)
    assert companion_radius(model.ar_coefs) < 1
    assert 1 <= model.order <= 4 and model.sbc.shape == (4,)
    assert model.order == int(np.argmin(model.sbc)) + 1


def test_coordination_solves_the_constrained_generalized_eigenproblem():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(80, 6))
    p = fit_mppca(x, 2, 2, seed=0)
    u = coefficient_matrix(p["resp"], p["z"])
    idx, w = lle_weights(x, 6)
    assert np.allclose(w.sum(axis=1), 1) and not (idx == np.arange(80)[:, None]).any()
    lmap, ev = coordinate(u, idx, w, 3)
    g = u @ lmap
    assert np.abs(g.sum(axis=0)).max() < 1e-8
    assert np.allclose(g.T @ g / 80, np.eye(3), atol=1e-8)
    assert (np.diff(ev) >= -1e-12).all()
    # The cost trace(L^T A L) equals the sum of the eigenvalues and beats random feasible maps.
    resid = u - np.einsum("nk,nkj->nj", w, u[idx])
    cost = np.trace(lmap.T @ resid.T @ resid @ lmap)
    assert np.isclose(cost, ev.sum(), rtol=1e-6)
    for _ in range(5):
        m = rng.normal(size=lmap.shape)
        gm = u @ m
        gm -= gm.mean(axis=0)
        q = np.linalg.cholesky(gm.T @ gm / 80)
        m2 = np.linalg.lstsq(u, gm @ np.linalg.inv(q).T, rcond=None)[0]
        assert np.trace(m2.T @ resid.T @ resid @ m2) >= cost - 1e-9


def test_coordination_leaves_out_directions_the_coefficients_never_take():
    """Coefficients with exact linear dependencies (hard responsibilities, a component with few
    frames: the 64 px golden lines) once gave zero global axes and NaN coordinates."""
    rng = np.random.default_rng(2)
    x = rng.normal(size=(60, 6))
    p = fit_mppca(x, 2, 2, seed=0)
    u = coefficient_matrix(p["resp"], p["z"])
    u = np.concatenate([u, u[:, :2] - u[:, 2:4]], axis=1)  # two columns that add nothing
    idx, w = lle_weights(x, 6)
    lmap, _ = coordinate(u, idx, w, 4)
    g = u @ lmap
    assert np.isfinite(g).all() and np.allclose(g.T @ g / 60, np.eye(4), atol=1e-8)
    with pytest.raises(ValueError, match="span only 5 dimensions, fewer than global_dim=6"):
        coordinate(u, idx, w, 6)


def _stationary_cov(ar: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """Stationary covariance of ``x_t = sum_i ar[i] x_{t-1-i} + noise e_t`` (companion Lyapunov)."""
    p, d, _ = ar.shape
    comp = np.zeros((p * d, p * d))
    comp[:d] = np.concatenate(list(ar), axis=1)
    comp[d:, :-d] = np.eye((p - 1) * d)
    q = np.zeros((p * d, p * d))
    q[:d, :d] = noise @ noise.T
    cov = np.linalg.solve(np.eye((p * d) ** 2) - np.kron(comp, comp), q.ravel()).reshape(p * d, p * d)
    return cov[:d, :d]


def test_switching_dynamics_keep_each_components_covariance_and_the_clips_occupancy(model):
    dyn = model.switching
    s, d = model.components, model.dim
    assert dyn.transitions.shape == (s, s) and dyn.local_ar.shape == (s, 2, d, d)
    assert np.allclose(dyn.transitions.sum(axis=1), 1) and dyn.transitions.min() > 0
    for k in range(s):
        assert companion_radius(dyn.local_ar[k]) < 1
        assert np.allclose(_stationary_cov(dyn.local_ar[k], dyn.local_noise[k]), model.local_cov[k], atol=1e-8)
    # a clip that passes through its components once: the chain still spends the clip's share in each
    r = np.repeat(np.eye(3), [50, 30, 20], axis=0)
    z = np.random.default_rng(0).normal(size=(100, 3, 2))
    chain = fit_switching(r, z, np.zeros((3, 2)), np.tile(np.eye(2), (3, 1, 1))).transitions
    ev, vec = np.linalg.eig(chain.T)
    share = np.real(vec[:, np.argmax(np.real(ev))])
    assert np.allclose(share / share.sum(), [0.5, 0.3, 0.2], atol=0.02)
    stay = 1 / (1 - np.diag(chain))  # mean stay, frames: about the clip's (with a pseudo-count's doubt)
    assert (0.6 < stay / [50, 30, 20]).all() and (stay / [50, 30, 20] < 1.2).all()


def test_switching_recovers_a_smooth_ar2():
    """Order 2 holds how smooth the motion is, which a lag-1 correlation alone cannot."""
    rng = np.random.default_rng(3)
    y = np.zeros(4000)
    for t in range(2, 4000):
        y[t] = 1.6 * y[t - 1] - 0.8 * y[t - 2] + rng.standard_normal()
    r = np.ones((4000, 1))
    dyn = fit_switching(r, y[:, None, None], np.zeros((1, 1)), np.full((1, 1, 1), y.var()))
    assert np.allclose(dyn.local_ar[0, :, 0, 0], [1.6, -0.8], atol=0.05)
    assert np.isclose(dyn.local_noise[0, 0, 0] ** 2, 1.0, rtol=0.15)


def test_mppca_beats_a_single_subspace_on_a_union_of_subspaces():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(100, 2)) @ rng.normal(size=(2, 8)) + 5
    b = rng.normal(size=(100, 2)) @ rng.normal(size=(2, 8)) - 5
    x = np.concatenate([a, b]) + 0.01 * rng.normal(size=(200, 8))
    p = fit_mppca(x, 2, 2, seed=0)
    assert sorted(np.round(p["pi"], 2)) == [0.5, 0.5]
    hard = p["resp"].argmax(axis=1)
    assert len(set(hard[:100])) == 1 and len(set(hard[100:])) == 1 and hard[0] != hard[150]
    assert p["sigma2"].max() < 1e-3


def test_schwarz_criterion_recovers_ar2():
    rng = np.random.default_rng(3)
    a1 = np.array([[0.9, 0.2], [-0.1, 0.6]])
    a2 = np.array([[-0.5, 0.0], [0.1, -0.3]])
    g = np.zeros((3000, 2))
    for t in range(2, 3000):
        g[t] = a1 @ g[t - 1] + a2 @ g[t - 2] + rng.standard_normal(2)
    ar = fit_ar(g, 6)
    assert ar["p"] == 2
    assert np.abs(ar["A"][0] - a1).max() < 0.08 and np.abs(ar["A"][1] - a2).max() < 0.08
    assert np.allclose(ar["C"], np.eye(2), atol=0.1)
    assert ar["shrink"] == 1.0


def test_unstable_ar_is_pulled_inside_the_unit_circle():
    g = np.cumsum(np.random.default_rng(0).standard_normal((400, 2)), axis=0)  # random walk, pole ~1
    ar = fit_ar(g, 3, max_radius=0.9)
    assert ar["radius"] <= 0.9 + 1e-9 and ar["radius_raw"] > 0.9


def test_progress_is_reported():
    calls = []
    learn_mixture(
        wave_clip(40),
        components=2,
        dim=2,
        pca_dim=8,
        neighbors=5,
        pmax=2,
        progress=lambda done, total: calls.append((done, total)),
    )
    assert calls == [(i, 6) for i in range(1, 7)]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"components": 8, "dim": 6}, "needs more than components \\* \\(dim \\+ 1\\) = 56 frames, the clip has 40"),
        ({"components": 0}, r"components must be an integer in 1\.\."),
        ({"dim": 2.5}, "dim must be an integer"),
        ({"dim": 8, "pca_dim": 8}, "dim=8 must be smaller than pca_dim=8"),
        ({"neighbors": 40}, "neighbors=40 must be smaller"),
        ({"pmax": 12}, "pmax=12 is too large"),
        ({"max_radius": 1.0}, r"max_radius must be a finite number in \(0, 1\)"),
        ({"components": 2, "dim": 2, "global_dim": 6}, "global_dim=6 exceeds"),
    ],
)
def test_bad_parameters_give_clear_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        learn_mixture(wave_clip(40), **kwargs)


def test_constant_and_degenerate_clips_are_refused():
    const = np.full((40, 8, 8, 3), 77, np.uint8)
    with pytest.raises(ValueError, match="clip is constant"):
        learn_mixture(const, components=2, dim=2)
    two = np.where(np.arange(40)[:, None, None, None] % 2 == 0, 10, 200).astype(np.uint8) * np.ones(
        (1, 8, 8, 3), np.uint8
    )
    with pytest.raises(ValueError, match="rank"):
        learn_mixture(two, components=2, dim=2)
    with pytest.raises(ValueError, match="uint8"):
        learn_mixture(np.zeros((40, 8, 8, 3)), components=2, dim=2)


def test_a_component_without_data_is_an_error_not_a_nan_model():
    # Frames from two tight clusters cannot feed six components of dimension 3.
    rng = np.random.default_rng(0)
    base = rng.integers(0, 255, (2, 8, 8, 3))
    frames = (base[np.arange(40) % 2] + rng.integers(0, 3, (40, 8, 8, 3))).clip(0, 255).astype(np.uint8)
    with pytest.raises(ValueError, match="use fewer components"):
        learn_mixture(frames, components=6, dim=3, pca_dim=30, seed=0)


@pytest.mark.clips
@pytest.mark.parametrize("name", ["water_sea_waves_dyntex.avi", "flag_wind_dyntex_571c110.avi"])
def test_mixture_reconstructs_better_than_single_pca_of_same_dimension(clips_dir, name):
    clip = load_clip(clips_dir / name, stop=120, size=(72, 88))
    m = learn_mixture(clip, components=3, dim=8)
    assert m.info["recon_error"] < m.info["recon_error_pca_dim"]
    assert m.info["recon_error_hard"] < m.info["recon_error_pca_dim"]


def test_residual_process_keeps_the_residual_in_its_span_with_its_variance_and_pace():
    """Rows: two components' mean offsets and loadings in an 8-dimensional space; the residual has
    energy along a loading of the other component (free), along two directions no loading reaches
    (extra rows, within the budget) and along one more that the budget leaves out."""
    rng = np.random.default_rng(3)
    t, q = 4000, 8
    eye = np.eye(q)
    rows = np.stack([5 * eye[7], eye[0], eye[1], -4 * eye[7], eye[2], eye[3]])  # S=2, d=2
    y = np.zeros((t, 4))
    phi = np.array([[0.9, 0.0], [1.2, -0.5], [0.3, 0.0], [0.0, 0.0]])
    for i in range(2, t):
        y[i] = phi[:, 0] * y[i - 1] + phi[:, 1] * y[i - 2] + rng.standard_normal(4)
    res = y * [1.0, 1.0, 1.0, 0.5] @ np.stack([eye[1], eye[4], eye[5], eye[6]])
    proc, coords, info = fit_residual(res, rows, 2, row_share=2 / 6)
    assert info["residual_rows"] == 2 and info["residual_axes"] == 3 and coords.shape == (t, 3)
    assert proc.rows.shape == (2, q) and np.allclose((proc.rows[:, 4:6] ** 2).sum(axis=1), 1)  # they span e4, e5
    kept = (res[:, :6] ** 2).sum()  # all but the direction past the budget
    assert np.isclose(info["residual_process_energy"], kept, rtol=1e-3)
    # each axis's coefficients over the loadings and the extra rows rebuild the residual on their
    # span; the mean offsets take none
    span = np.concatenate([eye[:4], proc.rows])
    rebuilt = coords @ proc.gain @ np.concatenate([rows, proc.rows])
    assert np.allclose(rebuilt, res @ span.T @ span, atol=1e-9)
    assert np.all(proc.gain[:, [0, 3]] == 0) and np.abs(proc.gain).max() <= 10 + 1e-9
    # stationary variance is the axis's own; the AR(2) along the free loading is recovered
    for a in range(3):
        assert np.isclose(proc.noise[a] ** 2 * scalar_ar_gain(proc.ar[a]), coords[:, a].var(), rtol=0.05)
        assert companion_radius(proc.ar[a][:, None, None]) < 1
    for i in range(3):  # each axis found its source's process (AR(1) 0.9 on the free loading, AR(2), AR(1) 0.3)
        a = int(np.argmax([abs(np.corrcoef(coords[:, a], y[:, i])[0, 1]) for a in range(3)]))
        assert np.allclose(proc.ar[a], phi[i], atol=0.08), (i, proc.ar[a])


def test_residual_is_learned_where_the_detail_is_refused_or_when_asked(model, monkeypatch):
    """``auto``: a model with a detail part (this wave's residual is fine) has none; one whose detail
    is refused (a coarse residual) has it, as ``on`` always does; ``off`` never."""
    kw = dict(components=3, dim=4, pca_dim=20, neighbors=8, pmax=4)
    clip = wave_clip(90, periods=(17.0, 11.0, 7.0))
    assert model.detail is not None and model.residual is None and "residual_axes" not in model.info
    on = learn_mixture(clip, residual="on", **kw)
    assert on.residual is not None and on.info["residual_axes"] == on.residual.ar.shape[0]
    assert on.info["residual_rows"] == on.residual.rows.shape[0] <= 0.3 * len(on.stacked_basis)
    assert on.info["energy_model"] > 1 - on.info["recon_error"]
    assert np.array_equal(on.stacked_basis, model.stacked_basis) and on.detail is not None
    assert learn_mixture(clip, residual="off", **kw).residual is None
    monkeypatch.setattr("dynatex.analyzer.mixture.attach_detail", lambda *a, **k: None)  # as refused
    refused = learn_mixture(clip, **kw)
    assert refused.detail is None and refused.residual is not None
    assert np.array_equal(refused.residual.gain, on.residual.gain)
