"""Every example in every module's docstrings runs and says what the module does.

Collected here rather than by ``pytest --doctest-modules``, which imports files by path and
cannot place ``player/``, ``analyzer/`` and ``tiledb/`` (top-level folders installed as
``dynatex.player`` and so on) in their package.
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import pkgutil
import re

import pytest

import dynatex

PACKAGES = (
    "dynatex",
    "dynatex.commands",
    "dynatex.tiledb",
    "dynatex.analyzer",
    "dynatex.player",
    "dynatex.player.modes",
    "dynatex.player.engines",
    "dynatex.player.opencl",
)


def _modules() -> list[str]:
    names = set()
    for package in PACKAGES:
        root = importlib.import_module(package)
        names.add(package)
        names.update(info.name for info in pkgutil.walk_packages(root.__path__, package + "."))  # subpackages too
    return sorted(n for n in names if not n.endswith("__main__"))


MODULES = _modules()


def test_every_package_module_is_collected():
    assert len(MODULES) >= 40 and "dynatex.player.engines.runs" in MODULES and "dynatex.tiledb.database" in MODULES
    assert dynatex.__name__ in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for test in finder.find(module, name):
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} failed (see the output)"


#: a Sphinx cross-reference to a name of ours: :data:`~dynatex.player.pixels.FORMATS`
REFERENCE = re.compile(r":(?:data|func|class|mod|meth|attr|exc):`~?(dynatex\.[\w.]+)`")


def _resolves(dotted: str) -> bool:
    """Whether ``dotted`` names a module, or an attribute reached from the longest module prefix."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for part in parts[i:]:
            if not hasattr(obj, part):
                return False
            obj = getattr(obj, part)
        return True
    return False


def test_every_reference_to_a_dynatex_name_resolves():
    """A docstring that points a reader to a name that does not exist (``player.engine.FORMATS``
    once) sends them nowhere."""
    found, missing = 0, []
    for name in MODULES:
        source = inspect.getsource(importlib.import_module(name))
        for match in REFERENCE.finditer(source):
            found += 1
            if not _resolves(match.group(1)):
                missing.append(f"{name}: {match.group(1)}")
    assert found >= 50, found
    assert not missing, missing
    assert not _resolves("dynatex.player.engine.FORMATS")


#: a short cross-reference, to a name of the module itself or (with a leading dot) of its package:
#: :func:`probe`, :class:`~.frames.FrameStore`, :mod:`.probe`
SHORT_REFERENCE = re.compile(r":(?:data|func|class|mod|exc):`~?(\.?[A-Za-z_][\w.]*)`")


def test_every_short_reference_resolves_in_its_module_or_package():
    """``:func:`run_child``` in a module that no longer has ``run_child`` points nowhere too. Methods
    and attributes (``:meth:``, ``:attr:``) name members of other classes or instances: not checked."""
    found, missing = 0, []
    for name in MODULES:
        module = importlib.import_module(name)
        package = name if hasattr(module, "__path__") else name.rsplit(".", 1)[0]
        for match in SHORT_REFERENCE.finditer(inspect.getsource(module)):
            ref = match.group(1)
            if ref.startswith("dynatex."):
                continue  # the test above
            found += 1
            if ref.startswith("."):
                ok = _resolves(package + ref)
            else:
                head, _, rest = ref.partition(".")
                ok = hasattr(module, head) and (not rest or _resolves(f"{name}.{ref}")) or _resolves(ref)
            if not ok:
                missing.append(f"{name}: {match.group(0)}")
    assert found >= 50, found
    assert not missing, missing
