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
