"""``python -m benchmarks``: the ``hasa-bench`` command (see :mod:`benchmarks.cli`)."""

import sys

from benchmarks.cli import main

sys.exit(main())
