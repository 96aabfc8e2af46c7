"""Every method's model describes itself: ``describe()`` gives plain facts (what ``dynatex info``
prints), ``summary()`` one line (what ``dynatex analyze`` prints)."""

from __future__ import annotations

import json

import pytest

from dynatex.commands.info import describe
from dynatex.tiledb import open_db
from dynatex.tiledb.schema import METHODS

from . import fuzzing


@pytest.fixture(scope="module")
def bases(tmp_path_factory):
    return fuzzing.build_bases(tmp_path_factory.mktemp("describe-bases"))


def _assert_plain(value, where="describe()"):
    if isinstance(value, dict):
        for k, v in value.items():
            assert isinstance(k, str), where
            _assert_plain(v, f"{where}[{k!r}]")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _assert_plain(v, f"{where}[{i}]")
    else:
        assert value is None or type(value) in (bool, int, float, str), f"{where} is {type(value).__name__}"


@pytest.mark.parametrize("method", METHODS)
def test_describe_is_plain_and_json_and_summary_is_one_line(bases, method):
    with open_db(bases[method]) as db:
        model = db.texture(fuzzing.TEXTURE).read(method)
    facts = model.describe()
    assert facts
    _assert_plain(facts)
    assert json.loads(json.dumps(facts)) == facts
    line = model.summary()
    assert line.strip() == line and "\n" not in line and 20 < len(line) < 300, line
    # dynatex info prints the model's own description
    assert describe(str(bases[method]))["textures"][fuzzing.TEXTURE]["methods"][method] == facts


def test_described_facts_follow_the_model(bases):
    with open_db(bases["lds"]) as db:
        lds = db.texture(fuzzing.TEXTURE).read("lds")
    facts = lds.describe()
    assert (facts["n"], facts["k"]) == (lds.n, lds.k) == (6, 6)
    assert lds.summary().startswith("n=6 k=6, energy ")
    with open_db(bases["tiles"]) as db:
        tiles = db.texture(fuzzing.TEXTURE).read("tiles")
    facts = tiles.describe()
    assert facts["construction"] == "quilted" and facts["n_tiles"] == tiles.n_tiles
    assert facts["tiles_per_class"] == [tiles.n_tiles] and facts["border_tiles"] == 0
    assert tiles.summary().startswith(f"quilted torus {facts['period_w']}x{facts['period_h']} of {tiles.n_tiles} cells")
