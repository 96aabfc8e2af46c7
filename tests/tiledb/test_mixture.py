"""The ``mixture`` group: round trip, and damaged or hostile values refused with a clear error."""

from __future__ import annotations

import numpy as np
import pytest

from dynatex.analyzer import load_clip
from dynatex.analyzer.mixture import learn_mixture
from dynatex.tiledb import DatabaseWriter, TileDB, TileDBFormatError
from dynatex.tiledb.mixture import scalar_ar_autocov, scalar_ar_gain

from ..conftest import wave_clip
from .conftest import edited_copy, replace_dataset


@pytest.fixture(scope="module")
def db_path(tmp_path_factory):
    clip = load_clip(wave_clip(60))
    path = tmp_path_factory.mktemp("mix") / "mix.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("waves", clip.source_info())
        w.put_method(
            "waves", "mixture", learn_mixture(clip, components=2, dim=3, pca_dim=12, neighbors=6, pmax=3, residual="on")
        )
    return path


def test_round_trip(db_path):
    model = learn_mixture(load_clip(wave_clip(60)), components=2, dim=3, pca_dim=12, neighbors=6, pmax=3, residual="on")
    with TileDB(db_path) as db:
        tex = db.texture("waves")
        assert "mixture" in tex.methods
        back = tex.read("mixture")
    for name in (
        "stacked_basis",
        "coord_map",
        "global_coords",
        "ar_coefs",
        "ar_noise_cov",
        "decode_gain",
        "local_cov",
        "local_radius",
        "sbc",
    ):
        assert np.array_equal(getattr(back, name), getattr(model, name).astype(getattr(back, name).dtype)), name
    assert (back.components, back.dim, back.global_dim, back.order) == (2, 3, 3, model.order)
    assert back.info["recon_error"] == model.info["recon_error"]
    for name in ("transitions", "local_ar", "local_noise"):
        assert np.array_equal(getattr(back.switching, name), getattr(model.switching, name)), name
    assert back.residual is not None
    for name in ("rows", "gain", "ar", "noise"):
        assert np.array_equal(getattr(back.residual, name), getattr(model.residual, name)), name
    m, k = back.residual.ar.shape[0], len(back.residual.rows)
    assert back.describe()["residual"] == f"{m} axes, AR({back.residual.ar.shape[1]}) each, {k} extra rows"
    assert f"played by {m} axes" in back.summary()


def test_residual_part_is_optional_and_versioned(db_path, tmp_path):
    """A database written without ``residual`` reads with none; a newer part is ignored; no extra rows is fine."""
    for edit in (lambda g: g.__delitem__("residual"), lambda g: g["residual"].attrs.__setitem__("version", 2)):
        with TileDB(_damaged(db_path, tmp_path, edit)) as db:
            model = db.texture("waves").read("mixture")
        assert model.residual is None and model.switching is not None
        assert "residual" not in model.describe() and "axes" not in model.summary()

    def no_rows(g):
        res = g["residual"]
        k = res["rows"].shape[0]
        gain = res["gain"][()][:, : res["gain"].shape[1] - k]
        for name, data in (("rows", res["rows"][()][:0]), ("gain", gain)):
            del res[name]
            res.create_dataset(name, data=data)

    with TileDB(_damaged(db_path, tmp_path, no_rows)) as db:
        model = db.texture("waves").read("mixture")
    assert model.residual.rows.shape == (0, model.stacked_basis.shape[1])


def test_switching_part_is_optional_and_versioned(db_path, tmp_path):
    """A database written before format 1.6 (no ``switching``) reads with none; a newer part is ignored."""
    for edit in (lambda g: g.__delitem__("switching"), lambda g: g["switching"].attrs.__setitem__("version", 2)):
        path = _damaged(db_path, tmp_path, edit)
        with TileDB(path) as db:
            model = db.texture("waves").read("mixture")
        assert model.switching is None and model.ar_coefs.shape[1:] == (3, 3)


def _damaged(src, tmp_path, edit):
    return edited_copy(src, tmp_path, "textures/waves/mixture", edit)


@pytest.mark.parametrize(
    "edit, match",
    [
        (replace_dataset("ar_coefs", lambda a: a * 50), r"/ar_coefs: the AR process is not stable"),
        (
            replace_dataset("global_coords", lambda a: np.where(np.arange(a.size).reshape(a.shape) == 3, np.nan, a)),
            r"/global_coords: contains NaN",
        ),
        (replace_dataset("weights", lambda a: a * 2), r"/weights: mixing proportions"),
        (
            replace_dataset("gauss_cov", lambda a: -a),
            r"/gauss_cov: covariance of component 0 is not symmetric positive definite",
        ),
        (replace_dataset("local_cov", lambda a: a[:, :2, :2]), r"/local_cov: has shape"),
        (replace_dataset("stacked_basis", lambda a: a[:-1]), r"/stacked_basis: has shape"),
        (replace_dataset("responsibilities", lambda a: a * 3), r"/responsibilities: rows must be probabilities"),
        (replace_dataset("local_radius", lambda a: -a), r"/local_radius: radii must be > 0"),
        (lambda g: g.attrs.__setitem__("components", 1000), r"@components: 1000 out of range"),
        (lambda g: g.attrs.__setitem__("global_dim", 50), r"@global_dim: 50 exceeds"),
        (
            replace_dataset("switching/transitions", lambda a: a + 0.5),
            r"/switching/transitions: rows must be probabilities",
        ),
        (
            replace_dataset("switching/local_ar", lambda a: a * 0 + np.eye(a.shape[-1])),
            r"/switching/local_ar: component 0's",
        ),
        (
            replace_dataset("switching/local_noise", lambda a: a * 10),
            r"/switching/local_noise: the driving noise's variance",
        ),
        (replace_dataset("switching/local_ar", lambda a: a[:, :, :2]), r"/switching/local_ar: has shape"),
        (
            replace_dataset("residual/ar", lambda a: a * 0 + [2.0, -0.1]),
            r"/residual/ar: axis 0's process is not stable",
        ),
        (replace_dataset("residual/ar", lambda a: a[:-1]), r"/residual/ar: gain, ar and noise must have one row"),
        (replace_dataset("residual/noise", lambda a: -a), r"/residual/noise: standard deviations must be >= 0"),
        (replace_dataset("residual/noise", lambda a: a * 1e9), r"/residual/noise: an axis reaches"),
        (replace_dataset("residual/noise", lambda a: a * np.nan), r"/residual/noise: contains NaN"),
        (replace_dataset("residual/rows", lambda a: a * 3), r"/residual/rows: a row has norm"),
        (replace_dataset("residual/gain", lambda a: a[:, :-1]), r"/residual/gain: has shape"),
        (replace_dataset("residual/rows", lambda a: a.astype(np.float16)), r"/residual/rows: .*float16"),
    ],
)
def test_damaged_groups_are_refused(db_path, tmp_path, edit, match):
    bad = _damaged(db_path, tmp_path, edit)
    with TileDB(bad) as db:
        with pytest.raises(TileDBFormatError, match=match) as info:
            db.texture("waves").read("mixture")
    assert str(bad) in str(info.value) and "\n" not in str(info.value)


def test_scalar_ar_gain_is_the_stationary_variance():
    """The Yule-Walker solve against the Kronecker (Lyapunov) form for low orders and the impulse
    response's energy for a long one (an order a damaged file may state: side p + 1, not p^2)."""
    rng = np.random.default_rng(4)
    for p in range(1, 7):
        phi = -np.poly(rng.uniform(-0.9, 0.9, p))[1:]
        comp = np.zeros((p, p))
        comp[0], comp[1:, :-1] = phi, np.eye(p - 1)
        e0 = np.zeros(p * p)
        e0[0] = 1.0
        kron = np.linalg.solve(np.eye(p * p) - np.kron(comp, comp), e0)[0]
        assert np.isclose(scalar_ar_gain(phi), kron, rtol=1e-9)
    phi = np.zeros(64)
    phi[0], phi[63] = 0.5, 0.2
    h = np.zeros(4000)
    h[0] = 1.0
    for k in range(1, len(h)):
        h[k] = phi[: min(64, k)] @ h[k - 1 :: -1][: min(64, k)]
    assert np.isclose(scalar_ar_gain(phi), float(h @ h), rtol=1e-6)
    assert np.allclose(scalar_ar_autocov(np.array([0.5]), 3), np.array([4, 2, 1, 0.5]) / 3)
