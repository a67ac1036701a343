"""Smoke test of ``python -m bench.scaling --quick`` and of its stencil-form switch."""

import importlib

import numpy as np

import sparsedepth as sd
from sparsedepth.grid.stencil import SymmetricStencil
from sparsedepth.objective.objective import Objective


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
    original = Objective.normal_equations
    with scaling._stencil_form():
        obj, _, _ = sd.build_objective(image, sparse, mask, weights=sd.DEFAULT_WEIGHTS.replace(gamma=0))
        assert isinstance(obj.normal_equations()[0], SymmetricStencil)
    assert Objective.normal_equations is original
