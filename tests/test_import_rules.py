"""The dependency rule: the player ships without OpenCV, SciPy, matplotlib, PyAV, Pillow, Dask or the analyzer."""

from __future__ import annotations

import subprocess
import sys
import textwrap

BLOCKER = textwrap.dedent("""
    import sys
    BLOCKED = ("cv2", "scipy", "matplotlib", "tqdm", "av", "PIL", "dask", "distributed", "dynatex.analyzer",
               "dynatex.commands")

    class Block:
        def find_spec(self, name, path=None, target=None):
            if name in BLOCKED or name.startswith(tuple(b + "." for b in BLOCKED)):
                raise ImportError(f"{name} is not allowed here")
            return None

    sys.meta_path.insert(0, Block())
""")


def test_player_imports_and_runs_without_analyzer_dependencies(lds_db):
    code = BLOCKER + textwrap.dedent(f"""
        import dynatex.player as player
        import dynatex.tiledb
        from dynatex.player import modes
        import importlib
        for name, target in modes.MODES.items():
            importlib.import_module("dynatex.player." + target.split(":")[0])
        with player.open_player({str(lds_db)!r}) as p:
            f = p.next_frame()
        assert f.shape == (24, 32, 3)
        print("ok")
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().endswith("ok")


def test_tiledb_imports_nothing_above_it():
    code = textwrap.dedent("""
        import sys
        import dynatex.tiledb
        bad = [m for m in sys.modules if m.startswith(("dynatex.player", "dynatex.analyzer", "cv2", "pyopencl"))]
        assert not bad, bad
        print("ok")
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def test_analyzer_runs_a_corpus_in_process_without_dask(tmp_path):
    np_path = tmp_path / "w.npy"
    code = textwrap.dedent(f"""
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in ("dask", "distributed"):
                    raise ImportError(f"{{name}} is not installed here")
                return None
        sys.meta_path.insert(0, Block())
        import numpy as np
        from dynatex.analyzer import analyze_corpus
        t = np.arange(20)[:, None, None, None]
        x = np.arange(12)[None, None, :, None]
        y = np.arange(8)[None, :, None, None]
        wave = 128 + 60 * np.sin(0.3 * t + 0.5 * x + 0 * y)
        np.save({str(np_path)!r}, np.repeat(wave.astype(np.uint8), 3, axis=3))
        r = analyze_corpus([{str(np_path)!r}], {str(tmp_path / "out")!r}, params={{"lds": {{"n": 3}}}}, progress=False)
        assert [row.status for row in r] == ["ok"], r
        try:
            analyze_corpus([{str(np_path)!r}], {str(tmp_path / "out")!r}, scheduler="local", progress=False)
        except ImportError as exc:
            assert "dynatex[dask]" in str(exc), exc
        else:
            raise AssertionError("a local cluster ran without Dask")
        print("ok")
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().endswith("ok")
