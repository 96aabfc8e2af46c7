"""The analyzer's sign convention holds under near ties, on every solver path."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer.lds import _fix_signs, learn_lds
from dynatex.analyzer.mixture import learn_mixture
from dynatex.analyzer.signs import canonical_signs, orient_rows, sign_weights
from dynatex.analyzer.stream import spill_clip
from dynatex.errors import InvalidArgumentError

from .subspace import assert_same_lds


def _tied_component(m: int = 4096, seed: int = 1) -> tuple[np.ndarray, int, int]:
    """A unit vector whose two largest entries tie in magnitude with opposite signs."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-0.5, 0.5, m)
    i, j = 17, m - 18
    u[i], u[j] = 2.0, -2.0
    return u / np.linalg.norm(u), i, j


@pytest.mark.parametrize("rel", [1e-6, 1e-9])
def test_near_tie_gives_the_same_component_either_way(rel):
    u, i, j = _tied_component()
    up, down = u.copy(), u.copy()
    up[i] *= 1 + rel  # entry i now wins by magnitude ...
    down[j] *= 1 + rel  # ... and here entry j does: a largest-entry rule flips between the two
    assert np.argmax(np.abs(up)) == i and np.argmax(np.abs(down)) == j
    states = np.ones((1, 5))
    for basis in (up, down, -up, -down):
        fixed, st = _fix_signs(basis[None].astype(np.float32), states)
        # One sign for all four inputs: the same component, and its states turned with it.
        np.testing.assert_allclose(fixed[0], up / np.linalg.norm(up) * canonical_signs(up[None])[0], atol=1e-6)
        assert np.sign(st[0, 0]) == np.sign(fixed[0, 0] * basis[0])


def test_signs_do_not_depend_on_the_solvers_sign_or_on_chunking():
    rng = np.random.default_rng(0)
    rows = rng.standard_normal((6, (1 << 20) + 77))  # two chunks of weights
    signs = canonical_signs(rows)
    np.testing.assert_array_equal(canonical_signs(-rows), -signs)
    turned = orient_rows(rows)
    np.testing.assert_array_equal(orient_rows(-rows), turned)
    w = np.concatenate([sign_weights(0, 1 << 20), sign_weights(1 << 20, rows.shape[1])])
    assert np.all(turned @ w > 0)


def test_sign_weights_have_no_mirror_symmetry():
    w = sign_weights(0, 10_000)
    assert abs(float(np.mean(w))) < 0.03 and 0.3 < float(np.std(w)) < 0.7
    # A mirrored image's components are (anti)symmetric; the weights must not be.
    assert abs(float(np.corrcoef(w, w[::-1])[0, 1])) < 0.05


def test_rows_must_be_two_dimensional():
    with pytest.raises(InvalidArgumentError, match="2-D"):
        canonical_signs(np.ones(3))


def _mirrored_clip(tau: int = 60, h: int = 12, w: int = 16, seed: int = 3) -> np.ndarray:
    """A clip symmetric under a left-right mirror: its components tie in magnitude pairwise."""
    rng = np.random.default_rng(seed)
    half = np.cumsum(rng.standard_normal((tau, h, w // 2, 1)), axis=0)
    frames = np.concatenate([half, half[:, :, ::-1]], axis=2)
    frames = 128 + 100 * frames / np.abs(frames).max()
    return np.clip(np.rint(frames), 0, 255).astype(np.uint8)


def test_solver_paths_agree_on_a_symmetric_clip(tmp_path):
    frames = np.repeat(_mirrored_clip(), 3, axis=3)
    gram = learn_lds(frames, n=5, svd="gram")
    randomized = learn_lds(frames, n=5, svd="randomized")
    path = tmp_path / "mirror.npy"
    np.save(path, frames)
    streamed = learn_lds(spill_clip(path), n=5)
    assert streamed.info["svd"] == "gram-streamed"
    # Streamed is the same Gram matrix summed in another order: same model, signs included.
    np.testing.assert_allclose(streamed.basis, gram.basis, atol=1e-4 * np.abs(gram.basis).max())
    assert_same_lds(streamed, gram, tol=1e-4)
    # The randomized solver approximates the weaker components; each still points the same way.
    assert np.all(np.sum(randomized.basis * gram.basis, axis=1) > 0.9)


def test_perturbed_clip_keeps_its_signs():
    frames = _mirrored_clip()
    nudged = frames.copy()
    nudged[0, 0, 0, 0] ^= 1  # one pixel, one grey level: inputs that differ in their last bits
    a, b = learn_lds(frames, n=5), learn_lds(nudged, n=5)
    assert np.all(np.sign(np.sum(a.basis * b.basis, axis=1)) > 0)


def test_mixture_axes_have_canonical_signs():
    frames = np.repeat(_mirrored_clip(tau=80), 3, axis=3)
    nudged = frames.copy()
    nudged[0, 0, 0, 0] ^= 1
    kw = {"components": 2, "dim": 2, "pca_dim": 6, "neighbors": 6, "pmax": 2}
    a, b = learn_mixture(frames, **kw), learn_mixture(nudged, **kw)
    np.testing.assert_array_equal(canonical_signs(a.global_coords.T), 1.0)
    # The nudged clip's global axes point the same way, not only span the same line.
    assert np.all(np.sum(a.global_coords * b.global_coords, axis=0) > 0)
