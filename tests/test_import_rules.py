"""The dependency rules: the player ships without OpenCV, SciPy, matplotlib, PyAV, Pillow, Dask or the
analyzer; ``dynatex CMD`` loads CMD's module alone, and ``play``/``info`` no analyzer; tiledb imports
nothing above it; no command imports the CLI; no new import cycle in a package (imports inside
functions and methods count)."""

from __future__ import annotations

import ast
import json
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
            importlib.import_module("dynatex.player.modes." + target.split(":")[0])
        with player.open_player({str(lds_db)!r}) as p:
            f = p.next_frame()
        assert f.shape == (24, 32, 3)
        print("ok")
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().endswith("ok")


#: runs ``dynatex ARGV`` in this process, then prints (last line) its exit code, the command modules
#: it loaded and the analyzer side it loaded (the analyzer, OpenCV, SciPy, matplotlib, Dask)
LOADED = textwrap.dedent("""
    import json, sys
    from dynatex.cli import main
    try:
        code = main(sys.argv[1:])
    except SystemExit as exc:  # --help
        code = exc.code
    commands = sorted(m for m in sys.modules if m.startswith("dynatex.commands."))
    heavy = ("cv2", "scipy", "matplotlib", "dask", "distributed")
    heavy = sorted(m for m in sys.modules if m.split(".")[0] in heavy or m.startswith("dynatex.analyzer"))
    print(json.dumps([code, commands, heavy]))
""")


def test_a_command_loads_its_own_module_and_play_or_info_no_analyzer(lds_db, tmp_path):
    """``dynatex --help`` names every command without importing one; ``dynatex CMD`` imports
    CMD's module (and its helpers) alone, so ``play`` (``--loop`` too, which reports the wrap)
    and ``info`` load no analyzer, OpenCV, SciPy or Dask, and ``analyze`` no player command."""
    from dynatex.commands import COMMANDS

    def loaded(*argv) -> tuple[str, list[str], list[str]]:
        r = subprocess.run(
            [sys.executable, "-c", LOADED, *map(str, argv)], capture_output=True, text=True, timeout=300, check=False
        )
        code, commands, heavy = json.loads(r.stdout.splitlines()[-1])
        assert code == 0, r.stderr
        return r.stdout, [m.rsplit(".", 1)[1] for m in commands], heavy

    out, commands, heavy = loaded("--help")
    assert commands == [] and heavy == [], (commands, heavy)
    listed = " ".join(out.split())
    assert all(f"{name} {summary}" in listed for name, summary in COMMANDS.items()), out
    player_side = ["_common", "_modes", "_output", "play"]
    video = tmp_path / "o.mp4"  # H.264 through PyAV (PNG frames, .mkv and .avi are written by OpenCV)
    for argv, own in (
        (("info", lds_db), ["info"]),
        (("play", "--help"), player_side),
        (("play", lds_db, "--frames", "2", "-o", video), player_side),
        (("play", lds_db, "--loop", "--frames", "8", "-o", tmp_path / "loop.mp4"), player_side),
    ):
        out, commands, heavy = loaded(*argv)
        assert (commands, heavy) == (own, []), argv
    assert video.stat().st_size > 0
    out, commands, heavy = loaded("analyze", "--help")
    assert commands == ["_common", "analyze"] and "--methods" in out, commands


def test_info_loads_no_opencl(lds_db):
    """``dynatex info`` reads the file and the modes' declarations: it loads neither pyopencl nor the
    player's OpenCL plumbing (a machine without an OpenCL driver lists a database all the same)."""
    code = textwrap.dedent("""
        import json, sys
        from dynatex.cli import main
        code = main(sys.argv[1:])
        opencl = sorted(m for m in sys.modules if m.split(".")[0] == "pyopencl" or ".opencl" in m)
        print(json.dumps([code, opencl]))
    """)
    r = subprocess.run([sys.executable, "-c", code, "info", str(lds_db)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "speed" in r.stdout  # the lds mode's controls were described
    assert json.loads(r.stdout.splitlines()[-1]) == [0, []]


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
    "dynatex.analyzer.metrics": "analyzer/metrics",
    "dynatex.analyzer.tiles": "analyzer/tiles",
    "dynatex.player": "player",
    "dynatex.player.modes": "player/modes",
    "dynatex.player.engines": "player/engines",
    "dynatex.player.opencl": "player/opencl",
}
#: the packages whose modules must not import each other in a cycle (a subpackage counts as its
#: package: ``player.modes.tiles`` -> ``player.base`` -> ``player.modes.tiles`` is a knot too)
TOP_PACKAGES = ("dynatex", "dynatex.commands", "dynatex.tiledb", "dynatex.analyzer", "dynatex.player")


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


def test_the_import_graph_sees_every_kind_of_import(tmp_path):
    source = textwrap.dedent("""
        import dynatex.text
        from . import probe as _probe
        from .. import cli
        from ..errors import DynatexError

        def later():
            from .database import TileDB
            import dynatex.child

        class Lazy:
            def method(self):
                from ..tiledb import schema
    """)
    (tmp_path / "x.py").write_text(source, encoding="utf-8")
    modules = {m: Path() for m in ("dynatex.text", "dynatex.cli", "dynatex.errors", "dynatex.child")}
    modules |= {f"dynatex.tiledb.{m}": Path() for m in ("probe", "database", "schema", "x")}
    assert _imports("dynatex.tiledb.x", tmp_path / "x.py", modules) == set(modules) - {"dynatex.tiledb.x"}
    graph = _graph()
    assert "dynatex.errors" in graph["dynatex.cli"] and "dynatex.text" in graph["dynatex.commands.info"]


def test_no_command_imports_the_cli_above_it():
    """``dynatex/cli.py`` loads the commands; a command importing it back would be a knot. What
    both need (errors, text helpers) lives in leaf modules below them."""
    graph = _graph()
    upward = sorted(m for m, targets in graph.items() if m.startswith("dynatex.commands") and "dynatex.cli" in targets)
    assert not upward, f"import dynatex.cli: {upward}"


#: leaf modules every layer may use, the tile database and the player included: they import no
#: module of ours but the errors (and nothing beyond the standard library: see the test below)
LEAVES = ("dynatex.errors", "dynatex.stale", "dynatex.child", "dynatex.cache", "dynatex.text")


def test_the_leaves_every_layer_uses_stay_leaves():
    graph = _graph()
    assert {m: graph[m] - {"dynatex.errors"} for m in LEAVES} == {m: set() for m in LEAVES}
    code = "import sys\n" + "".join(f"import {m}\n" for m in LEAVES)
    code += "print(sorted(m for m in ('numpy', 'h5py', 'pyopencl', 'cv2') if m in sys.modules))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert r.stdout.strip() == "[]", r.stdout


def _home(module: str) -> str:
    """The package of :data:`TOP_PACKAGES` that ``module`` belongs to (its subpackages included)."""
    return max((p for p in TOP_PACKAGES if module.startswith(p + ".")), key=len, default=module)


def _cycle_imports(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    """Imports between two modules of one package (its subpackages included) that lie on a
    cycle (the top packages' ``__init__`` modules aside: a module may import names from its own
    package; a subpackage's ``__init__`` is a module like any other)."""
    edges = {
        m: {t for t in targets if _home(t) == _home(m) and t not in TOP_PACKAGES}
        for m, targets in graph.items()
        if m not in TOP_PACKAGES
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


def test_no_import_cycle_inside_a_package():
    cycles = _cycle_imports(_graph())
    assert not cycles, f"imports closing a cycle: {sorted(cycles)}"
    knot = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycle_imports({f"dynatex.x.{k}": {f"dynatex.x.{t}" for t in v} for k, v in knot.items()}) == {
        ("dynatex.x.a", "dynatex.x.b"),
        ("dynatex.x.b", "dynatex.x.c"),
        ("dynatex.x.c", "dynatex.x.a"),
    }


def test_the_opencl_plumbing_imports_nothing_above_it():
    """``player/opencl`` is layered (devices, programs, verify, context) below every engine and
    mode; only the self-test's checks, which its child process alone imports, reach above."""
    graph = _graph()
    below = {"dynatex", "dynatex.player.errors", *LEAVES}
    plumbing = {m for m in graph if m.startswith("dynatex.player.opencl") and m != "dynatex.player.opencl.selftest"}
    assert {"dynatex.player.opencl.devices", "dynatex.player.opencl.context"} <= plumbing
    upward = {m: graph[m] - plumbing - below for m in plumbing if graph[m] - plumbing - below}
    assert not upward, upward
    importers = sorted(m for m, targets in graph.items() if "dynatex.player.opencl.selftest" in targets)
    assert not importers, f"the self-test's checks are imported by {importers}"


def test_no_player_module_over_800_lines():
    """A module a newcomer must read whole stays under 800 lines (issue 31: split it by its parts)."""
    long = {
        m: n
        for m, p in _modules().items()
        if m.startswith("dynatex.player") and (n := len(p.read_text().splitlines())) > 800
    }
    assert not long, long
