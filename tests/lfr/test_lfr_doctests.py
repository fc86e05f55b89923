"""The examples in the oos_drake.lfr docstrings run and give what they say."""

import doctest
import importlib

import pytest

MODULES = [
    "oos_drake.lfr.core",
    "oos_drake.lfr.uncertain",
    "oos_drake.lfr.substitution",
    "oos_drake.lfr.interconnect",
    "oos_drake.lfr.frequency",
    "oos_drake.lfr.reduction",
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0
