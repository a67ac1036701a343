"""--best and --blowups on the command line: the library's result, the printed lines and the JSON agree."""

import json

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from conftest import make_scene
from sparsedepth.blowups import flag_blowups
from sparsedepth.cli.command import PROG, main


@pytest.fixture
def frame(tmp_path):
    """rgb.png and sparse.npy (10 % of a stepped plane, metres) whose image edge sits 3 px off the depth step."""
    image, depth = make_scene(shape=(48, 64))
    image = np.roll(image, 3, axis=1)
    iio.imwrite(tmp_path / "rgb.png", image)
    sparse, mask = sd.sample_depth(depth, fraction=0.1, seed=2)
    np.save(tmp_path / "sparse.npy", np.where(mask, sparse, np.nan))
    return tmp_path


def _run(frame, capsys, *extra):
    argv = ["--image", frame / "rgb.png", "--depth", frame / "sparse.npy", "--depth-scale", "m",
            "--out", frame / "out.npy", "--json", frame / "report.json", *extra]
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert rc == 0, err
    return out, json.loads((frame / "report.json").read_text()), np.load(frame / "out.npy")


def _library(frame, **options):
    image = sd.read_image(frame / "rgb.png")
    sparse = np.load(frame / "sparse.npy")
    return image, sparse, sd.complete_depth(image, sparse, **options)


@pytest.mark.filterwarnings("ignore::sparsedepth.ClampWarning")
def test_blowups_remove_writes_the_flagged_pixels_missing_and_says_how_many(frame, capsys):
    out, report, written = _run(frame, capsys, "--blowups", "remove")
    image, sparse, plain = _library(frame)
    flagged = flag_blowups(plain.depth, sparse)
    assert flagged.any()
    np.testing.assert_array_equal(np.isnan(written), flagged)
    np.testing.assert_allclose(written[~flagged], plain.depth[~flagged], rtol=1e-12)
    assert report["blowups"] == {"action": "remove", "flagged": int(flagged.sum()), "removed": int(flagged.sum())}
    assert f"--blowups remove: {int(flagged.sum())} pixels" in out


@pytest.mark.filterwarnings("ignore::sparsedepth.ClampWarning")
def test_blowups_flag_keeps_the_depth(frame, capsys):
    out, report, written = _run(frame, capsys, "--blowups", "flag")
    assert np.isfinite(written).all()
    assert report["blowups"]["removed"] == 0 and report["blowups"]["flagged"] > 0
    assert "--blowups flag" in out


@pytest.mark.filterwarnings("ignore::sparsedepth.ClampWarning")
def test_best_writes_the_chosen_completion_and_records_the_choice(frame, capsys):
    out, report, written = _run(frame, capsys, "--best", "--expected-error")
    image, sparse, chosen = _library(frame, quality="best", expected_error=True)
    np.testing.assert_allclose(written, chosen.depth, rtol=1e-12)
    assert report["selection"]["chosen"] == chosen.selection.chosen
    assert report["selection"]["scores"] == pytest.approx(dict(chosen.selection.scores), rel=1e-12)
    assert report["expected_rmse"] == pytest.approx(chosen.expected_rmse, rel=1e-12)
    assert f"best: {chosen.selection.chosen}" in report["method"]


@pytest.mark.parametrize("extra, expect", [
    (["--best", "--fast"], "--best and --fast"),
    (["--best", "--uncertainty", "u.npy"], "--best"),
    (["--best", "--tol", "1e-6"], "--tol"),
    (["--blowups", "sometimes"], "--blowups"),
    (["--fill-holes", "--blowups", "flag"], "--blowups"),
])
def test_refused_combinations_are_one_line_naming_the_flag(frame, capsys, extra, expect):
    argv = ["--image", frame / "rgb.png", "--depth", frame / "sparse.npy", "--depth-scale", "m", *extra]
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith(f"{PROG}: error: ")]
    assert len(lines) == 1 and expect in lines[0], err

