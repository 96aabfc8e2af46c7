"""The method registry describes itself: declared parameters match the learn functions."""
from __future__ import annotations

import inspect

import pytest
from dynatex.analyzer.methods import METHODS, get_method

from dynatex.errors import InvalidArgumentError


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
        assert p.check(p.default) == p.default or p.default == ()     # the declared default follows its rule


def test_flags_are_distinct_across_methods():
    flags = [p.flag_name for m in METHODS.values() for p in m.params if p.flag_name]
    assert len(flags) == len(set(flags)) and "--tp-n" in flags and "--mix-components" in flags


def test_unknown_method_and_parameter_are_named():
    with pytest.raises(InvalidArgumentError, match="method must be one of .*'lds'.* not 'nope'"):
        get_method("nope")
    with pytest.raises(InvalidArgumentError, match="method lds has no parameter 'zz'"):
        get_method("lds").param("zz")
