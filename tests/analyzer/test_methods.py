"""The method registry describes itself: declared parameters match the learn functions."""

from __future__ import annotations

import inspect

import pytest

from dynatex.analyzer.methods import METHODS, Method, get_method
from dynatex.checks import Range
from dynatex.cli import main
from dynatex.errors import InvalidArgumentError
from dynatex.params import Param


@pytest.mark.parametrize("name", sorted(METHODS))
def test_declared_parameters_are_keywords_of_the_learn_function_with_its_defaults(name):
    method = METHODS[name]
    signature = inspect.signature(method.function()).parameters
    assert method.params, name
    for p in method.params:
        assert p.name in signature, f"{name}: {p.name} is not a keyword of {method.target}"
        assert signature[p.name].kind is inspect.Parameter.KEYWORD_ONLY, p.name
        default = signature[p.name].default
        if default is not inspect.Parameter.empty:
            assert p.default == default, f"{name}.{p.name}: declared {p.default!r}, function {default!r}"
        assert p.check(p.default) == p.default or p.default == ()  # the declared default follows its rule


def test_flags_are_distinct_across_methods():
    flags = [p.flag_name for m in METHODS.values() for p in m.params if p.flag_name]
    assert len(flags) == len(set(flags)) and "--tp-n" in flags and "--mix-components" in flags


def test_unknown_method_and_parameter_are_named():
    with pytest.raises(InvalidArgumentError, match="method must be one of .*'lds'.* not 'nope'"):
        get_method("nope")
    with pytest.raises(InvalidArgumentError, match="method lds has no parameter 'zz'"):
        get_method("lds").param("zz")


# -- a method added in one place reaches the command line and its learn function -----------------
SEEN: dict = {}


def toy_learn(clip, *, level: float = 0.25, progress=None):
    """A learn function of a toy method (registered only by the test below)."""
    SEEN["level"] = level
    return clip


TOY = Method(
    "toy",
    "tests.analyzer.test_methods:toy_learn",
    False,
    "a toy method of the test",
    (Param("level", Range(float, 0.0, 2.0, high_open=True), 0.25, "Toy level.", "--toy-level"),),
)


@pytest.fixture
def toy(monkeypatch):
    monkeypatch.setitem(METHODS, "toy", TOY)
    return TOY


def test_a_declared_parameter_is_an_option_with_its_rule_and_reaches_the_learn_function(toy, capsys):
    from dynatex.cli import build_parser
    from dynatex.commands.analyze import method_params

    with pytest.raises(SystemExit):
        main(["analyze", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "toy: a toy method of the test" in help_text
    assert "--toy-level TOY_LEVEL Toy level. A finite number in [0, 2) (default 0.25)." in help_text

    args = build_parser().parse_args(["analyze", "c.npy", "-o", "x.h5", "--methods", "toy", "--toy-level", "1.5"])
    params = method_params("toy", args)
    assert params == {"level": 1.5}
    toy.function()(None, **params)
    assert SEEN["level"] == 1.5
    args = build_parser().parse_args(["analyze", "c.npy", "-o", "x.h5", "--methods", "toy"])
    assert method_params("toy", args) == {"level": 0.25}


def test_a_declared_parameter_refuses_values_outside_its_rule(toy, capsys):
    with pytest.raises(SystemExit) as e:
        main(["analyze", "c.npy", "-o", "x.h5", "--toy-level", "2"])
    err = capsys.readouterr().err
    assert e.value.code == 2
    assert "argument --toy-level: expected a finite number in [0, 2), not '2'" in err
