"""The offline runner's record of the mixture filter's states, kept in blocks of steps.

:func:`estimators.offline.run_estimator` steps a
:class:`~estimators.gm_ekf.GaussianMixtureEKF` with
:meth:`~estimators.gm_ekf.GaussianMixtureEKF.advance` and hands each step's
:class:`~estimators.gm_ekf.MixtureState` to :class:`MixtureTrace`. A state's arrays are never
changed once stored, so the trace keeps references and, every :data:`BLOCK_STEPS` steps,
stacks them and computes what the per-step record (``_Trace.store`` in
:mod:`estimators.offline`) computes from the :class:`~estimators.base.Estimate` and the
filter's properties, with the same numpy expressions over a K R run axis instead of R (the
same arithmetic, element by element: the results are equal to the bit, which
``tests/test_estimators_batched_step.py`` checks)::

    w      = exp(log w)                         x = sum_i w_i x_i
    std_n  = sqrt(sum_i w_i (P_i,nn + (x_i,n - x_n)^2))
    NIS_c  = sum_i w'_i min(max(u_ic, -1e3), 1e3)^2   (w': the weights the innovations were
                                                      weighed with; not at step 0)
"""

from __future__ import annotations

import numpy as np

from estimators.gm_ekf import MixtureState

__all__ = ["BLOCK_STEPS", "MixtureTrace"]

BLOCK_STEPS = 64
"""Steps kept as references before they are stacked and written (a block's stacked
covariance diagonals of 100 runs x 2 hypotheses x 10 states are 1 MB)."""


class MixtureTrace:
    """Per-step mixture estimates and diagnostics of R runs over T steps, written in blocks.

    Attributes (filled by :meth:`append` and :meth:`flush`): ``mean``, ``std`` (R, T, n),
    ``weights`` (R, T, C), ``most_likely`` (R, T), ``components`` (R, T, C, n) or None,
    ``gated`` (R, T, 3), ``low_speed`` (R, T), ``decision`` (R, T) int8, ``model_error``,
    ``evidence_scale`` (R, T) and ``channel_nis`` (R, T, 3); as ``_Trace`` of
    :mod:`estimators.offline` fills them.
    """

    def __init__(
        self, n_runs: int, n_steps: int, n_comp: int, n_states: int, store_components: bool
    ) -> None:
        self.mean = np.empty((n_runs, n_steps, n_states))
        self.std = np.empty((n_runs, n_steps, n_states))
        self.weights = np.empty((n_runs, n_steps, n_comp))
        self.most_likely = np.empty((n_runs, n_steps), dtype=np.int64)
        self.components = (
            np.empty((n_runs, n_steps, n_comp, n_states)) if store_components else None
        )
        self.gated = np.zeros((n_runs, n_steps, 3), dtype=bool)
        self.low_speed = np.zeros((n_runs, n_steps), dtype=bool)
        self.decision = np.full((n_runs, n_steps), -1, dtype=np.int8)
        self.model_error = np.full((n_runs, n_steps), np.nan)
        self.evidence_scale = np.full((n_runs, n_steps), np.nan)
        self.channel_nis = np.full((n_runs, n_steps, 3), np.nan)
        self._shape = (n_runs, n_comp, n_states)
        self._pending: list[MixtureState] = []
        self._first_step = 0

    def append(self, state: MixtureState) -> None:
        """Keep the state of the next step (written at the end of its block)."""
        self._pending.append(state)
        if len(self._pending) == BLOCK_STEPS:
            self.flush()

    def flush(self) -> None:
        """Write the kept steps."""
        states = self._pending
        if not states:
            return
        n_runs, n_comp, n = self._shape
        count = len(states)
        start, stop = self._first_step, self._first_step + count
        log_w = np.stack([s.log_w for s in states]).reshape(count * n_runs, n_comp)
        x = np.stack([s.x for s in states]).reshape(count * n_runs, n_comp, n)
        variance = np.stack([np.diagonal(s.P, axis1=-2, axis2=-1) for s in states])
        variance = variance.reshape(count * n_runs, n_comp, n)
        w = np.exp(log_w)
        mean = (w[:, None, :] @ x)[:, 0, :]
        spread = variance + (x - mean[:, None, :]) ** 2
        std = np.sqrt(np.einsum("rc,rcn->rn", w, spread))

        def put(target: np.ndarray, values: np.ndarray) -> None:
            """``target[:, start:stop] = values`` given (count R, ...) step-major."""
            block = values.reshape(count, n_runs, *values.shape[1:])
            target[:, start:stop] = np.moveaxis(block, 0, 1)

        put(self.mean, mean)
        put(self.std, std)
        put(self.weights, w)
        put(self.most_likely, np.argmax(log_w, axis=1))
        if self.components is not None:
            put(self.components, x)
        put(self.gated, np.concatenate([s.gated for s in states]))
        put(self.low_speed, np.concatenate([s.channel_off for s in states]))
        put(self.decision, np.concatenate([s.decision for s in states]))
        put(self.model_error, np.concatenate([s.model_error for s in states]))
        put(self.evidence_scale, np.concatenate([s.evidence_scale for s in states]))
        normalized = np.concatenate([s.normalized_innovation for s in states])
        innovation_w = np.exp(np.concatenate([s.innovation_log_w for s in states]))
        clipped = np.minimum(np.maximum(normalized, -1e3), 1e3)  # (NaN stays)
        put(self.channel_nis, np.einsum("rc,rcm->rm", innovation_w, clipped * clipped))
        if start == 0:  # step 0 (the reset) has no update: no gating, no NIS
            self.gated[:, 0] = False
            self.channel_nis[:, 0] = np.nan
        self._pending = []
        self._first_step = stop
