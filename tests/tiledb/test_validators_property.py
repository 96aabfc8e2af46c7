"""Property: whatever value an attribute or a small dataset holds, opening and reading give a
valid model or a one-line TileDBFormatError naming the file and the object, nothing else."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from dynatex.tiledb import TileDBFormatError, open_db

from ..conftest import wave_clip

SOURCE_ATTRS = (
    "width",
    "height",
    "channels",
    "n_frames",
    "fps",
    "frame_start",
    "frame_step",
    "crop",
    "source_size",
    "color_order",
    "filename",
    "sha256",
)
LDS_ATTRS = ("n", "k")
LDS_DATASETS = ("A", "B", "x0", "mean", "stationary_cov", "singular_values")

scalars = st.one_of(
    st.integers(-(2**63), 2**63 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.binary(max_size=8),
    st.booleans(),
)
arrays = hnp.arrays(
    st.sampled_from([np.int64, np.int32, np.uint8, np.float64, np.float32, np.float16, np.bool_]),
    hnp.array_shapes(min_dims=0, max_dims=2, max_side=5),
)
values = st.one_of(scalars, arrays)


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds
    from dynatex.tiledb import DatabaseWriter

    clip = load_clip(wave_clip(t=20, h=8, w=8))
    path = tmp_path_factory.mktemp("prop") / "base.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("t", clip.source_info())
        w.put_method("t", "lds", learn_lds(clip, n=4))
    return path


def _outcome(path: Path) -> None:
    try:
        with open_db(path) as db:
            model = db.texture("t").read("lds")
    except TileDBFormatError as exc:
        text = str(exc)
        assert text.startswith(str(path)) and "\n" not in text
        return
    assert np.isfinite(model.A).all() and model.basis.shape[0] == model.n


def _mutant(base: Path, change) -> Path:
    folder = Path(tempfile.mkdtemp(prefix="dynatex-prop-"))
    path = folder / "m.h5"
    shutil.copyfile(base, path)
    try:
        with h5py.File(path, "a") as f:
            change(f)
    except (TypeError, ValueError, OverflowError):
        shutil.rmtree(folder)
        assume(False)  # h5py cannot store this value at all
    return path


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(obj=st.sampled_from(["source", "lds"]), data=st.data(), value=values)
def test_any_attribute_value_is_read_or_refused_in_one_line(base, obj, data, value):
    name = data.draw(st.sampled_from(SOURCE_ATTRS if obj == "source" else LDS_ATTRS))

    def change(f):
        f[f"textures/t/{obj}"].attrs[name] = value

    path = _mutant(base, change)
    try:
        _outcome(path)
    finally:
        shutil.rmtree(path.parent)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(LDS_DATASETS), value=arrays)
def test_any_small_lds_array_is_read_or_refused_in_one_line(base, name, value):
    def change(f):
        del f[f"textures/t/lds/{name}"]
        f[f"textures/t/lds/{name}"] = value

    path = _mutant(base, change)
    try:
        _outcome(path)
    finally:
        shutil.rmtree(path.parent)
