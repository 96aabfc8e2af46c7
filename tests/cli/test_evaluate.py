"""``dynatex evaluate``: table and JSON reports, video/array/database outputs, bad input (exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dynatex.cli import main


def _texture(t: int = 40, h: int = 48, w: int = 64, seed: int = 0) -> np.ndarray:
    """A smooth drifting texture, RGB uint8."""
    import cv2

    rng = np.random.default_rng(seed)
    big = cv2.GaussianBlur(rng.normal(0, 1, (h + t, w + t)).astype(np.float32), (0, 0), 3)
    big /= big.std()
    frames = np.stack([big[i // 2 : i // 2 + h, i : i + w] for i in range(t)])
    return np.repeat((128 + 40 * frames).clip(0, 255).astype(np.uint8)[..., None], 3, axis=-1)


def _write_video(path: Path, frames: np.ndarray) -> Path:
    import cv2

    wr = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 25, (frames.shape[2], frames.shape[1]))
    assert wr.isOpened()
    for f in frames:
        wr.write(np.ascontiguousarray(f[..., ::-1]))
    wr.release()
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("evaluate")
    src = _texture()
    np.save(d / "src.npy", src)
    np.save(d / "loop.npy", src[np.arange(40) % 10])
    np.save(d / "small.npy", src[:, :32, :32])
    _write_video(d / "src.avi", src)
    return d


def _run(capsys, *argv) -> tuple[int, str, str]:
    rc = main(["evaluate", *map(str, argv)])
    out, err = capsys.readouterr()
    return rc, out, err


def test_json_report_video_against_itself(files, capsys):
    rc, out, _ = _run(
        capsys, files / "src.avi", files / "src.avi", "--boundaries", "grid:16x16+3+3", "--events", "10,20", "--json"
    )
    assert rc == 0
    rep = json.loads(out)
    assert rep["output_frames"] == 40 and rep["output_size"] == [48, 64]  # [height, width]
    assert rep["stability"]["stable"] is True
    assert rep["spectrum_distance_db"] == 0.0
    assert rep["frame_coverage"] == 1.0 and rep["repetition_lag"] is None
    assert rep["temporal_discontinuity"]["events"] == [10, 20]
    assert 0.7 < rep["seam_visibility"]["mean"] < 1.3
    lat = rep["lattice_correlation"]
    assert lat["period"] == [16, 16] and lat["output"] == lat["source"]  # the source against itself


def test_a_tiled_output_shows_its_lattice(files, capsys, tmp_path):
    """An output made of one 16x16 block repeated: correlation 1 at the grid period."""
    src = np.load(files / "src.npy")
    tiled = np.tile(src[:, :16, :16], (1, 3, 4, 1))
    np.save(tmp_path / "tiled.npy", tiled)
    rc, out, _ = _run(capsys, files / "src.npy", tmp_path / "tiled.npy", "--boundaries", "grid:16x16")
    assert rc == 0
    line = next(ln for ln in out.splitlines() if ln.startswith("lattice correlation y/x at 16x16"))
    assert "1.00 / 1.00" in line
    # a grid wider than the frame still has seams across y; the lattice figure is n/a, not a crash
    rc, out, _ = _run(capsys, files / "src.npy", tmp_path / "tiled.npy", "--boundaries", "grid:2000x16")
    assert rc == 0
    line = next(ln for ln in out.splitlines() if ln.startswith("lattice correlation"))
    assert "n/a: frame not larger than the grid" in line


def test_table_flags_a_loop(files, capsys):
    rc, out, _ = _run(capsys, files / "src.npy", files / "loop.npy", "--events", "every:10")
    assert rc == 0
    lines = {ln.split("  ")[0].strip(): ln for ln in out.splitlines()}
    assert "repetition lag (frames)" in lines and " 10 " in lines["repetition lag (frames)"] + " "
    assert "0.250" in lines["frame coverage"]  # 10 of 40 source frames
    assert "over 3 events" in lines["temporal discontinuity max"]


def test_other_size_output_skips_size_bound_metrics(files, capsys):
    rc, out, _ = _run(capsys, files / "src.npy", files / "small.npy", "--json")
    assert rc == 0
    rep = json.loads(out)
    assert rep["stability"] is None and rep["frame_coverage"] is None
    assert rep["patch_coherence"] == pytest.approx(0.0, abs=1e-3)  # a crop: all its patches are source patches
    rc, out, _ = _run(capsys, files / "src.npy", files / "small.npy")
    assert rc == 0 and "n/a: output size differs" in out


def test_png_label_mask(files, capsys, tmp_path):
    import cv2

    mask = np.zeros((48, 64, 3), np.uint8)
    mask[:, 30:] = (255, 0, 0)
    mask[20:, :] = (0, 255, 0)
    cv2.imwrite(str(tmp_path / "mask.png"), mask)
    rc, out, _ = _run(capsys, files / "src.npy", files / "src.npy", "--boundaries", tmp_path / "mask.png", "--json")
    assert rc == 0
    assert 0.6 < json.loads(out)["seam_visibility"]["mean"] < 1.5
    cv2.imwrite(str(tmp_path / "small.png"), mask[:10, :10])
    rc, _, err = _run(capsys, files / "src.npy", files / "src.npy", "--boundaries", tmp_path / "small.png")
    assert rc == 2 and "mask is 10x10 but the output frames are 64x48" in err


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--boundaries", "grid:100x100"], "no seam inside the 64x48 frame"),
        (["--boundaries", "grid:axb"], "grid:WxH"),
        (["--boundaries", "nowhere.png"], "neither grid:WxH, border, nor an existing image"),
        (["--events", "40"], "outside the output's frames 1..39"),
        (["--events", "3,x"], "comma-separated frame indices"),
        (["--events", "every:0"], "N >= 1"),
        (["--texture", "water"], "--texture applies to a database output"),
    ],
)
def test_bad_options_exit_2(files, capsys, extra, message):
    rc, out, err = _run(capsys, files / "src.npy", files / "src.npy", *extra)
    assert rc == 2
    assert message in err and "Traceback" not in err
    assert out == ""


def test_bad_files_exit_2(files, capsys, tmp_path):
    empty = tmp_path / "empty.avi"
    empty.write_bytes(b"")
    rc, _, err = _run(capsys, files / "src.npy", empty)
    assert rc == 2 and "empty" in err
    rc, _, err = _run(capsys, files / "src.npy", tmp_path / "missing.avi")
    assert rc == 2 and "no such clip" in err
    np.save(tmp_path / "one.npy", np.zeros((1, 8, 8, 3), np.uint8))
    rc, _, err = _run(capsys, files / "src.npy", tmp_path / "one.npy")
    assert rc == 2 and "only one frame" in err


@pytest.mark.clips
def test_real_clip_against_its_loop(clips_dir, capsys, tmp_path):
    from dynatex.analyzer import load_clip

    src = clips_dir / "steam_vapour_pot_128px.avi"
    frames = load_clip(src).frames
    np.save(tmp_path / "loop.npy", frames[np.arange(frames.shape[0]) % 10])
    rc, out, _ = _run(capsys, src, tmp_path / "loop.npy", "--events", "every:10", "--json")
    assert rc == 0
    rep = json.loads(out)
    assert rep["repetition_lag"] == 10
    assert rep["temporal_discontinuity"]["max"] > 1.5
    assert rep["patch_completeness"] > 2 * rep["patch_coherence"]


def test_database_output_lds(files, capsys, tmp_path):
    pytest.importorskip("h5py")
    db = tmp_path / "tex.h5"
    rc = main(["analyze", str(files / "src.npy"), "-o", str(db), "--n", "10", "-q"])
    capsys.readouterr()
    assert rc == 0
    rc, out, err = _run(capsys, files / "src.npy", db, "--frames", "60", "--backend", "numpy", "--seed", "3", "--json")
    assert rc == 0, err
    rep = json.loads(out)
    assert rep["output_frames"] == 60 and rep["output_size"] == [48, 64]  # [height, width]
    assert rep["player"]["mode"] == "lds"
    assert rep["stability"]["nonfinite_frames"] == 0
    assert 0.2 < rep["stability"]["min_ratio"] and rep["stability"]["max_ratio"] < 5
    # the same seed gives the same frames, so the same report
    rc, out2, _ = _run(capsys, files / "src.npy", db, "--frames", "60", "--backend", "numpy", "--seed", "3", "--json")
    assert json.loads(out2)["stability"] == rep["stability"]
    rc, _, err = _run(capsys, files / "src.npy", db, "--size", "32x32", "--backend", "numpy")
    assert rc == 2 and "--size is not supported by mode lds" in err
    with pytest.raises(SystemExit) as exit_:
        _run(capsys, files / "src.npy", db, "--mode", "nope", "--backend", "numpy")
    assert exit_.value.code == 2 and "argument --mode: invalid choice: 'nope'" in capsys.readouterr().err


def test_tiles_database_reports_lattice_prominence_and_writes_a_sheet(tmp_path, capsys):
    from ..conftest import wave_clip

    clip = tmp_path / "wave.npy"
    np.save(clip, wave_clip(50, 40, 48))
    db = tmp_path / "t.h5"
    assert (
        main(
            [
                "analyze",
                str(clip),
                "-o",
                str(db),
                "--methods",
                "tiles",
                "--tile",
                "16",
                "--tiles-n",
                "2",
                "--tiles-min-loop",
                "16",
            ]
        )
        == 0
    )
    capsys.readouterr()
    sheet = tmp_path / "sheet.png"
    rc, out, _ = _run(
        capsys,
        clip,
        db,
        "--mode",
        "tiles",
        "--size",
        "96x80",
        "--frames",
        "12",
        "--json",
        "--sheet",
        sheet,
        "--samples",
        "100",
    )
    assert rc == 0
    rep = json.loads(out)
    lp = rep["lattice_prominence"]
    assert lp["tile"] == [16, 16] and -1.0 <= lp["output"] <= 1.0 and len(lp["lags"]) >= 3
    assert lp["source"] is None or -1.0 <= lp["source"] <= 1.0
    from PIL import Image

    img = np.asarray(Image.open(sheet))
    # three rows of the 48x40 source beside the 96x80 output
    assert img.shape[1] == 48 + 8 + 96 and img.shape[0] > 3 * 80
    assert rep["sheet"] == str(sheet)
    rc, out, _ = _run(capsys, clip, db, "--mode", "tiles", "--size", "96x80", "--frames", "12", "--samples", "100")
    assert rc == 0 and any(ln.startswith("lattice prominence at 16x16 cells") for ln in out.splitlines())


def test_sheet_to_an_unwritable_place_is_one_line(files, capsys, tmp_path):
    rc, _, err = _run(capsys, files / "src.npy", files / "src.npy", "--sheet", tmp_path / "no" / "such" / "s.png")
    assert rc == 2 and "--sheet" in err and "Traceback" not in err


def test_verdicts_in_json_and_table_and_strict_gates(files, capsys):
    rc, out, _ = _run(capsys, files / "src.npy", files / "src.npy", "--json", "--strict")
    assert rc == 0
    rep = json.loads(out)
    judged = {v["figure"]: v for v in rep["verdicts"]}
    assert rep["verdict"] == "good" and all(v["verdict"] in ("good", "n/a") for v in rep["verdicts"])
    assert judged["frame_step_ratio"]["good"] == "0.8..1.25" and judged["seam_visibility"]["verdict"] == "n/a"
    # a 10-frame loop of the source: repeats after 10 frames (bad), and --strict says so
    rc, out, err = _run(capsys, files / "src.npy", files / "loop.npy", "--strict")
    assert rc == 3
    line = next(ln for ln in out.splitlines() if ln.startswith("repetition lag"))
    assert line.split()[-1] == "bad"
    assert out.splitlines()[-1].startswith("overall: bad")
    assert "repetition_lag" in err
    # without --strict the same report exits 0
    rc, _, _ = _run(capsys, files / "src.npy", files / "loop.npy")
    assert rc == 0


def test_a_frozen_output_is_judged_bad(files, capsys, tmp_path):
    src = np.load(files / "src.npy")
    np.save(tmp_path / "frozen.npy", np.repeat(src[:1], 40, axis=0))
    rc, out, _ = _run(capsys, files / "src.npy", tmp_path / "frozen.npy", "--json", "--strict")
    assert rc == 3
    judged = {v["figure"]: v["verdict"] for v in json.loads(out)["verdicts"]}
    assert judged["frame_step_ratio"] == "bad" and judged["spectrum_distance_db"] == "bad"
