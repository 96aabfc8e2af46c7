"""The quilted tiles construction: one large seamless torus quilted from the looped clip, cut
into cells that the player lays out in the torus's order (issue 17: no visible lattice)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from dynatex.analyzer import load_clip, metrics
from dynatex.analyzer.tiles import learn_tiles, quilt_geometry
from dynatex.player.modes.tiles import TilesPlayer
from dynatex.tiledb import DatabaseWriter, TileDB, TileDBFormatError

from ..analyzer.test_tiles import _stochastic

PERIOD = (216, 288)


@pytest.fixture(scope="module")
def quilted(tmp_path_factory):
    clip = _stochastic(t=60, h=56, w=72)
    model = learn_tiles(clip, tile=24, min_loop=24, period=PERIOD)
    path = tmp_path_factory.mktemp("quilted") / "q.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("noise", load_clip(clip).source_info())
        w.put_method("noise", "tiles", model)
    return clip, model, path


def _torus(model) -> np.ndarray:
    rows, cols = model.torus
    _, length, ch, cw, _ = model.tiles.shape
    return (
        model.tiles.reshape(rows, cols, length, ch, cw, 3)
        .transpose(2, 0, 3, 1, 4, 5)
        .reshape(length, rows * ch, cols * cw, 3)
    )


def test_geometry_cells_cover_whole_steps_and_the_period():
    block, step, (ch, cw), (py, px) = quilt_geometry(288, 352, scale=5.0)  # grass-like grain
    assert (block, step) == (96, 72) and ch % step == 0 and ch >= 64
    assert py % ch == 0 and px % cw == 0 and py >= 576 and px >= 704
    assert quilt_geometry(288, 352, period=(1000, 1000), scale=5.0)[3] == (1008, 1008)
    with pytest.raises(ValueError, match="larger than the clip frame"):
        quilt_geometry(40, 48, block=64)
    with pytest.raises(ValueError, match="period must be"):
        quilt_geometry(288, 352, period=(100, 2000))


def test_the_torus_is_seamless_across_its_own_period(quilted):
    _, model, _ = quilted
    assert model.info["construction"] == "quilted" and model.torus == (3, 4)
    assert model.tile_size == (72, 72) and model.n_tiles == 12
    torus = _torus(model)[::3]
    py, px = torus.shape[1:3]
    assert (py, px) == PERIOD
    # the wrap-around border looks like the interior; uncut blocks from random places do not
    wrap = metrics.seam_visibility(torus, wrap=True).mean()
    assert wrap <= 1.15, wrap
    shifted = np.roll(torus, (py // 2, px // 2), axis=(1, 2))
    shifted[:, : py // 2, : px // 2] = torus[:, : py // 2, : px // 2][:, ::-1, ::-1]
    assert metrics.seam_visibility(shifted, wrap=True).mean() > 1.5 * wrap


def test_the_player_shows_a_window_of_the_torus(quilted):
    """With zero time offsets and no tone, frame 0 is the torus's frame 0 shifted by whole
    cells: the arrangement is the torus's cell order, shifted per seed."""
    _, model, path = quilted
    torus = _torus(model)
    ch, cw = model.tile_size
    rows, cols = model.torus
    with TilesPlayer(path, size=(300, 400), backend="numpy", seed=3, layout="torus") as p:
        p.max_shift = 0.0
        dy, dx = divmod(int(p.arrangement[0, 0]), cols)
        expect_cells = ((np.arange(p.grid_shape[0])[:, None] + dy) % rows) * cols + (
            np.arange(p.grid_shape[1])[None, :] + dx
        ) % cols
        assert (p.arrangement == expect_cells).all()
        got = p.next_frame()
    yy = (np.arange(300) + dy * ch) % torus.shape[1]
    xx = (np.arange(400) + dx * cw) % torus.shape[2]
    assert np.array_equal(got, torus[0][yy[:, None], xx[None, :]])


def test_seeds_shift_the_torus_and_states_keep_its_order(quilted):
    _, _, path = quilted
    firsts = set()
    for seed in range(6):
        with TilesPlayer(path, size=(120, 160), backend="numpy", seed=seed) as p:
            firsts.add(int(p.arrangement[0, 0]))
    assert len(firsts) >= 3
    with TilesPlayer(path, size=(120, 160), backend="numpy", seed=1) as p:
        state = p.get_state()
        broken = state["arrangement"].copy()
        broken[0, 0], broken[0, 1] = broken[0, 1], broken[0, 0]
        with pytest.raises(ValueError, match="out of their order"):
            p.set_state({**state, "arrangement": broken})
        p.set_state(state)
        assert np.array_equal(p.arrangement, state["arrangement"])


def test_output_has_no_lattice_and_no_seams_at_cells(quilted):
    _, _, path = quilted
    with TilesPlayer(path, size=(216, 288), backend="numpy", seed=2) as p:
        out = np.stack([p.next_frame() for _ in range(12)])
        ch, cw = p.tile_size
    assert abs(metrics.lattice_prominence(out, (ch, cw))) <= 0.03
    assert metrics.seam_visibility(out, metrics.grid_labels((216, 288), (ch, cw))).mean() <= 1.15


def test_quilted_options_are_clear_errors():
    clip = _stochastic(t=40)
    for kwargs, message in (
        ({"construction": "quilted", "mix": [clip]}, "cannot mix textures"),
        ({"construction": "quilted", "n_tiles": 3}, "n_tiles applies"),
        ({"construction": "quilted", "tile": (16, 24)}, "quilt block size"),
        ({"construction": "quilted", "flow_gain": -1}, "flow_gain"),
        ({"construction": "ring", "period": (200, 200)}, "period applies"),
    ):
        with pytest.raises(ValueError, match=message):
            learn_tiles(clip, min_loop=12, transition=4, **kwargs)


def test_a_broken_torus_is_a_format_error(quilted, tmp_path):
    _, _, path = quilted
    bad = tmp_path / "bad.h5"
    bad.write_bytes(path.read_bytes())
    with h5py.File(bad, "r+") as f:
        f["textures/noise/tiles"].attrs["torus_cols"] = 5
    with pytest.raises(TileDBFormatError, match="torus of cells needs"):
        TileDB(bad).texture("noise").read("tiles")


@pytest.mark.clips
def test_real_clip_has_no_lattice(clips_dir, tmp_path):
    clip = load_clip(clips_dir / "grass_straw_wind_dyntex.avi", size=(144, 176), stop=80)
    model = learn_tiles(clip.frames, period=(288, 360))  # the output below fits inside
    path = tmp_path / "g.h5"
    with DatabaseWriter(path) as w:
        w.put_texture("grass", clip.source_info())
        w.put_method("grass", "tiles", model)
    with TilesPlayer(path, size=(288, 352), seed=1) as p:
        out = np.stack([p.next_frame() for _ in range(24)])
        ch, cw = p.tile_size
    assert metrics.lattice_prominence(out, (ch, cw)) <= 0.03
    assert metrics.seam_visibility(out, metrics.grid_labels((288, 352), (ch, cw))).mean() <= 1.15
