"""complete_depth(blowups=...): the completion's pixels judged by sparsedepth.blowups, flagged or removed."""

import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.blowups import flag_blowups

pytestmark = pytest.mark.filterwarnings("ignore::sparsedepth.ClampWarning")


def _step_frame(seed=0):
    """A two-level scene (1 m | 3 m) whose image edge sits 3 px off the depth edge, so the completion leaves
    values between the two levels near the edge."""
    h, w = 48, 64
    depth = np.where(np.arange(w)[None, :] < 30, 1.0, 3.0) * np.ones((h, 1))
    image = np.zeros((h, w, 3))
    image[:, 33:] = 1.0
    sparse, mask = sd.sample_depth(depth, fraction=0.05, seed=seed)
    return image, sparse, mask


@pytest.mark.parametrize("quality", ["default", "fast"])
def test_flag_marks_what_flag_blowups_marks_on_the_same_depth(quality):
    image, sparse, mask = _step_frame()
    plain = sd.complete_depth(image, sparse, mask, quality=quality)
    flagged = sd.complete_depth(image, sparse, mask, quality=quality, blowups="flag")
    np.testing.assert_array_equal(flagged.depth, plain.depth)
    np.testing.assert_array_equal(flagged.blowups, flag_blowups(plain.depth, sparse, mask))
    assert flagged.blowups.any()
    assert flagged.removed == plain.removed == 0
    assert plain.blowups is None


def test_remove_sets_the_flagged_pixels_to_nan_and_counts_them():
    image, sparse, mask = _step_frame(seed=1)
    plain = sd.complete_depth(image, sparse, mask)
    removed = sd.complete_depth(image, sparse, mask, blowups="remove")
    expected = flag_blowups(plain.depth, sparse, mask)
    np.testing.assert_array_equal(removed.blowups, expected)
    np.testing.assert_array_equal(np.isnan(removed.depth), expected)
    np.testing.assert_array_equal(removed.depth[~expected], plain.depth[~expected])
    assert removed.removed == int(expected.sum()) > 0


def test_a_planted_mid_jump_value_is_flagged_through_complete_depth():
    """A depth map whose pixel sits halfway up a jump between two flat sample sets is flagged (checked on the
    function the keyword calls, with a hand-made completed map)."""
    h, w = 32, 32
    truth = np.where(np.arange(w)[None, :] < 16, 1.0, 4.0) * np.ones((h, 1))
    sparse, mask = sd.sample_depth(truth, fraction=0.2, seed=3)
    completed = truth.copy()
    completed[10:13, 15:17] = 2.5
    completed[mask] = truth[mask]
    flagged = flag_blowups(completed, sparse, mask)
    assert flagged[10:13, 15:17][~mask[10:13, 15:17]].all()
    assert not flagged[:, :8].any() and not flagged[:, 24:].any()


def test_best_quality_takes_blowups_too():
    image, sparse, mask = _step_frame(seed=2)
    result = sd.complete_depth(image, sparse, mask, quality="best", blowups="flag")
    np.testing.assert_array_equal(result.blowups, flag_blowups(result.depth, sparse, mask))
    assert result.selection.chosen in result.selection.scores


@pytest.mark.parametrize("value, error", [("yes", ValueError), ("Flag", ValueError), (True, TypeError),
                                          (1, TypeError)])
def test_a_wrong_blowups_is_refused_naming_it(value, error):
    image, sparse, mask = _step_frame()
    with pytest.raises(error, match="blowups"):
        sd.complete_depth(image, sparse, mask, blowups=value)
