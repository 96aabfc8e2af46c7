"""tiledb/FORMAT.md says what the writer writes: every dataset and attribute a real database
holds in each method group (and in ``source``) is in that section's tables, with the dtype
the table gives for datasets."""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import numpy as np
import pytest

import dynatex.tiledb as tiledb
from dynatex.player.opencl import selftest

FORMAT_MD = Path(tiledb.__file__).with_name("FORMAT.md")
DTYPES = {"int8", "uint8", "int32", "int64", "float16", "float32", "float64"}


def _sections() -> dict[str, dict[str, dict[str, str]]]:
    """Per section (``source``, ``lds``, ...): documented datasets (name -> dtype) and attributes."""
    text = FORMAT_MD.read_text(encoding="utf-8")
    out: dict[str, dict[str, dict[str, str]]] = {}
    for block in re.split(r"^## ", text, flags=re.M)[1:]:
        title = block.splitlines()[0]
        m = re.match(r"(?:Method group: |Required subgroup )?`(\w+)`", title)
        if not m:
            continue
        doc = out.setdefault(m.group(1), {"datasets": {}, "attributes": {}})
        kind = None
        for line in block.splitlines():
            if line.startswith("| dataset"):
                kind = "datasets"
            elif line.startswith("| attribute"):
                kind = "attributes"
            elif not line.startswith("|"):
                kind = None
            elif kind and not line.startswith("|--"):
                cells = [c.strip() for c in line.strip("|").split("|")]
                for name in re.findall(r"`(\w+)`", cells[0]):
                    doc[kind][name] = cells[1] if len(cells) > 1 else ""
    return out


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict[str, h5py.Group]:
    """Groups of real databases: every method of the shipped self-test database (written by
    tools/make_selftest_db.py through the writer) and a quilted tiles set."""
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.tiles import learn_tiles
    from dynatex.tiledb import DatabaseWriter

    rng = np.random.default_rng(0)
    clip = rng.integers(0, 256, (40, 48, 56, 3), dtype=np.uint8)
    path = tmp_path_factory.mktemp("fmt") / "q.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("noise", load_clip(clip).source_info())
        w.put_method("noise", "tiles", learn_tiles(clip, min_loop=16, period=(192, 192)))
    files = [h5py.File(selftest._db_path(), "r"), h5py.File(path, "r")]
    groups: dict[str, list] = {}
    for f in files:
        for texture in f["textures"].values():
            for name, obj in texture.items():
                groups.setdefault(name, []).append(obj)
            groups.setdefault("source", []).append(texture["source"])
    yield groups
    for f in files:
        f.close()


def test_the_document_has_every_section():
    sections = _sections()
    assert {"source", "lds", "turnpoints", "mixture", "quilt", "tiles"} <= set(sections)
    assert "basis" in sections["lds"]["datasets"] and "construction" in sections["tiles"]["attributes"]


@pytest.mark.parametrize("section", ["source", "lds", "turnpoints", "mixture", "quilt", "tiles"])
def test_what_the_writer_writes_is_documented(written, section):
    doc = _sections()[section]
    assert section in written, f"no database in the test writes {section!r}"
    for group in written[section]:
        undocumented_attrs = sorted(set(group.attrs) - set(doc["attributes"]))
        assert not undocumented_attrs, f"{section}: attributes not in FORMAT.md: {undocumented_attrs}"
        for name, obj in group.items():
            assert isinstance(obj, h5py.Dataset), f"{section}/{name} is not a dataset"
            assert name in doc["datasets"], f"{section}: dataset {name!r} is not in FORMAT.md"
            want = doc["datasets"][name].split()[0]
            if want in DTYPES:
                assert obj.dtype == np.dtype(want), f"{section}/{name}: FORMAT.md says {want}, written {obj.dtype}"
