"""Inputs that look valid and could give a wrong answer without a word: each is an error naming the cause, or the
right answer.

A mask flipped to scikit-image's inpainting convention (True = to fill), a prior at an extreme scale, and relative
priors (an exact 0, negative values), which the command line takes by the library's rule.
"""
import warnings

import numpy as np
import pytest

import sparsedepth as sd
from conftest import make_scene
from sparsedepth.complete import main
from sparsedepth.priors import align_prior, as_prior

SHAPE = (16, 20)
#: Paper weights and the sparse LU: an exact, fast solve, so results can be compared to a tight tolerance.
EXACT = dict(weights=sd.Weights.paper(gamma=0.0), solver="direct")


def _scene(seed=0):
    """(image, truth, sparse with 0 where missing, mask) of a tilted plane with a step, 20 % observed."""
    rng = np.random.default_rng(seed)
    ii, jj = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    truth = 1.0 + 0.05 * ii + 0.02 * jj + 0.5 * (jj > SHAPE[1] // 2)
    image = np.clip(0.2 + 0.5 * (jj > SHAPE[1] // 2)[..., None] + 0.05 * rng.standard_normal(SHAPE + (3,)), 0, 1)
    mask = rng.random(SHAPE) < 0.2
    return image, truth, np.where(mask, truth, 0.0), mask


def _quiet(function, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        return function(*args, **kwargs)


# -- a flipped mask ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("call", [
    lambda image, sparse, mask: sd.complete_depth(image, sparse, mask, **EXACT),
    lambda image, sparse, mask: sd.fill_holes(image, sparse, mask=mask),
    lambda image, sparse, mask: sd.nearest_fill(sparse, mask),
    lambda image, sparse, mask: align_prior(np.ones(SHAPE), sparse, mask),
], ids=["complete_depth", "fill_holes", "nearest_fill", "align_prior"])
def test_a_mask_flipped_to_the_inpainting_convention_is_refused_with_the_likely_cause(call):
    image, _, sparse, mask = _scene()
    with pytest.raises(ValueError) as info:
        call(image, sparse, ~mask)
    message = str(info.value)
    flipped = int(np.count_nonzero(~mask))
    assert f"no depth at {flipped:,} of the {flipped:,} pixels mask marks as observed (0 at {flipped:,})" in message
    assert "mask must be True where depth is observed" in message and "pass ~mask" in message, message


def test_a_mask_over_a_few_missing_depths_is_refused_with_their_counts_and_no_flip_hint():
    image, _, sparse, mask = _scene()
    observed, bad = mask.copy(), sparse.copy()
    zero, negative, nan = (tuple(pixel) for pixel in np.argwhere(~mask)[:3])
    observed[zero] = observed[negative] = observed[nan] = True
    bad[negative], bad[nan] = -2.0, np.nan
    with pytest.raises(ValueError) as info:
        sd.complete_depth(image, bad, observed, **EXACT)
    message = str(info.value)
    count = int(observed.sum())
    assert f"no depth at 3 of the {count:,} pixels mask marks as observed" in message, message
    assert "0 at 1" in message and "1 negative" in message and "NaN or infinite values at 1" in message, message
    assert "~mask" not in message, message


def test_the_command_line_refuses_a_flipped_mask_in_one_line_naming_it(scene_files, capsys):
    f = scene_files
    depth = sd.read_depth(f / "sparse.png", scale=1000)
    observed = np.isfinite(depth)
    flipped = ~observed
    flipped[tuple(np.argwhere(observed)[:3].T)] = True  # an inpainting mask that covers a few samples too
    np.save(f / "holes.npy", flipped)
    before = (f / "holes.npy").read_bytes()
    rc = main(["--image", str(f / "rgb.png"), "--depth", str(f / "sparse.png"), "--depth-scale", "mm",
               "--mask", str(f / "holes.npy"), "--out", str(f / "out.npy"), "-q"])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    missing = int(np.count_nonzero(flipped & ~observed))
    assert f"--mask '{f / 'holes.npy'}'" in err and f"at {missing:,} of the {int(flipped.sum()):,} pixels" in err, err
    assert "invert" in err, err
    assert not (f / "out.npy").exists() and (f / "holes.npy").read_bytes() == before


# -- a prior at an extreme scale ------------------------------------------------------------------------------------

SCALES = [("scale_shift", 1e-14), ("scale_shift", 1e14), ("scale_shift", 2.0 ** -600), ("scale", 1e-170),
          ("scale", 1e160)]


@pytest.mark.parametrize("alignment, factor", SCALES)
def test_alignment_does_not_depend_on_the_scale_of_the_prior(alignment, factor):
    _, truth, sparse, mask = _scene()
    prior = truth + 0.3 * np.sin(np.arange(SHAPE[1]) / 3.0)  # not an affine copy: the fit has a residual
    reference, s, t = align_prior(prior, sparse, mask, alignment=alignment)
    aligned, s_f, t_f = align_prior(prior * factor, sparse, mask, alignment=alignment)
    np.testing.assert_allclose(aligned, reference, rtol=1e-12)
    assert s_f * factor == pytest.approx(s, rel=1e-12) and t_f == pytest.approx(t, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("alignment, factor", SCALES)
def test_a_prior_at_an_extreme_scale_completes_like_the_prior_itself(alignment, factor):
    image, truth, sparse, mask = _scene()
    prior = 0.5 * truth + 0.2 * np.cos(np.arange(SHAPE[0]) / 4.0)[:, None]
    reference = _quiet(sd.complete_depth, image, sparse, mask, prior=prior, prior_alignment=alignment, **EXACT)
    scaled = _quiet(sd.complete_depth, image, sparse, mask, prior=prior * factor, prior_alignment=alignment,
                    **EXACT)
    np.testing.assert_allclose(scaled.depth, reference.depth, rtol=1e-10)


@pytest.mark.parametrize("make_prior, alignment, words", [
    (lambda truth, mask: np.where(mask, 2.0, truth), "scale_shift", "takes the one value 2 at all"),
    (lambda truth, mask: np.where(mask, 0.0, truth), "scale", "is 0 at all"),
    (lambda truth, mask: np.zeros(SHAPE), "scale_shift", "is 0 at every pixel"),
    (lambda truth, mask: 1e-300 * truth, "scale", "not finite"),
], ids=["constant-at-the-samples", "zero-at-the-samples", "all-zero", "scale-overflows"])
def test_a_prior_that_cannot_be_aligned_is_refused_naming_it(make_prior, alignment, words):
    _, truth, sparse, mask = _scene()
    with pytest.raises(ValueError, match="prior") as info:
        align_prior(make_prior(truth, mask), sparse * 1e10, mask, alignment=alignment)
    assert words in str(info.value), str(info.value)


# -- one rule for relative priors -------------------------------------------------------------------------------------

def _relative_priors(truth):
    """A prior in [0, 1] with an exact 0 (normalised inverse ranks, as monocular networks give) and a zero-mean one."""
    unit = (truth - truth.min()) / (truth.max() - truth.min())
    return {"unit": unit, "zero_mean": truth - truth.mean()}


@pytest.mark.parametrize("kind", ["unit", "zero_mean"])
def test_a_relative_prior_with_zeros_or_negatives_is_taken_by_the_library_and_the_command_line_alike(
        scene_files, capsys, kind):
    f = scene_files
    prior = _relative_priors(make_scene()[1])[kind]
    assert prior.min() == 0 if kind == "unit" else prior.min() < 0
    np.save(f / "prior.npy", prior)
    image, sparse = sd.read_image(f / "rgb.png"), sd.read_depth(f / "sparse.png", scale=1000)
    # --depth-scale mm divides every depth file by 1000, the prior's too
    expected = _quiet(sd.complete_depth, image, sparse, prior=prior / 1000).depth
    rc = main(["--image", str(f / "rgb.png"), "--depth", str(f / "sparse.png"), "--depth-scale", "mm",
               "--prior", str(f / "prior.npy"), "--out", str(f / "out.npy"), "-q"])
    assert rc == 0, capsys.readouterr().err
    assert np.array_equal(np.load(f / "prior.npy"), prior)  # the input is not touched
    np.testing.assert_allclose(np.load(f / "out.npy"), expected, rtol=1e-12)


def test_as_prior_is_the_one_rule_zeros_and_negatives_are_values_nan_is_not():
    prior = np.array([[0.0, -1.5], [2.0, 0.0]])
    np.testing.assert_array_equal(as_prior(prior, (2, 2)), prior)
    holed = prior.copy()
    holed[0, 1] = np.inf
    with pytest.raises(ValueError, match=r"prior has 1 NaN or infinite values \(1 pixels without a value\)"):
        as_prior(holed, (2, 2))
    with pytest.raises(ValueError, match=r"--prior 'p.npy' has shape \(2, 2\) but --depth 'd.png' has shape"):
        as_prior(prior, (2, 3), name="--prior 'p.npy'", shape_name="--depth 'd.png'")
