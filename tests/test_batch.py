"""Batch: per-frame pipeline, folder pairing, NYU .mat ranges, CSV rows, failing frames, executors."""

import csv
import os
import signal
import sys
import warnings
from concurrent.futures import ThreadPoolExecutor

import h5py
import imageio.v3 as iio
import numpy as np
import pytest

import sparsedepth as sd

from conftest import make_scene as _scene
from sparsedepth.batch import (
    CSV_COLUMNS,
    BatchOptions,
    FileFrame,
    evaluate_frame,
    find_frames,
    nyu_frames,
    run_batch,
)

FAST = sd.Weights(gamma=0.0)  # quadratic objective: the direct solver is exact and fast


def _read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


# ----------------------------------------------------------------------------- evaluate_frame
def test_evaluate_frame_matches_independent_computation():
    image, depth = _scene()
    out = evaluate_frame(image, depth, keep_fraction=0.1, seed=3, weights=FAST, solver="direct")
    sparse, mask = sd.sample_depth(depth, fraction=0.1, seed=3)
    np.testing.assert_array_equal(out.observed, mask)
    expected = sd.complete_depth(image, sparse, mask, weights=FAST, solver="direct")
    np.testing.assert_allclose(out.depth, expected.depth, rtol=0, atol=1e-12)
    assert out.metrics == sd.depth_metrics(expected.depth, depth, mask=~mask)
    assert out.nearest_metrics == sd.depth_metrics(sd.nearest_fill(sparse, mask), depth, mask=~mask)
    assert out.metrics.count == depth.size - mask.sum()
    assert out.method == "complete (direct)"


def test_evaluate_frame_fill_scores_holes_against_truth():
    image, truth = _scene(seed=1)
    raw = truth.copy()
    raw[10:20, 5:25] = 0.0
    out = evaluate_frame(image, raw, truth=truth, task="fill")
    np.testing.assert_array_equal(out.depth, sd.fill_holes(image, raw))
    holes = raw == 0
    np.testing.assert_array_equal(out.scored, holes)
    assert out.metrics == sd.depth_metrics(out.depth, truth, mask=holes)
    assert out.result is None and out.method == "fill colorization"


def test_evaluate_frame_without_truth_has_no_metrics():
    image, depth = _scene()
    sparse, _ = sd.sample_depth(depth, fraction=0.05, seed=0)
    out = evaluate_frame(image, sparse, weights=FAST, solver="direct")
    assert out.metrics is None and out.nearest_metrics is None
    assert np.all(np.isfinite(out.depth))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"task": "guess"}, "unknown task"),
        ({"task": "fill", "keep_fraction": 0.1}, "do not apply"),
        ({"task": "fill", "fill_method": "magic"}, "unknown fill method"),
    ],
)
def test_evaluate_frame_bad_options(kwargs, match):
    image, depth = _scene()
    with pytest.raises(ValueError, match=match):
        evaluate_frame(image, depth, **kwargs)


def test_evaluate_frame_bad_inputs():
    image, depth = _scene()
    with pytest.raises(ValueError, match="image has shape"):
        evaluate_frame(image[:-2], depth)
    with pytest.raises(ValueError, match="no valid pixel"):
        evaluate_frame(image, np.full(depth.shape, np.nan))


# ----------------------------------------------------------------------------- folders
def _write_frame(folder, key, image, depth, scale=1000.0):
    iio.imwrite(folder / f"rgb_{key}.png", image)
    sd.write_depth(folder / f"depth_{key}.png", depth, scale=scale)


def test_find_frames_pairs_by_name(tmp_path):
    image, depth = _scene()
    _write_frame(tmp_path, "002", image, depth)
    _write_frame(tmp_path, "001", image, depth)
    iio.imwrite(tmp_path / "rgb_003.png", image)  # no depth partner
    (tmp_path / "notes.txt").write_text("ignored")
    frames = find_frames(tmp_path)
    assert [f.name for f in frames] == ["001", "002", "003"]
    assert frames[0].depth == str(tmp_path / "depth_001.png")
    assert frames[2].depth is None


def test_frames_whose_files_do_not_pair_fail_with_the_reason(tmp_path):
    image, depth = _scene()
    for key in ("ok", "two_images", "two_depths", "two_truths", "alone"):
        _write_frame(tmp_path, key, image, depth)
        sd.write_depth(tmp_path / f"gt_{key}.npy", depth)
    iio.imwrite(tmp_path / "rgb_two_images.jpg", image)
    sd.write_depth(tmp_path / "depth_two_depths.npy", depth)
    sd.write_depth(tmp_path / "gt_two_truths.png", depth, scale=1000)
    (tmp_path / "depth_alone.png").unlink()
    frames = {f.name: f for f in find_frames(tmp_path, truth_prefix="gt_")}
    assert frames["ok"].problem is None and frames["ok"].truth == str(tmp_path / "gt_ok.npy")
    options = BatchOptions(keep_fraction=0.1, weights=FAST, solver="direct", depth_scale="mm")
    summary = run_batch(list(frames.values()), tmp_path / "m.csv", options=options,
                        executor=ThreadPoolExecutor(1))
    assert (summary.succeeded, summary.failed) == (1, 4)
    errors = {row["name"]: row["error"] for row in _read_csv(tmp_path / "m.csv")}
    assert errors["ok"] == ""
    assert "several images are named 'two_images' (rgb_two_images.jpg, rgb_two_images.png)" in errors["two_images"]
    assert "several depth files" in errors["two_depths"] and "depth_two_depths.npy" in errors["two_depths"]
    assert "several ground-truth files" in errors["two_truths"] and "gt_two_truths.png" in errors["two_truths"]
    assert errors["alone"] == f"ValueError: no depth file for image '{tmp_path / 'rgb_alone.png'}'"


def test_find_frames_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        find_frames(tmp_path / "absent")
    with pytest.raises(ValueError, match="no image"):
        find_frames(tmp_path)
    with pytest.raises(ValueError, match="prefixes"):
        find_frames(tmp_path, image_prefix="x_", depth_prefix="x_")


def test_folder_batch_with_a_corrupt_frame(tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    scenes = {key: _scene(seed=i) for i, key in enumerate(["a", "b", "c"])}
    for key, (image, depth) in scenes.items():
        _write_frame(folder, key, image, depth)
    (folder / "depth_b.png").write_bytes(b"\x89PNG\r\n\x1a\n this is not a PNG")  # corrupt
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    options = BatchOptions(keep_fraction=0.1, seed=7, weights=FAST, solver="direct", depth_scale="mm",
                           out_dir=str(out_dir))
    calls = []
    with ThreadPoolExecutor(max_workers=2) as pool:
        summary = run_batch(find_frames(folder), tmp_path / "m.csv", options=options, executor=pool,
                            progress=lambda done, total, row: calls.append((done, total, row["name"])))
    assert (summary.total, summary.succeeded, summary.failed) == (3, 2, 1)
    assert sorted(c[0] for c in calls) == [1, 2, 3] and all(c[1] == 3 for c in calls)
    rows = {row["name"]: row for row in _read_csv(tmp_path / "m.csv")}
    assert list(_read_csv(tmp_path / "m.csv")[0]) == list(CSV_COLUMNS)
    assert rows["b"]["status"] == "error" and "depth_b.png" in rows["b"]["error"]
    assert not (out_dir / "b.npy").exists()
    for position, key in ((0, "a"), (2, "c")):
        row = rows[key]
        assert row["status"] == "ok" and row["error"] == ""
        # independent recomputation from the files, with the documented per-frame seed
        image = sd.read_image(folder / f"rgb_{key}.png")
        depth = sd.read_depth(folder / f"depth_{key}.png", scale=1000)
        mask = sd.sample_mask(depth, fraction=0.1, seed=np.random.default_rng([7, position]))
        sparse = np.where(mask, depth, np.nan)
        completed = sd.complete_depth(image, sparse, mask, weights=FAST, solver="direct").depth
        metrics = sd.depth_metrics(completed, depth, mask=~mask)
        assert float(row["rmse"]) == pytest.approx(metrics.rmse, rel=1e-5)
        assert int(row["observed"]) == mask.sum() and int(row["scored"]) == metrics.count
        np.testing.assert_allclose(np.load(out_dir / f"{key}.npy"), completed, atol=1e-12)


def test_rows_are_flushed_as_frames_finish(tmp_path):
    # the caller stops the batch after the second frame: the first two rows are already on disk
    image, depth = _scene()
    for key in "abcd":
        _write_frame(tmp_path, key, image, depth)

    def progress(done, total, row):
        if done == 2:
            raise KeyboardInterrupt

    options = BatchOptions(keep_fraction=0.1, weights=FAST, solver="direct", depth_scale="mm")
    with ThreadPoolExecutor(max_workers=1) as pool, pytest.raises(KeyboardInterrupt):
        run_batch(find_frames(tmp_path), tmp_path / "m.csv", options=options, executor=pool,
                  max_workers=1, progress=progress)
    rows = _read_csv(tmp_path / "m.csv")
    assert [r["name"] for r in rows] == ["a", "b"]


def test_run_batch_errors(tmp_path):
    with pytest.raises(ValueError, match="no frame"):
        run_batch([], tmp_path / "m.csv")
    with pytest.raises(FileNotFoundError):
        run_batch([FileFrame("x", "a.png", "b.png")], tmp_path / "absent" / "m.csv")


# ----------------------------------------------------------------------------- NYU .mat
def _write_nyu_mat(path, frames):
    """HDF5 in the MATLAB v7.3 layout of nyu_depth_v2_labeled.mat (axes reversed)."""
    images = np.stack([img.transpose(2, 1, 0) for img, _, _ in frames])  # (N, 3, W, H)
    depths = np.stack([d.T for _, d, _ in frames]).astype(np.float32)  # (N, W, H)
    raws = np.stack([r.T for _, _, r in frames]).astype(np.float32)
    with h5py.File(path, "w") as fh:
        fh.create_dataset("images", data=images)
        fh.create_dataset("depths", data=depths)
        fh.create_dataset("rawDepths", data=raws)


def test_nyu_mat_range_on_a_process_pool(tmp_path):
    frames = []
    for seed in range(3):
        image, depth = _scene(seed=seed)
        raw = depth.copy()
        raw[np.random.default_rng(seed).random(depth.shape) < 0.3] = 0.0
        frames.append((image, depth, raw))
    mat = tmp_path / "nyu.mat"
    _write_nyu_mat(mat, frames)
    selected = nyu_frames(mat, slice(1, 3))
    assert [(f.name, f.index) for f in selected] == [("nyu_0001", 1), ("nyu_0002", 2)]
    summary = run_batch(selected, tmp_path / "nyu.csv", options=BatchOptions(task="fill"), max_workers=2)
    assert summary.failed == 0 and summary.succeeded == 2
    rows = {row["name"]: row for row in _read_csv(tmp_path / "nyu.csv")}
    for i in (1, 2):
        image, depth, raw = frames[i]
        depth32, raw32 = depth.astype(np.float32).astype(float), raw.astype(np.float32).astype(float)
        holes = raw32 == 0
        filled = sd.fill_holes(image, np.where(holes, np.nan, raw32))
        expected = sd.depth_metrics(filled, depth32, mask=holes)
        row = rows[f"nyu_{i:04d}"]
        assert row["method"] == "fill colorization"
        assert int(row["scored"]) == holes.sum()
        assert float(row["mae"]) == pytest.approx(expected.mae, rel=1e-5)


def test_nyu_frames_errors(tmp_path):
    image, depth = _scene()
    mat = tmp_path / "nyu.mat"
    _write_nyu_mat(mat, [(image, depth, depth)])
    with pytest.raises(IndexError):
        nyu_frames(mat, [5])
    with pytest.raises(ValueError, match="no frame selected"):
        nyu_frames(mat, slice(3, 5))
    with pytest.raises(FileNotFoundError):
        nyu_frames(tmp_path / "absent.mat")


def test_nyu_frames_index_the_file_as_the_reader_does(tmp_path):
    from sparsedepth.io import NYUDepthV2Labeled

    scenes = [_scene(seed=seed) for seed in range(3)]
    mat = tmp_path / "nyu.mat"
    _write_nyu_mat(mat, [(image, depth, depth) for image, depth in scenes])
    chosen = nyu_frames(mat, [-1, 0, np.int64(-3), 1])
    assert [f.index for f in chosen] == [2, 0, 0, 1]
    with NYUDepthV2Labeled(mat) as nyu:
        for frame in chosen:  # the frame the batch reads is the reader's frame of the index given
            np.testing.assert_array_equal(nyu[frame.index][0], scenes[frame.index][0])
        for bad, kind in ((3, IndexError), (-4, IndexError), (1.0, TypeError), ("0", TypeError)):
            with pytest.raises(kind) as from_reader:
                nyu[bad]
            with pytest.raises(kind) as from_batch:
                nyu_frames(mat, [bad])
            assert str(from_batch.value) == str(from_reader.value)


def test_clamped_pixels_are_a_column_not_a_printed_warning(tmp_path):
    image, depth = _scene()
    iio.imwrite(tmp_path / "rgb_a.png", image)
    sd.write_depth(tmp_path / "depth_a.npy", depth)
    # the default second-order terms overshoot the observed range at the depth step, so some pixels are clamped
    options = BatchOptions(keep_fraction=0.05, solver="direct")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run_batch(find_frames(tmp_path), tmp_path / "m.csv", options=options, executor=ThreadPoolExecutor(1))
    assert not [w for w in caught if issubclass(w.category, sd.ClampWarning)]
    (row,) = _read_csv(tmp_path / "m.csv")
    assert row["status"] == "ok", row
    # the same frame completed directly: the column holds the count the library reports
    with pytest.warns(sd.ClampWarning):
        out = evaluate_frame(image, depth, keep_fraction=0.05, seed=np.random.default_rng([0, 0]),
                             weights=options.weights, solver="direct")
    assert out.result.clamped > 0
    assert int(row["clamped"]) == out.result.clamped


def test_clip_to_observed_option_is_checked_and_passed_on(tmp_path):
    with pytest.raises(TypeError, match="clip_to_observed"):
        BatchOptions(clip_to_observed="no")
    image, depth = _scene()
    iio.imwrite(tmp_path / "rgb_a.png", image)
    sd.write_depth(tmp_path / "depth_a.npy", depth)
    out = tmp_path / "out"
    out.mkdir()
    options = BatchOptions(keep_fraction=0.05, solver="direct", clip_to_observed=False, out_dir=str(out))
    run_batch(find_frames(tmp_path), tmp_path / "m.csv", options=options, executor=ThreadPoolExecutor(1))
    (row,) = _read_csv(tmp_path / "m.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("error", sd.ClampWarning)  # unclamped: nothing to warn about
        expected = evaluate_frame(image, depth, keep_fraction=0.05, seed=np.random.default_rng([0, 0]),
                                  solver="direct", clip_to_observed=False)
    np.testing.assert_allclose(np.load(row["output"]), expected.depth, rtol=0, atol=1e-12)
    assert int(row["clamped"]) == expected.result.clamped


def openblas_threads() -> list[int]:
    """The thread count of every loaded OpenBLAS that reports one (run in a worker too: module level)."""
    import ctypes

    from sparsedepth.batch.pool import loaded_openblas, openblas_function

    counts = []
    for library in loaded_openblas():
        function = openblas_function(library, "get")
        if function is not None:
            function.restype = ctypes.c_int
            counts.append(int(function()))
    return counts


def test_default_pool_workers_run_blas_on_one_thread():
    from concurrent.futures import ProcessPoolExecutor

    from sparsedepth.batch import pool as batch

    before = openblas_threads()
    if not before:
        pytest.skip("no OpenBLAS loaded in this process (another BLAS build): nothing to check")
    with ProcessPoolExecutor(max_workers=1, initializer=batch.init_worker) as pool:
        in_worker = pool.submit(openblas_threads).result()
    assert in_worker and all(count == 1 for count in in_worker), in_worker
    assert openblas_threads() == before  # the driver's own pools are left as they were


def test_batch_applies_the_reader_options_to_every_frame(tmp_path, capsys):
    """--invalid-value / --min-depth / --max-depth in a batch: each frame reads as read_depth with those options."""
    from sparsedepth.complete import main

    frames = tmp_path / "frames"
    frames.mkdir()
    for key, seed in (("a", 0), ("b", 1)):
        image, depth = _scene(seed=seed)
        stored = np.rint(depth * 1000).astype(np.uint16)
        stored[0, :6] = 2047  # a sensor's "no measurement" code
        iio.imwrite(frames / f"rgb_{key}.png", image)
        iio.imwrite(frames / f"depth_{key}.png", stored)
    out = tmp_path / "out"
    out.mkdir()
    argv = ["--batch", frames, "--depth-scale", "mm", "--fill-holes", "--invalid-value", "2047", "--min-depth", "1.1",
            "--max-depth", "2.5", "--csv", tmp_path / "m.csv", "--outdir", out, "--workers", "1", "-q"]
    assert main([str(a) for a in argv]) == 0, capsys.readouterr().err
    rows = {row["name"]: row for row in _read_csv(tmp_path / "m.csv")}
    for key in ("a", "b"):
        raw = sd.read_depth(frames / f"depth_{key}.png", scale="mm", invalid_values=(2047,), min_depth=1.1,
                            max_depth=2.5)
        expected = evaluate_frame(sd.read_image(frames / f"rgb_{key}.png"), raw, task="fill")
        assert int(rows[key]["observed"]) == int(np.isfinite(raw).sum()) < raw.size - 6
        np.testing.assert_allclose(np.load(out / f"{key}.npy"), expected.depth, rtol=0, atol=1e-9)
    # the same command resumes (the options are part of the settings); other options are refused
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 0
    assert "2 skipped" in capsys.readouterr().out
    assert main([str(a) for a in argv] + ["--max-depth", "2.4"]) == 2  # the last --max-depth counts
    assert "--overwrite" in capsys.readouterr().err
    with pytest.raises(ValueError, match="min_depth"):
        BatchOptions(min_depth=3.0, max_depth=2.0)
    with pytest.raises(TypeError, match="invalid_values"):
        BatchOptions(invalid_values=[2047])


_DRIVER = """
import os, sys
from sparsedepth.batch.pool import new_pool
pool = new_pool(1)
print(pool.submit(os.getpid).result(), flush=True)
os.kill(os.getpid(), 9)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's prctl")
def test_default_pool_workers_end_with_a_killed_driver():
    import subprocess
    import time

    driver = subprocess.run([sys.executable, "-c", _DRIVER], capture_output=True, text=True, timeout=60)
    assert driver.returncode == -9
    worker = int(driver.stdout.split()[0])

    def alive(pid):
        try:
            with open(f"/proc/{pid}/stat") as stat:
                return stat.read().split(")")[-1].split()[0] != "Z"  # a zombie has ended
        except FileNotFoundError:
            return False

    deadline = time.monotonic() + 20.0
    while alive(worker) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(worker)


def test_end_with_parent_ends_a_process_whose_parent_is_gone():
    import multiprocessing

    from sparsedepth.batch.pool import end_with_parent

    if not sys.platform.startswith("linux"):
        assert end_with_parent(os.getppid()) is False
        return
    process = multiprocessing.get_context("fork").Process(target=end_with_parent, args=(-1,))  # not its parent
    process.start()
    process.join(20.0)
    assert process.exitcode == -signal.SIGTERM
