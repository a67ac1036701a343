"""The package's public surface: the user's API first, at most 40 names, every one importable."""

import pydoc

import sparsedepth as sd


def test_the_public_names_are_few_and_all_importable():
    assert len(sd.__all__) <= 40
    assert len(set(sd.__all__)) == len(sd.__all__)
    for name in sd.__all__:
        assert getattr(sd, name) is not None, name


def test_help_opens_with_the_users_api():
    text = pydoc.render_doc(sd, renderer=pydoc.plaintext)
    opening = "\n".join(text.splitlines()[:40])
    assert "The user's API" in opening
    for name in ("complete_depth", "fill_holes", "CompletionProblem", "Weights", "read_depth"):
        assert name in opening


def test_names_of_earlier_versions_stay_attributes():
    """Code written against the longer list keeps working: those names are attributes of the package."""
    for name in ("build_objective", "Objective", "QuadraticTerm", "AbsTerm", "RobustTerm", "observed_fraction",
                 "resolve_weights", "choose_solver", "geodesic_fill", "pool_image_shifts", "ImageShift",
                 "PRIOR_ALIGNMENTS", "RobustPenalty", "robust_penalty", "PENALTIES", "IterationRecord",
                 "SolverState", "UncertaintyCalibration", "Frame", "load_embedded_frame", "list_embedded_frames",
                 "shared_data_dir", "DEPTH_SCALES", "FILL_METHODS", "edge_weights"):
        assert hasattr(sd, name), name


def test_memory_limits_are_one_settings_object_changed_in_a_block():
    from sparsedepth.limits import MemoryLimits, limited, memory_limits

    default = memory_limits()
    assert default == MemoryLimits()
    with limited(stencil_form_pixels=1, gather_pixels=8) as inside:
        assert inside is memory_limits() and inside.stencil_form_pixels == 1 and inside.gather_pixels == 8
        with limited(gather_pixels=4):
            assert memory_limits().gather_pixels == 4 and memory_limits().stencil_form_pixels == 1
        assert memory_limits().gather_pixels == 8
    assert memory_limits() == default
    import pytest

    with pytest.raises(ValueError, match="unknown memory limit"):
        with limited(band_pixels=3):
            pass
    with pytest.raises(ValueError, match="must be an int >= 0"):
        MemoryLimits(gather_pixels=-1)


def test_scaling_in_place_divides_each_target_once_even_when_two_terms_share_it():
    import numpy as np
    import pytest

    from sparsedepth.objective import Objective, QuadraticTerm
    from sparsedepth.solvers import scaled_objective

    shared = np.full(6, 4.0)
    objective = Objective((2, 3), [QuadraticTerm("data", 1.0, None, None, shared),
                                   QuadraticTerm("prior", 0.5, None, None, shared[:])])
    scaled = scaled_objective(objective, 2.0, overwrite=True)
    np.testing.assert_array_equal(scaled.term("data").target, 2.0)
    np.testing.assert_array_equal(scaled.term("prior").target, 2.0)
    reference = Objective((2, 3), [QuadraticTerm("data", 1.0, None, None, np.full(6, 4.0)),
                                   QuadraticTerm("prior", 0.5, None, None, np.full(6, 4.0))])
    z = np.arange(6.0)
    assert scaled.value(z / 2.0) * 4.0 == pytest.approx(reference.value(z), rel=1e-15)
