"""Every example in every module's docstrings runs and says what the module does.

Collected here rather than by ``pytest --doctest-modules``, which imports files by path and
cannot place ``player/``, ``analyzer/`` and ``tiledb/`` (top-level folders installed as
``dynatex.player`` and so on) in their package.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import dynatex

PACKAGES = ("dynatex", "dynatex.tiledb", "dynatex.analyzer", "dynatex.player")


def _modules() -> list[str]:
    names = set()
    for package in PACKAGES:
        root = importlib.import_module(package)
        names.add(package)
        names.update(info.name for info in pkgutil.iter_modules(root.__path__, package + "."))
    return sorted(n for n in names if not n.endswith("__main__"))


MODULES = _modules()


def test_every_package_module_is_collected():
    assert len(MODULES) >= 40 and "dynatex.player.runs" in MODULES and "dynatex.tiledb.database" in MODULES
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
