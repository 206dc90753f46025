"""The paper's benchmark protocol (docs/design.md §9; Mai et al. sections 3.3 and 4.3).

:func:`run_protocol` (:mod:`~benchmarks.protocol.run`) runs it end to end;
the package's modules are its jobs: :mod:`~benchmarks.protocol.config`
(what to run), :mod:`~benchmarks.protocol.plan` (which runs: a
:class:`~benchmarks.protocol.plan.Plan` per seed or folder of recordings),
:mod:`~benchmarks.protocol.models` (user models, fitting),
:mod:`~benchmarks.protocol.tasks` (scoring and estimating batches of runs in
any process), :mod:`~benchmarks.protocol.aggregate` (tables),
:mod:`~benchmarks.protocol.results` (the result and its JSON) and
:mod:`~benchmarks.protocol.plots` (figure data).
"""

from benchmarks.protocol.config import BASELINES, BUILTIN_MODELS, BenchmarkError, ProtocolConfig
from benchmarks.protocol.models import ModelError, load_user_model
from benchmarks.protocol.results import BenchmarkResult
from benchmarks.protocol.run import run_protocol

__all__ = [
    "BASELINES",
    "BUILTIN_MODELS",
    "BenchmarkError",
    "BenchmarkResult",
    "ModelError",
    "ProtocolConfig",
    "load_user_model",
    "run_protocol",
]
