"""Benchmarks of hasa-env: the paper's protocol, its report, the performance benchmarks.

- :mod:`benchmarks.protocol`: the human-as-advisor benchmark (Mai et al.
  sections 3.3 and 4.3; docs/design.md §9): runs, fits, steering and
  estimation scores, for the built-in and any user steering model.
- :mod:`benchmarks.report`: tables, CSV files, the Markdown report, figures.
- :mod:`benchmarks.output`: the result folder of ``hasa-bench``, replaced only when complete.
- :mod:`benchmarks.recordings`: recordings replayed and checked, a steering model and
  the estimator scored on them (``hasa-replay``); :mod:`benchmarks.replay_document`: its
  ``--json`` document.
- :mod:`benchmarks.speed_scaled`: a fitted generalized model's speed-scaled equation error,
  fitted on held-out residuals (``hasa-bench`` and ``hasa-replay --fit``).
- :mod:`benchmarks.executor`: independent tasks on local processes or Dask.
- :mod:`benchmarks.paper_values`: the paper's published numbers.
- :mod:`benchmarks.perf`: performance benchmarks (env, estimators, views,
  advisor task).

The command line is ``hasa-bench`` (:mod:`hasa_cli.bench`).
"""
