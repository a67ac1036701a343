"""A batch with image_shift="auto": one shift measured on up to 8 of its frames, pooled, and used for every frame."""

import json
from concurrent.futures import ThreadPoolExecutor

import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd
from sparsedepth.batch import BatchOptions, find_frames, run_batch
from sparsedepth.batch import run as batch_run
from sparsedepth.complete import main

FAST = sd.Weights(gamma=0.0)  # quadratic objective: the direct solver is exact and fast
OFFSET = (0, 2)  # the image files are this far from the depth: (0, -2) registers them

pytestmark = pytest.mark.filterwarnings("ignore::sparsedepth.ClampWarning")


def _scene(seed, shape=(48, 60), regions=14):
    """Voronoi regions, a depth and a colour per region; the image moved by OFFSET (uint8)."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform((0, 0), shape, size=(regions, 2))
    yy, xx = np.mgrid[:shape[0], :shape[1]]
    labels = np.argmin((yy[..., None] - centres[:, 0]) ** 2 + (xx[..., None] - centres[:, 1]) ** 2, axis=-1)
    depth = rng.uniform(1.0, 5.0, regions)[labels]
    colours = rng.integers(0, 256, (regions, 3), dtype=np.uint8)[labels]
    return sd.shift_image(colours, OFFSET), depth


def _write_frames(folder, keys):
    folder.mkdir(exist_ok=True)
    for i, key in enumerate(keys):
        image, depth = _scene(seed=i)
        iio.imwrite(folder / f"rgb_{key}.png", image)
        sd.write_depth(folder / f"depth_{key}.png", depth, scale=1000)
    return find_frames(folder)


def _inputs(folder, key, position, seed, fraction):
    """The image, samples and mask of a frame, read and sampled as documented (seed [seed, position])."""
    image = sd.read_image(folder / f"rgb_{key}.png")
    depth = sd.read_depth(folder / f"depth_{key}.png", scale=1000)
    mask = sd.sample_mask(depth, fraction=fraction, seed=np.random.default_rng([seed, position]))
    return image, np.where(mask, depth, np.nan), mask


def test_shift_positions_spread_up_to_eight_frames_evenly():
    assert batch_run.shift_positions(1) == [0]
    assert batch_run.shift_positions(3) == [0, 1, 2]
    assert batch_run.shift_positions(10) == [0, 1, 3, 4, 5, 6, 8, 9]  # round(0, 1.29, 2.57, ..., 9)
    assert batch_run.shift_positions(20) == [0, 3, 5, 8, 11, 14, 16, 19]
    assert batch_run.shift_positions(5, 2) == [0, 4]


def test_auto_measures_one_shift_for_the_batch_and_completes_every_frame_with_it(tmp_path):
    keys = ["a", "b", "c"]
    folder = tmp_path / "frames"
    frames = _write_frames(folder, keys)
    out = tmp_path / "out"
    out.mkdir()
    options = BatchOptions(keep_fraction=0.2, seed=4, weights=FAST, solver="direct", depth_scale="mm",
                           out_dir=str(out), image_shift="auto")
    with ThreadPoolExecutor(max_workers=2) as pool:
        summary = run_batch(frames, tmp_path / "m.csv", options=options, executor=pool)
    assert summary.succeeded == 3 and summary.image_shift == (0, -2) and summary.image_shift_frames == 3

    inputs = [_inputs(folder, key, position, 4, 0.2) for position, key in enumerate(keys)]
    pooled = sd.pool_image_shifts([sd.estimate_image_shift(*frame) for frame in inputs])
    assert pooled.shift == (0, -2)
    for key, (image, sparse, mask) in zip(keys, inputs):
        expected = sd.complete_depth(sd.shift_image(image, (0, -2)), sparse, mask, weights=FAST, solver="direct")
        np.testing.assert_allclose(np.load(out / f"{key}.npy"), expected.depth, rtol=0, atol=1e-12)
    # the settings file keeps "auto", not the measured pair
    settings = json.loads((tmp_path / "m.csv.settings.json").read_text())
    assert settings["options"]["image_shift"] == "auto"

    # a rerun on the same CSV: nothing to do, the same shift measured on the same frames
    again = run_batch(frames, tmp_path / "m.csv", options=options, max_workers=1)
    assert again.skipped == 3 and again.image_shift == (0, -2) and again.image_shift_frames == 3


def test_the_measurement_counts_done_frames_so_a_resumed_batch_uses_the_same_shift(tmp_path):
    keys = ["a", "b", "c"]
    folder = tmp_path / "frames"
    frames = _write_frames(folder, keys)
    options = BatchOptions(keep_fraction=0.2, weights=FAST, solver="direct", depth_scale="mm", image_shift="auto")
    with ThreadPoolExecutor(max_workers=1) as pool:
        first = run_batch(frames, tmp_path / "m.csv", options=options, executor=pool)
    lines = (tmp_path / "m.csv").read_bytes().splitlines(keepends=True)
    # drop the last frame's row: the rerun runs it alone, with the shift measured on all three frames
    assert len(lines) == 4 and lines[-1].split(b",")[1] == b"c"
    (tmp_path / "m.csv").write_bytes(b"".join(lines[:-1]))
    with ThreadPoolExecutor(max_workers=1) as pool:
        second = run_batch(frames, tmp_path / "m.csv", options=options, executor=pool)
    assert second.skipped == 2 and second.succeeded == 3
    assert second.image_shift == first.image_shift == (0, -2) and second.image_shift_frames == 3


def test_frames_without_an_estimate_are_left_out_and_none_means_no_shift(tmp_path):
    folder = tmp_path / "frames"
    frames = _write_frames(folder, ["a", "b", "c"])
    (folder / "depth_b.png").write_bytes(b"\x89PNG\r\n\x1a\n this is not a PNG")  # corrupt
    options = BatchOptions(keep_fraction=0.2, weights=FAST, solver="direct", depth_scale="mm", image_shift="auto")
    with ThreadPoolExecutor(max_workers=2) as pool:
        summary = run_batch(frames, tmp_path / "m.csv", options=options, executor=pool)
    assert (summary.succeeded, summary.failed) == (2, 1)
    assert summary.image_shift == (0, -2) and summary.image_shift_frames == 2

    # 5 samples a frame: fewer than estimate_image_shift needs; the batch runs unshifted
    out = tmp_path / "out"
    out.mkdir()
    few = BatchOptions(keep_count=5, weights=FAST, solver="direct", depth_scale="mm", image_shift="auto",
                       out_dir=str(out), clip_to_observed=False)
    with ThreadPoolExecutor(max_workers=2) as pool:
        summary = run_batch(frames[:1], tmp_path / "few.csv", options=few, executor=pool)
    assert summary.image_shift == (0, 0) and summary.image_shift_frames == 0
    image = sd.read_image(folder / "rgb_a.png")
    depth = sd.read_depth(folder / "depth_a.png", scale=1000)
    mask = sd.sample_mask(depth, count=5, seed=np.random.default_rng([0, 0]))
    expected = sd.complete_depth(image, np.where(mask, depth, np.nan), mask, weights=FAST, solver="direct",
                                 clip_to_observed=False)
    np.testing.assert_allclose(np.load(out / "a.npy"), expected.depth, rtol=0, atol=1e-12)


def test_the_batch_estimates_only_the_frames_at_the_spread_positions(tmp_path, monkeypatch):
    image, depth = _scene(seed=0, shape=(16, 20), regions=4)
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(10):
        iio.imwrite(folder / f"rgb_{i:02d}.png", image)
        sd.write_depth(folder / f"depth_{i:02d}.png", depth, scale=1000)
    seen = []
    estimate = batch_run.estimate_frame_shift

    def recorded(position, source, options):
        seen.append((position, source.name))
        return estimate(position, source, options)

    monkeypatch.setattr(batch_run, "estimate_frame_shift", recorded)
    options = BatchOptions(keep_fraction=0.5, weights=FAST, solver="direct", depth_scale="mm", image_shift="auto")
    with ThreadPoolExecutor(max_workers=1) as pool:
        summary = run_batch(find_frames(folder), tmp_path / "m.csv", options=options, executor=pool)
    assert sorted(seen) == [(p, f"{p:02d}") for p in (0, 1, 3, 4, 5, 6, 8, 9)]
    assert summary.image_shift_frames == 8 and summary.succeeded == 10


def test_a_given_pair_or_no_option_is_reported_as_is(tmp_path):
    frames = _write_frames(tmp_path / "frames", ["a"])
    with ThreadPoolExecutor(max_workers=1) as pool:
        given = run_batch(frames, tmp_path / "g.csv", executor=pool,
                          options=BatchOptions(keep_fraction=0.2, weights=FAST, solver="direct", depth_scale="mm",
                                               image_shift=(1, -1)))
        none = run_batch(frames, tmp_path / "n.csv", executor=pool,
                         options=BatchOptions(keep_fraction=0.2, weights=FAST, solver="direct", depth_scale="mm"))
    assert (given.image_shift, given.image_shift_frames) == ((1, -1), None)
    assert (none.image_shift, none.image_shift_frames) == (None, None)


def test_cli_batch_prints_the_shift_of_the_batch(tmp_path, capsys):
    _write_frames(tmp_path, ["a", "b"])
    common = ["--batch", str(tmp_path), "--depth-scale", "mm", "--keep-fraction", "0.2", "--workers", "1", "-q",
              "--gamma", "0", "--solver", "direct"]
    assert main([*common, "--image-shift", "auto", "--csv", str(tmp_path / "a.csv")]) == 0
    out = capsys.readouterr().out
    assert "image shift for the batch: dy = 0, dx = -2 (measured on 2 frames)" in out
    assert main([*common, "--image-shift", "1,0", "--csv", str(tmp_path / "g.csv")]) == 0
    assert "image shift for the batch: dy = 1, dx = 0 (given)" in capsys.readouterr().out
    assert main([*common, "--csv", str(tmp_path / "n.csv")]) == 0
    assert "image shift" not in capsys.readouterr().out
