"""bench.figures on hand-made inputs (no completion): the copies for the docs fit their size, the limits table is the
share computed by hand, and the point cloud's view puts a point where a pinhole camera would."""

import importlib
import io

import numpy as np
import pytest


def _figures():
    return importlib.import_module("bench.figures")


def test_docs_copy_is_narrow_and_small_enough():
    pytest.importorskip("PIL", reason="the docs copies are encoded with Pillow (matplotlib's)")
    from PIL import Image

    figures = _figures()
    rng = np.random.default_rng(0)
    noise = rng.integers(0, 256, (900, 2600, 3), dtype=np.uint8)  # no encoder shrinks noise much
    buffer = io.BytesIO()
    Image.fromarray(noise).save(buffer, format="PNG")
    for jpeg in (False, True):
        data = figures.for_docs(buffer.getvalue(), jpeg=jpeg)
        picture = Image.open(io.BytesIO(data))
        assert picture.format == ("JPEG" if jpeg else "PNG")
        assert picture.width <= figures.DOCS_WIDTH
        assert picture.height == round(900 * picture.width / 2600)
        if picture.width > 600:  # the narrowest copy is kept even when it is still too large
            assert len(data) <= figures.MAX_BYTES


def test_limits_rows_are_the_shares_left_out():
    figures = _figures()
    depth = np.array([[1.0, 2.0, 4.0, 8.0], [1.0, 2.0, 4.0, 8.0]])
    sigma = np.array([[0.05, 0.3, 0.3, 3.0], [0.0, 0.0, 0.5, 0.5]])
    observed = np.array([[False, False, False, False], [True, True, False, False]])
    measured = np.where([[True, True, True, True], [True, True, True, False]], depth, np.nan)
    run = {"depth": depth, "sigma": sigma, "observed": observed, "measured": measured}
    rows = figures.limits_rows("hand", run)
    assert len(rows) == len(figures.ABSOLUTE_LIMITS) + len(figures.RELATIVE_LIMITS)
    # the measured region: unobserved with truth = (0,0) (0,1) (0,2) (0,3) (1,2); its nearest quarter: depth <= 2
    region = np.array([[True, True, True, True], [False, False, True, False]])
    near = region & (depth <= np.percentile(depth[region], 25))
    for row, (key, limit) in zip(rows, [("abs", m) for m in figures.ABSOLUTE_LIMITS]
                                 + [("rel", r) for r in figures.RELATIVE_LIMITS]):
        out = sigma > (limit if key == "abs" else limit * depth)
        assert row[1] == ("--max-uncertainty" if key == "abs" else "--max-relative-uncertainty")
        assert row[2:] == [f"{limit:g}", *(f"{100 * share:.1f}" for share in (out.mean(), out[region].mean(),
                                                                             out[near].mean()))]
    assert len(rows[0]) == len(figures.LIMITS_HEADER)


def test_turned_view_draws_the_median_point_at_the_centre():
    figures = _figures()
    points = np.array([[0.0, 0.0, 4.0], [0.0, 0.0, 5.0], [0.0, 0.0, 6.0]])
    colours = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255]], dtype=np.uint8)
    picture = figures._turned_view(points, colours, (40, 60), step=1)
    assert picture.shape == (40, 60, 3)
    # the median point (z = 5) is the centre of the turn: straight ahead of the moved camera
    assert picture[20, 30].tolist() == [0, 255, 0]
    assert (picture == 235).all(axis=2).sum() > 40 * 60 - 3 * 4 - 4  # elsewhere the background
