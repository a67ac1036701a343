"""Benchmarks of sparsedepth: every table and figure in ``docs/`` is written by a module of this package.

Run each one as a module from the repository root (``python -m bench.<name>``; ``--help`` lists its options,
and most have ``--quick`` for a seconds-long smoke test on tiny frames):

* :mod:`bench.scene_disjoint` - the headline accuracy: leave-one-scene-out over every shared frame and seven input patterns (``docs/scene_disjoint.md``, and the README's accuracy block with ``--readme README.md``);
* :mod:`bench.run_all` - every table of ``docs/results.md`` (and the solver figures), from the five below;
* :mod:`bench.sparsity` - nearest-neighbour fill vs completion at 1 %, 5 %, 10 % observed (paper Table 3.1);
* :mod:`bench.baselines` - every baseline (nearest, linear, biharmonic, colorization) side by side with ours;
* :mod:`bench.ablation` - which terms of the objective matter (paper Table 3.2) and the extension terms;
* :mod:`bench.solvers` - every solver on the same objective: accuracy, speed, objective gap (paper Table 3.3, Fig. 3);
* :mod:`bench.protocol` - the literature's NYU protocol (304x228 crop, 200 / 500 samples);
* :mod:`bench.perf` - same-run speed ratios and peak memory on a 640x480 NYU frame (``docs/performance.md``);
* :mod:`bench.quadratic_variants` - multigrid variants of the default quadratic system and their diagnosis;
* :mod:`bench.holefill` - hole filling against the NYU-provided filled depth (``docs/holefill.md``);
* :mod:`bench.batch_scale` - batch throughput, process pool vs Dask LocalCluster (``docs/batch_scale.md``);
* :mod:`bench.admm_scale` - ADMM's time per pixel on L1 problems at 0.3, 1.2 and 4.9 megapixels (``docs/admm_scale.md``);
* :mod:`bench.solver_gaps` - every L1 solver on the reference objective's four terms (alpha 1, beta 0.5, gamma 0.2), three whole frames: gaps and times relative to ADMM;
* :mod:`bench.accuracy` - modelling variants (blurred edges, image-aware prior fill, depth-aware re-solve, ``prior=``) with a leave-one-dataset-out table (``docs/accuracy.md``);
* :mod:`bench.speed` - the depth-based stop of the default solve and, through :mod:`bench.fast_peers`, FGS and IP-Basic beside ours (``docs/speed.md``, ``docs/figures/speed_accuracy.png``);
* :mod:`bench.fast_mode` - ``quality="fast"`` against the default solve and OpenCV's fast global smoother (``docs/fast_mode.md``);
* :mod:`bench.scaling` - time per pixel of the default and fast modes from 0.3 to 4.9 megapixels and their 8-megapixel peak memory (``docs/scaling.md``);
* :mod:`bench.robust_penalties` - robust edge penalties against the L1 edge term (``docs/robust_penalties.md``);
* :mod:`bench.tune` - the seeded search that chose ``sparsedepth.DEFAULT_WEIGHTS`` (``docs/tuning.md``);
* :mod:`bench.density` - the density schedule of the default weights, tuned per density, with a leave-one-dataset-out table (``docs/density.md``);
* :mod:`bench.registration` - shifting the image onto the samples' depth edges, per input and calibrated per frame (``docs/registration.md``);
* :mod:`bench.default_runtime` - the default completion's time against the baseline objective's, same process (``docs/default_runtime.md``);
* :mod:`bench.interpolation` - bilinear against operator-dependent multigrid interpolation on the radius-2 completion systems (``docs/interpolation.md``);
* :mod:`bench.uncertainty` - how ``result.uncertainty`` ranks and covers the errors (``docs/uncertainty.md``);
* :mod:`bench.figures` - the front-page figures of four sensors, ``docs/figures/overview.png`` and the uncertainty pictures;
* :mod:`bench.expected_error` - the expected error against the true RMSE, scene by scene (``docs/expected_error.md``);
* :mod:`bench.best_quality` - ``quality="best"``'s choice, accuracy and cost (``docs/best_quality.md``);
* :mod:`bench.blowups` - what :func:`sparsedepth.blowups.flag_blowups` catches (``docs/blowups.md``);
* :mod:`bench.colmap_scene` and :mod:`bench.outliers` - dense depth from a COLMAP model, and wrong samples (``docs/colmap_scene.md``, ``docs/outliers.md``).

Shared pieces: :mod:`bench.frames` (the reported and the tuning frames, scene-disjoint; each frame's scene and leave-one-scene-out folds), :mod:`bench.harness`
(inputs, methods, one evaluation, aggregation, timing, markdown tables, machine description, report header,
command line), :mod:`bench.blas` (one BLAS thread, before numpy is imported), :mod:`bench.naive_colorization`
(the slow per-pixel reference port of the NYU toolbox fill) and ``bench/templates/`` (the prose of the reports,
as :class:`string.Template` files).

The benchmark modules may import :mod:`sparsedepth`, numpy, scipy, scikit-image and each other's shared pieces;
the library never imports this package.  Importing ``bench`` itself imports nothing.
"""
