"""Benchmarks of hasa-env: the paper's protocol and the ``hasa-bench`` command.

- :mod:`benchmarks.protocol`: the human-as-advisor benchmark (Mai et al.
  sections 4.3 and 5.3; DESIGN.md section 6): runs, fits, steering and
  estimation scores, for the built-in and any user steering model.
- :mod:`benchmarks.report`: tables, CSV files, the Markdown report, figures.
- :mod:`benchmarks.cli`: ``hasa-bench paper | score | perf``
  (also ``python -m benchmarks``).
- :mod:`benchmarks.executor`: independent tasks on local processes or Dask.
- :mod:`benchmarks.paper_values`: the paper's published numbers.
- :mod:`benchmarks.perf_env`, :mod:`benchmarks.perf_estimators`,
  :mod:`benchmarks.perf_render`: performance benchmarks.
"""
