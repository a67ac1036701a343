"""Which arguments go together is one table (completion.ARGUMENT_RULES) that the library, the batch options and the
command line all read: each front end refuses exactly the same combinations."""

import itertools

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.batch import BatchOptions
from sparsedepth.completion import ARGUMENT_RULES, argument_conflict
from sparsedepth.complete import main

#: complete_depth's value for each argument of the table that it takes
LIBRARY = dict(quality="fast", solver="cg", tol=1e-3, max_iter=3, callback=print, options={}, uncertainty=True,
               max_uncertainty=1.0, prior=np.ones((12, 14)), expected_error=True)
#: the command line's flags for each argument of the table that it has
FLAGS = dict(quality=["--fast"], solver=["--solver", "cg"], tol=["--tol", "1e-3"], max_iter=["--max-iter", "3"],
             uncertainty=["--uncertainty", "u.npy"], max_uncertainty=["--max-uncertainty", "1"],
             prior=["--prior", "prior.npy"], colorization=["--fill-holes", "--fill-method", "colorization"],
             weights=["--delta", "0.1"], expected_error=["--expected-error"])


def _pairs(names):
    return [pair for pair in itertools.combinations(sorted(names), 2)]


def test_the_table_refuses_what_each_rule_lists_and_nothing_else():
    for argument, _, excludes in ARGUMENT_RULES:
        for name in excludes:
            assert argument_conflict({argument, name})[0] == argument
    ruled = {(a, n) for a, _, ex in ARGUMENT_RULES for n in ex} | {(n, a) for a, _, ex in ARGUMENT_RULES for n in ex}
    names = {a for a, _, _ in ARGUMENT_RULES} | {n for _, _, ex in ARGUMENT_RULES for n in ex}
    for a, b in _pairs(names):
        assert (argument_conflict({a, b}) is not None) == ((a, b) in ruled), (a, b)


@pytest.mark.parametrize("a, b", _pairs(LIBRARY))
def test_complete_depth_follows_the_table(a, b):
    rng = np.random.default_rng(0)
    image, depth = rng.random((12, 14, 3)), 1.0 + rng.random((12, 14))
    sparse, mask = sd.sample_depth(depth, fraction=0.3, seed=0)
    kwargs = {a: LIBRARY[a], b: LIBRARY[b]}
    if argument_conflict({a, b}) is not None:
        with pytest.raises(ValueError, match="cannot be combined|takes no"):
            sd.complete_depth(image, sparse, mask, **kwargs)
    else:
        sd.completion.check_modes(**kwargs)  # the pair is allowed


@pytest.mark.parametrize("a, b", _pairs(["quality", "solver", "tol", "max_iter", "colorization", "weights"]))
def test_batch_options_follow_the_table(a, b):
    values = dict(quality=dict(quality="fast"), solver=dict(solver="cg"), tol=dict(tol=1e-3), max_iter=dict(max_iter=3),
                  colorization=dict(task="fill", fill_method="colorization"), weights=dict(weights=sd.DEFAULT_WEIGHTS))
    kwargs = {**values[a], **values[b]}
    if "colorization" not in (a, b):
        kwargs.setdefault("task", "complete")
    if argument_conflict({a, b}) is not None:
        with pytest.raises(ValueError, match="cannot be combined|takes no"):
            BatchOptions(**kwargs)
    else:
        BatchOptions(**kwargs)


@pytest.mark.parametrize("a, b", [pair for pair in _pairs(FLAGS) if argument_conflict(set(pair)) is not None])
def test_the_command_line_follows_the_table(a, b, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = ["--image", "rgb.png", "--depth", "depth.png", "--out", "dense.npy", *FLAGS[a], *FLAGS[b]]
    assert main(argv) == 2  # refused before any file is read
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and ("cannot be combined" in err[0] or "takes no" in err[0]), err
