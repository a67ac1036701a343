"""The solver registry and the options dataclasses: one entry per solver, strict keys, instances as options."""

import dataclasses
import importlib
import inspect
import pkgutil

import numpy as np
import pytest

import sparsedepth as sd
import sparsedepth.solvers as solvers
from sparsedepth import Weights, build_objective, complete_depth
from sparsedepth.solvers import REGISTRY, SOLVER_OPTIONS, SOLVERS, check_solver_arguments, solve
from sparsedepth.solvers.options import AdmmOptions, IrlsOptions, SolverOptions

from conftest import make_problem

L1 = Weights.paper(alpha=1.0, beta=0.2, gamma=0.05, delta=0.01, kappa=5.0)
QUADRATIC = Weights.paper(gamma=0.0)

#: per solver: non-default options (each changes the run), the weights and a cap on the iterations
NON_DEFAULT = {
    "direct": ({"gap_tol": 1e-3}, QUADRATIC, None),
    "cg": ({"gap_tol": 1e-3}, QUADRATIC, None),
    "amg": ({"preconditioner": "amg", "gap_tol": 1e-3}, QUADRATIC, None),
    "irls": ({"eps_start": 0.05, "eps_factor": 5.0, "preconditioner": "amg"}, L1, None),
    "admm": ({"rho": 3.0, "relaxation": 1.5, "polish_rounds": 3, "check_every": 4}, L1, None),
    "lbfgsb": ({"maxcor": 5, "gtol": 1e-10}, L1, 200),
    "adam": ({"learning_rate": 0.02, "window": 20, "record_every": 3}, L1, 300),
}


@pytest.fixture(scope="module")
def problem():
    image, sparse, mask, _ = make_problem((12, 15))
    return image, sparse, mask


def _solver_functions():
    """Every ``solve_<name>`` function defined in a module of sparsedepth.solvers (the front door's excluded)."""
    found = set()
    for info in pkgutil.iter_modules(solvers.__path__):
        module = importlib.import_module(f"sparsedepth.solvers.{info.name}")
        for name, obj in vars(module).items():
            if (name.startswith("solve_") and name != "solve_scaled" and inspect.isfunction(obj)
                    and obj.__module__ == module.__name__):
                found.add(obj)
    return found


def test_the_registry_lists_exactly_the_solver_functions():
    assert tuple(SOLVERS) == tuple(REGISTRY) == tuple(SOLVER_OPTIONS) == tuple(sd.SOLVERS)
    assert all(SOLVERS[name] is REGISTRY[name].solve for name in SOLVERS)  # sd.SOLVERS stays a name → function mapping
    assert set(SOLVERS) == {"direct", "cg", "amg", "irls", "admm", "lbfgsb", "adam"}
    assert {entry.solve for entry in REGISTRY.values()} == _solver_functions()
    for name, entry in REGISTRY.items():
        assert entry.solve.__name__ == f"solve_{name}"
        assert entry.options.solver == name
        assert issubclass(entry.options, SolverOptions)
        assert SOLVER_OPTIONS[name] == {f.name: f.default for f in dataclasses.fields(entry.options)}
        assert "gap_tol" in SOLVER_OPTIONS[name]
    assert len({entry.options for entry in REGISTRY.values()}) == len(REGISTRY)


@pytest.mark.parametrize("solver", SOLVERS)
def test_a_misspelt_option_names_the_key_for_every_solver(problem, solver):
    first = next(iter(SOLVER_OPTIONS[solver]))
    misspelt = first[:-1] + ("x" if first[-1] != "x" else "y")
    for call in (lambda: check_solver_arguments(solver, options={misspelt: 1.0}),
                 lambda: REGISTRY[solver].options.from_mapping({misspelt: 1.0})):
        with pytest.raises(ValueError, match=rf"unknown option '{misspelt}' for solver '{solver}'") as info:
            call()
        for valid, default in SOLVER_OPTIONS[solver].items():
            assert f"{valid}={default!r}" in str(info.value)
    image, sparse, mask = problem
    weights = NON_DEFAULT[solver][1]
    with pytest.raises(ValueError, match=rf"unknown option '{misspelt}'"):
        complete_depth(image, sparse, mask, weights=weights, solver=solver, options={misspelt: 1.0})


@pytest.mark.parametrize("solver", SOLVERS)
def test_an_options_instance_gives_the_dict_forms_result(problem, solver):
    options, weights, max_iter = NON_DEFAULT[solver]
    image, sparse, mask = problem
    instance = REGISTRY[solver].options(**options)
    assert instance.as_dict() == {**SOLVER_OPTIONS[solver], **options}
    for depth_unit in (1.0, 1000.0):  # eps_start and learning_rate are in depth units: scaled alike
        if depth_unit != 1.0:
            options = {k: (v * depth_unit if k in ("eps_start", "learning_rate") else v) for k, v in options.items()}
            instance = REGISTRY[solver].options(**options)
        by_dict = complete_depth(image, sparse * depth_unit, mask, weights=weights, solver=solver, max_iter=max_iter,
                                 options=options)
        by_instance = complete_depth(image, sparse * depth_unit, mask, weights=weights, solver=solver,
                                     max_iter=max_iter, options=instance)
        np.testing.assert_array_equal(by_instance.depth, by_dict.depth)
        assert by_instance.objective == by_dict.objective
        assert by_instance.iterations == by_dict.iterations and by_instance.message == by_dict.message
    # the options change the run: the instance is not ignored
    default = complete_depth(image, sparse, mask, weights=weights, solver=solver, max_iter=max_iter)
    obj, coarse, _ = build_objective(image, sparse, mask, weights=weights)
    out, _ = solve(obj, coarse.ravel(), solver=solver, max_iter=max_iter, options=REGISTRY[solver].options(**options))
    ref, _ = solve(obj, coarse.ravel(), solver=solver, max_iter=max_iter, options=dict(options))
    np.testing.assert_array_equal(out.z, ref.z)
    if solver not in ("direct", "cg"):  # their options only set the certificate's threshold
        assert not np.array_equal(default.depth, by_dict.depth) or default.message != by_dict.message


def test_options_instances_are_frozen_keyword_only_and_checked():
    opts = AdmmOptions(rho=2)
    assert opts.rho == 2.0 and isinstance(opts.rho, float)
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.rho = 3.0
    with pytest.raises(TypeError):
        AdmmOptions(2.0)
    with pytest.raises(ValueError, match=r"options\['rho'\] of solver 'admm' must be finite and > 0; got -1.0"):
        AdmmOptions(rho=-1.0)
    with pytest.raises(TypeError, match=r"options\['polish'\] of solver 'admm' must be True or False; got int 1"):
        AdmmOptions(polish=1)
    with pytest.raises(ValueError, match=r"options\['preconditioner'\] of solver 'irls' must be one of"):
        IrlsOptions(preconditioner="ilu")
    assert AdmmOptions() == AdmmOptions.from_mapping(None) == AdmmOptions.from_mapping({})
    assert AdmmOptions.from_mapping(opts) is opts


def test_the_options_of_another_solver_are_refused(problem):
    image, sparse, mask = problem
    with pytest.raises(TypeError, match=r"options has type IrlsOptions, the options of solver 'irls'; solver 'admm'"):
        complete_depth(image, sparse, mask, weights=L1, solver="admm", options=IrlsOptions())
    with pytest.raises(TypeError, match=r"options must be a dict; got tuple"):
        check_solver_arguments("admm", options=(("rho", 1.0),))
    tol, max_iter, options = check_solver_arguments("admm", options=AdmmOptions(rho=2.0))
    assert options == {**SOLVER_OPTIONS["admm"], "rho": 2.0}
