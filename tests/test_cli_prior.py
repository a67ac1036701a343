"""``--prior``: the command line's external depth prior equals the library's ``complete_depth(prior=...)``; its errors."""
import json
import warnings

import numpy as np
import pytest

import sparsedepth as sd
from conftest import make_scene
from sparsedepth.complete import main


@pytest.fixture
def prior_files(scene_files):
    """``scene_files`` plus ``prior.npy`` (the scene's depth halved and shifted: relative depth) and ``truth.npy``, in mm."""
    _, depth = make_scene()
    np.save(scene_files / "prior.npy", 1000 * (0.5 * depth + 0.25))
    np.save(scene_files / "truth.npy", 1000 * depth)
    return scene_files


def _library(files, alignment):
    image = sd.read_image(files / "rgb.png")
    sparse = sd.read_depth(files / "sparse.png", scale=1000)
    prior = np.load(files / "prior.npy") / 1000  # --depth-scale mm reads every depth file in mm
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sd.ClampWarning)
        return sd.complete_depth(image, sparse, prior=prior, prior_alignment=alignment).depth


@pytest.mark.parametrize("alignment", [None, "scale"])
def test_cli_prior_writes_the_library_completion_with_that_prior(prior_files, capsys, alignment):
    f = prior_files
    argv = ["--image", str(f / "rgb.png"), "--depth", str(f / "sparse.png"), "--depth-scale", "mm",
            "--prior", str(f / "prior.npy"), "--out", str(f / "out.npy"), "--json", str(f / "m.json"), "-q"]
    rc = main(argv + ([] if alignment is None else ["--prior-alignment", alignment]))
    assert rc == 0, capsys.readouterr().err
    expected = _library(f, alignment or "scale_shift")
    np.testing.assert_allclose(sd.read_depth(f / "out.npy"), expected, rtol=1e-12)
    report = json.loads((f / "m.json").read_text())
    assert report["prior"] == {"file": str(f / "prior.npy"), "alignment": alignment or "scale_shift"}


def test_cli_prior_from_the_truth_up_to_scale_and_shift_beats_the_run_without_it(prior_files, capsys):
    f = prior_files
    base = ["--image", str(f / "rgb.png"), "--depth", str(f / "sparse.png"), "--depth-scale", "mm",
            "--truth", str(f / "truth.npy"), "-q"]
    scores = []
    for extra, name in (([], "plain"), (["--prior", str(f / "prior.npy")], "prior")):
        assert main(base + extra + ["--json", str(f / f"{name}.json")]) == 0, capsys.readouterr().err
        scores.append(json.loads((f / f"{name}.json").read_text())["metrics"]["completed"]["rmse"])
    # the aligned prior is the truth itself (the samples are the truth rounded to mm): far better than without it
    assert scores[1] < 0.2 * scores[0]


@pytest.mark.parametrize("extra, words", [
    (["--fast"], "--prior cannot be combined with --fast"),
    (["--uncertainty", "u.npy"], "--prior cannot be combined with --uncertainty"),
    (["--fill-holes", "--fill-method", "colorization"], "--fill-method colorization is not the completion solver and "
                                                        "takes no --prior"),
    (["--out", "prior.npy"], "--prior"),
])
def test_cli_prior_refuses_what_it_cannot_do_with_one_line_and_exit_2(prior_files, capsys, extra, words):
    f = prior_files
    before = (f / "prior.npy").read_bytes()
    rc = main(["--image", str(f / "rgb.png"), "--depth", str(f / "sparse.png"), "--depth-scale", "mm",
               "--prior", str(f / "prior.npy"), "-q", *[str(f / a) if a.endswith(".npy") else a for a in extra]])
    assert rc == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1
    assert (f / "prior.npy").read_bytes() == before  # never overwritten


def test_cli_prior_needs_a_dense_map_of_the_frame_size_and_one_frame(prior_files, capsys, tmp_path):
    f = prior_files
    prior = np.load(f / "prior.npy")
    holed = prior.copy()
    holed[3, 4] = np.nan
    np.save(f / "holed.npy", holed)
    np.save(f / "small.npy", prior[:-1])
    for name, words in (("holed.npy", "1 pixels without a value"), ("small.npy", "must have the same size")):
        rc = main(["--image", str(f / "rgb.png"), "--depth", str(f / "sparse.png"), "--depth-scale", "mm",
                   "--prior", str(f / name), "-q"])
        err = capsys.readouterr().err
        assert rc == 2 and words in err and "--prior" in err and len(err.strip().splitlines()) == 1
    for argv, words in ((["--prior", str(f / "prior.npy")], "--prior needs --image and --depth"),
                        (["--prior-alignment", "scale"], "give --prior PATH too")):
        assert main(argv + ["-q", "--outdir", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1
