"""The figure of one frame: panels, layout, resolution, grey where there is no value, the sample disks."""

import dataclasses
import io

import imageio.v3 as iio
import numpy as np
import pytest
from scipy import ndimage

import sparsedepth as sd
from sparsedepth.batch import evaluate_frame
from sparsedepth.cli.report import (build_figure, dilate_samples, panel_pixels, render_figure, sample_radius,
                                    uncertainty_statistics)
from sparsedepth.visualize import MISSING_COLOUR

pytest.importorskip("matplotlib", reason="the figure needs matplotlib (pip install 'sparsedepth[plot]')")

H, W = 96, 640  # a 640-px wide frame, short to keep the solve quick: wide, drawn two panels a row
NARROW = 200  # its first NARROW columns: a frame drawn four panels a row
HOLE = (slice(20, 60), slice(100, 220))  # pixels without ground truth


@pytest.fixture(scope="module")
def frame():
    """(image, outcome with truth) of a tilted plane with a step; truth is unknown in HOLE."""
    ii, jj = np.mgrid[0:H, 0:W]
    depth = 1.0 + 0.01 * ii + 0.002 * jj + 0.8 * (jj > W // 2)
    image = np.clip(60 + 120 * (jj > W // 2)[..., None] + np.zeros((1, 1, 3)), 0, 255).astype(np.uint8)
    truth = depth.copy()
    truth[HOLE] = np.nan
    outcome = evaluate_frame(image, depth, truth=truth, keep_fraction=0.05, seed=3,
                             weights=sd.Weights(gamma=0.0), solver="amg", clip_to_observed=False)
    return image, outcome


def _without_truth(outcome):
    return dataclasses.replace(outcome, truth=None, scored=None, metrics=None, nearest_metrics=None)


def _narrow(image, outcome):
    """The first NARROW columns of the frame (the scores are the whole frame's: the layout does not read them)."""
    columns = (slice(None), slice(0, NARROW))
    arrays = {name: getattr(outcome, name)[columns] for name in ("depth", "observed", "sparse", "nearest", "truth",
                                                                   "scored", "uncertainty")
              if getattr(outcome, name) is not None}
    return image[columns], dataclasses.replace(outcome, **arrays)


def _uncertainty(outcome):
    """A stand-in uncertainty: distance to the nearest sample, in metres per 100 pixels."""
    return 0.01 * ndimage.distance_transform_edt(~outcome.observed)


def _panels(fig):
    return {ax.get_title().split("\n")[0].split(":")[0].split(" (")[0]: ax for ax in fig.axes if ax.images}


def _rendered(fig):
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3]


def _pixel(fig, picture, ax, row, col):
    """Colour drawn at data pixel (row, col) of ``ax`` (display y runs upwards)."""
    x, y = ax.transData.transform((col, row))
    return picture[picture.shape[0] - 1 - int(y), int(x)]


@pytest.mark.parametrize("truth, uncertainty, panels, rows, wide_rows", [
    (False, False, 4, 1, 2), (False, True, 5, 2, 3), (True, False, 7, 2, 4), (True, True, 8, 2, 4),
])
@pytest.mark.parametrize("wide", [False, True])
def test_panels_and_rows(frame, truth, uncertainty, panels, rows, wide_rows, wide):
    image, outcome = frame if wide else _narrow(*frame)
    if wide:
        rows = wide_rows
    if not truth:
        outcome = _without_truth(outcome)
    if uncertainty:
        outcome = dataclasses.replace(outcome, uncertainty=_uncertainty(outcome))
    fig = build_figure(image, outcome)
    shown = _panels(fig)
    assert len(shown) == panels
    expected = {"image", "input", "nearest neighbour", outcome.method.split(" (")[0]}
    if truth:
        expected |= {"truth", "|nearest - truth|", "|output - truth|"}
    if uncertainty:
        expected.add("uncertainty")
    assert set(shown) == expected
    assert len({ax.get_subplotspec().rowspan.start for ax in shown.values()}) == rows
    # colour bars: depth, + one shared by both errors, + the uncertainty
    assert len(fig.axes) - panels == 1 + truth + uncertainty


def test_errors_share_one_scale_and_titles_carry_the_rmse(frame):
    image, outcome = frame
    shown = _panels(build_figure(image, outcome))
    near, ours = shown["|nearest - truth|"], shown["|output - truth|"]
    assert near.images[0].get_clim() == ours.images[0].get_clim()
    assert near.images[0].get_clim()[0] == 0.0
    # the RMSE with the digits of the table on stdout
    assert f"RMSE {outcome.nearest_metrics.rmse:.4f} m" in shown["nearest neighbour"].get_title()
    assert f"RMSE {outcome.metrics.rmse:.4f} m" in ours.get_title()


def test_depth_panels_are_colorize_depth_on_one_scale(frame):
    """Each depth panel shows sd.colorize_depth of its map, all with the limits of the 2nd and 98th percentiles
    of the truth (the measured depths: extrapolated output does not set the colours)."""
    image, outcome = frame
    shown = _panels(build_figure(image, outcome))
    truth = outcome.truth
    vmin, vmax = np.percentile(truth[np.isfinite(truth)], [2, 98])
    for name, depth in (("nearest neighbour", outcome.nearest), ("truth", truth),
                        (outcome.method.split(" (")[0], outcome.depth)):
        drawn = np.asarray(shown[name].images[0].get_array())
        expected = sd.colorize_depth(depth, vmin=vmin, vmax=vmax) / 255.0
        np.testing.assert_allclose(drawn, expected, atol=1e-12)


def test_depth_colour_bar_is_labelled_in_metres_at_the_colours_of_its_depths(frame):
    image, outcome = frame
    fig = build_figure(image, outcome)
    bar = next(ax for ax in fig.axes if "depth [m]" in ax.get_ylabel())
    labels = [float(t.get_text()) for t in bar.get_yticklabels()]
    positions = bar.get_yticks()
    assert len(labels) >= 3
    truth = outcome.truth
    vmin, vmax = np.percentile(truth[np.isfinite(truth)], [2, 98])
    # a linear scale here (vmax < 8 vmin): a tick's position is its depth's place between vmin and vmax
    np.testing.assert_allclose(positions, (np.array(labels) - vmin) / (vmax - vmin), atol=1e-9)


def test_a_street_scale_is_drawn_in_inverse_depth():
    """Depths over a factor of 8 (3 to 60 m): the panels are colorize_depth's inverse-depth colours and the bar
    says so."""
    h, w = 40, 60
    jj = np.mgrid[0:h, 0:w][1]
    depth = 3.0 + 57.0 * jj / (w - 1)
    image = np.full((h, w, 3), 128, dtype=np.uint8)
    outcome = evaluate_frame(image, depth, keep_fraction=0.3, seed=0, weights=sd.Weights(gamma=0.0), solver="amg")
    fig = build_figure(image, _without_truth(outcome))
    shown = _panels(fig)
    observed = outcome.sparse[outcome.observed]
    vmin, vmax = np.percentile(observed, [2, 98])
    assert vmax >= 8 * vmin
    expected = sd.colorize_depth(outcome.depth, vmin=vmin, vmax=vmax, scale="inverse") / 255.0
    np.testing.assert_allclose(shown[outcome.method.split(" (")[0]].images[0].get_array(), expected, atol=1e-12)
    bar = next(ax for ax in fig.axes if "depth [m]" in ax.get_ylabel())
    assert "1/depth" in bar.get_ylabel()
    labels = np.array([float(t.get_text()) for t in bar.get_yticklabels()])
    np.testing.assert_allclose(bar.get_yticks(), (1 / vmin - 1 / labels) / (1 / vmin - 1 / vmax), atol=1e-9)


def test_uncertainty_title_reports_the_statistics_of_the_unobserved_pixels(frame):
    """The title's median and 90th percentile, and the colour scale's top, are those of the unobserved pixels,
    computed here directly; the observed pixels (given a large sigma here) do not count."""
    image, outcome = frame
    sigma = _uncertainty(outcome)
    sigma[outcome.observed] = 50.0
    fig = build_figure(image, dataclasses.replace(outcome, uncertainty=sigma))
    panel = _panels(fig)["uncertainty"]
    hidden = sigma[~outcome.observed]
    median, p90, p99 = np.percentile(hidden, [50, 90, 99])
    title = panel.get_title()
    assert f"median {median:.3g} m" in title and f"90th percentile {p90:.3g} m" in title
    assert f"99th percentile, {p99:.3g} m" in title
    assert np.percentile(sigma, 99) > 10 * p99  # the observed pixels would have moved it
    assert panel.images[0].norm.vmax == pytest.approx(p99, rel=1e-12)
    statistics = uncertainty_statistics(sigma, outcome.observed)
    assert statistics["count"] == hidden.size and statistics["pixels"] == "unobserved"
    np.testing.assert_allclose([statistics["median"], statistics["p90"], statistics["p99"]], [median, p90, p99],
                               rtol=1e-12)


def test_a_640_px_frame_keeps_its_width(frame):
    image, outcome = frame
    for case in (outcome, _without_truth(outcome)):
        fig = build_figure(image, case)
        _rendered(fig)
        for ax in _panels(fig).values():
            assert ax.get_window_extent().width >= 0.95 * W
        picture = iio.imread(render_figure(image, case, ".png"))
        assert picture.ndim == 3 and picture.shape[1] >= 2 * W  # wide: two panels a row


def test_panel_width_within_bounds():
    assert panel_pixels(640) == 640 and panel_pixels(40) == 320 and panel_pixels(5000) == 1000


def test_no_truth_is_grey_not_a_colour_of_the_error_scale(frame):
    image, outcome = frame
    fig = build_figure(image, outcome)
    picture = _rendered(fig)
    shown = _panels(fig)
    for name in ("|nearest - truth|", "|output - truth|", "truth"):
        inside = _pixel(fig, picture, shown[name], 40, 160)  # in HOLE: no truth
        np.testing.assert_allclose(inside, MISSING_COLOUR, atol=2)
        known = _pixel(fig, picture, shown[name], 80, 400)  # truth known there
        assert np.abs(known.astype(int) - 128).max() > 10


def test_pixels_removed_from_the_output_are_grey_and_counted(frame):
    image, outcome = frame
    depth = outcome.depth.copy()
    depth[:, :50] = np.nan  # as --max-uncertainty removes them
    case = dataclasses.replace(outcome, depth=depth, uncertainty=_uncertainty(outcome))
    fig = build_figure(image, case)
    picture = _rendered(fig)
    ours = _panels(fig)[outcome.method.split(" (")[0]]
    assert f"{50 * H} px without depth" in ours.get_title()
    np.testing.assert_allclose(_pixel(fig, picture, ours, 40, 20), MISSING_COLOUR, atol=2)
    assert np.abs(_pixel(fig, picture, ours, 40, 300).astype(int) - 128).max() > 10


def test_samples_are_drawn_as_disks(frame):
    image, outcome = frame
    fig = build_figure(image, outcome)
    picture = _rendered(fig)
    panel = _panels(fig)["input"]
    radius = sample_radius((H, W))
    assert radius >= 1
    rows, cols = np.nonzero(outcome.observed)
    lone = [(r, c) for r, c in zip(rows, cols)
            if radius + 1 <= r < H - radius - 1 and radius + 1 <= c < W - radius - 1
            and outcome.observed[r - radius - 1:r + radius + 2, c - radius - 1:c + radius + 2].sum() == 1][0]
    centre = _pixel(fig, picture, panel, *lone)
    beside = _pixel(fig, picture, panel, lone[0], lone[1] + radius)
    background = _pixel(fig, picture, panel, lone[0], lone[1] + radius + 1)
    np.testing.assert_allclose(beside, centre, atol=2)  # the disk is the sample's colour
    assert np.abs(centre.astype(int) - background.astype(int)).max() > 10


def test_dilate_samples_takes_the_nearest_sample_within_the_radius():
    rng = np.random.default_rng(0)
    observed = rng.random((30, 40)) < 0.03
    sparse = np.where(observed, rng.uniform(1, 5, observed.shape), np.nan)
    before = sparse.copy()
    for radius in (1, 2, 4):
        out = dilate_samples(sparse, observed, radius)
        rows, cols = np.nonzero(observed)
        for i in range(30):
            for j in range(40):
                d2 = (rows - i) ** 2 + (cols - j) ** 2
                inside = d2 <= radius * radius + radius
                if not inside.any():
                    assert np.isnan(out[i, j])
                else:
                    nearest = d2[inside].min()
                    assert out[i, j] in sparse[rows[inside & (d2 == nearest)], cols[inside & (d2 == nearest)]]
    np.testing.assert_array_equal(sparse, before)


def test_sample_disks_visible_at_any_size():
    radii = [sample_radius((h, w)) for h, w in ((40, 60), (480, 640), (375, 1242), (2000, 3000), (4000, 8000))]
    assert radii == sorted(radii) and radii[0] >= 1
    for w, r in zip((60, 640, 1242, 3000, 8000), radii):
        assert r * panel_pixels(w) / w >= 0.75  # a disk at least about one drawn pixel in radius


@pytest.mark.parametrize("extension", [".png", ".pdf", ".svg", ".jpg"])
def test_render_formats(frame, extension):
    image, outcome = frame
    data = render_figure(image, outcome, extension)
    if extension in (".png", ".jpg"):
        assert iio.imread(io.BytesIO(data)).shape[1] >= 2 * W
    else:
        assert data[:5] in (b"%PDF-", b"<?xml")
