"""Smoke test of ``python -m bench.scaling --quick`` and of its stencil-form switch."""

import importlib

import numpy as np

import sparsedepth as sd
from sparsedepth.grid.stencil import SymmetricStencil


def test_scaling_quick_report(capsys):
    scaling = importlib.import_module("bench.scaling")
    assert scaling.main(["--quick"]) == 0
    text = capsys.readouterr().out
    lines = [line for line in text.splitlines() if line.startswith("| ")]
    rows = {line.split("|")[1].strip(): line for line in lines}
    for mode in scaling.MODES:
        assert rows[mode].split("|")[2].strip().startswith("1.00 (")  # each mode relative to its smallest size
    assert "| 160x120 |" in text and "| 320x240 |" in text


def test_stencil_form_switch_is_restored():
    scaling = importlib.import_module("bench.scaling")
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (12, 14, 3)).astype(np.uint8)
    mask = rng.random((12, 14)) < 0.2
    sparse = np.where(mask, 1.0 + rng.random((12, 14)), 0.0)
    from sparsedepth.limits import memory_limits
    from sparsedepth.solvers import quadratic

    original = memory_limits()
    obj, _, _ = sd.build_objective(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS.replace(gamma=0))
    with scaling._stencil_form():
        assert isinstance(obj.normal_equations(form=quadratic.system_form(obj))[0], SymmetricStencil)
    assert memory_limits() == original and quadratic.system_form(obj) == "csr"
