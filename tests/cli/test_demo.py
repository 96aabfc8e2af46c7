"""`dynatex demo` runs the whole path on the built-in sample and writes what it promises."""

from __future__ import annotations

import cv2

from dynatex.cli import main
from dynatex.commands.demo import DEMO_STEPS
from dynatex.tiledb import open_db

from ..conftest import verified_devices


def test_demo_writes_database_video_and_contact_sheet(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "demo finished" in printed
    if verified_devices():
        assert "fps" in printed
        assert "lds 352x288 float32: OpenCL" in printed  # CIF, written WxH: the size was passed (height, width)
    else:  # the broken-driver case: the demo says why it has no benchmark
        assert "benchmark skipped: it compares the OpenCL player with the numpy reference" in printed
    with open_db(out / "sample.h5") as db:
        db.validate()
        assert "lds" in db.texture("ripples").methods
    cap = cv2.VideoCapture(str(out / "demo.mp4"))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    assert n == sum(step.frames for step in DEMO_STEPS)
    sheet = cv2.imread(str(out / "contact_sheet.png"))
    assert sheet is not None and sheet.shape[0] >= 96 * len(DEMO_STEPS)
