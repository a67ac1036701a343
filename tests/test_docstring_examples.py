"""Every ``Examples`` section of the package's docstrings runs and prints what it shows."""

import doctest
import importlib
import pkgutil

import pytest

import sparsedepth

MODULES = sorted(name for _, name, _ in pkgutil.walk_packages(sparsedepth.__path__, "sparsedepth."))


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run_as_shown(name):
    module = importlib.import_module(name)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for test in doctest.DocTestFinder().find(module, name):
        runner.run(test, out=lambda text: None)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} fail; run " \
                               f"python -m pytest --doctest-modules {module.__file__}"


def test_the_package_has_examples():
    found = sum(len([t for t in doctest.DocTestFinder().find(importlib.import_module(n), n) if t.examples])
                for n in MODULES)
    assert found >= 20
