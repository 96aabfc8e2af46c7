"""The dependency rules: the player ships without OpenCV, SciPy, matplotlib, PyAV, Pillow, Dask or the
analyzer; tiledb imports nothing above it; no command imports the CLI; no new import cycle in a package."""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

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


ROOT = Path(__file__).resolve().parents[1]
#: each package of dynatex -> its folder (pyproject's package-dir)
PACKAGE_DIRS = {
    "dynatex": "dynatex",
    "dynatex.commands": "dynatex/commands",
    "dynatex.tiledb": "tiledb",
    "dynatex.analyzer": "analyzer",
    "dynatex.player": "player",
}
#: Imports inside a package that close a cycle today (issue 31 untangles them): the test refuses
#: any other, so a knot can only shrink. Remove an entry when its import goes.
KNOWN_CYCLE_IMPORTS = {
    ("dynatex.tiledb.database", "dynatex.tiledb.probe"),
    ("dynatex.tiledb.probe", "dynatex.tiledb.database"),
    ("dynatex.player.base", "dynatex.player.loop"),
    ("dynatex.player.base", "dynatex.player.opencl"),
    ("dynatex.player.detail", "dynatex.player.engine"),
    ("dynatex.player.detail", "dynatex.player.opencl"),
    ("dynatex.player.engine", "dynatex.player.opencl"),
    ("dynatex.player.gather", "dynatex.player.base"),
    ("dynatex.player.gather", "dynatex.player.engine"),
    ("dynatex.player.gather", "dynatex.player.opencl"),
    ("dynatex.player.loop", "dynatex.player.tiles"),
    ("dynatex.player.opencl", "dynatex.player.selftest"),
    ("dynatex.player.projection", "dynatex.player.engine"),
    ("dynatex.player.projection", "dynatex.player.opencl"),
    ("dynatex.player.selftest", "dynatex.player.detail"),
    ("dynatex.player.selftest", "dynatex.player.gather"),
    ("dynatex.player.selftest", "dynatex.player.opencl"),
    ("dynatex.player.selftest", "dynatex.player.projection"),
    ("dynatex.player.selftest", "dynatex.player.stochastic"),
    ("dynatex.player.stochastic", "dynatex.player.base"),
    ("dynatex.player.stochastic", "dynatex.player.engine"),
    ("dynatex.player.stochastic", "dynatex.player.opencl"),
    ("dynatex.player.tiles", "dynatex.player.base"),
    ("dynatex.player.tiles", "dynatex.player.gather"),
    ("dynatex.player.tiles", "dynatex.player.stochastic"),
}


def _modules() -> dict[str, Path]:
    """Every module of dynatex (a package by its own name, for its ``__init__.py``) -> its file."""
    found = {}
    for package, folder in PACKAGE_DIRS.items():
        for path in sorted((ROOT / folder).glob("*.py")):
            found[package if path.stem == "__init__" else f"{package}.{path.stem}"] = path
    return found


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The modules of ours that ``name`` imports anywhere in its file (inside functions too)."""
    package = name if path.stem == "__init__" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            parts = package.split(".")
            base = ".".join(parts[: len(parts) - node.level + 1]) if node.level else ""
            target = ".".join(p for p in (base, node.module) if p)
            found.add(target)
            found.update(f"{target}.{alias.name}" for alias in node.names)  # from . import probe
    return {m for m in found if m in modules and m != name}


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def test_the_import_graph_sees_every_kind_of_import():
    graph = _graph()
    assert "dynatex.tiledb.probe" in graph["dynatex.tiledb.database"]  # from . import probe as _probe
    assert "dynatex.tiledb.database" in graph["dynatex.tiledb.probe"]  # inside a function
    assert "dynatex.errors" in graph["dynatex.cli"] and "dynatex.text" in graph["dynatex.commands.info"]


def test_no_command_imports_the_cli_above_it():
    """``dynatex/cli.py`` loads the commands; a command importing it back would be a knot. What
    both need (errors, text helpers) lives in leaf modules below them."""
    graph = _graph()
    upward = sorted(m for m, targets in graph.items() if m.startswith("dynatex.commands") and "dynatex.cli" in targets)
    assert not upward, f"import dynatex.cli: {upward}"


def _cycle_imports(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    """Imports between two modules of one package that lie on a cycle (package ``__init__``
    modules aside: a module may import names from its own package)."""
    edges = {
        m: {t for t in targets if t.rsplit(".", 1)[0] == m.rsplit(".", 1)[0] and t not in PACKAGE_DIRS}
        for m, targets in graph.items()
        if m not in PACKAGE_DIRS
    }

    def reach(start: str) -> set[str]:
        seen, todo = set(), [start]
        while todo:
            for t in edges.get(todo.pop(), ()):
                if t not in seen:
                    seen.add(t)
                    todo.append(t)
        return seen

    reachable = {m: reach(m) for m in edges}
    return {(a, b) for a, targets in edges.items() for b in targets if a in reachable[b]}


def test_no_new_import_cycle_inside_a_package():
    cycles = _cycle_imports(_graph())
    assert cycles <= KNOWN_CYCLE_IMPORTS, f"imports closing a new cycle: {sorted(cycles - KNOWN_CYCLE_IMPORTS)}"
    knot = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycle_imports({f"dynatex.x.{k}": {f"dynatex.x.{t}" for t in v} for k, v in knot.items()}) == {
        ("dynatex.x.a", "dynatex.x.b"),
        ("dynatex.x.b", "dynatex.x.c"),
        ("dynatex.x.c", "dynatex.x.a"),
    }
