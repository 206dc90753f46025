"""A run's estimate does not depend on the other runs of the batch, to the bit.

The vector advisor task filters N cars in one batch and must reproduce N
single envs exactly; one run pruning a hypothesis must not renormalize the
weights of the others.
"""

from __future__ import annotations

import numpy as np
import pytest

from estimators import FilterSettings, GaussianMixtureEKF
from hasa_env.steering.models import GeneralizedModel


@pytest.mark.parametrize("prune", [True, False], ids=["pruning", "default (evidence checks)"])
def test_every_run_of_a_batch_is_filtered_as_alone_also_when_another_prunes(prune):
    rng = np.random.default_rng(3)
    runs, steps = 5, 120
    speed = 15.0 + 0.05 * rng.standard_normal((steps, runs))
    camera = -0.5 + 0.05 * rng.standard_normal((steps, runs))
    steering = 0.002 * rng.standard_normal((steps, runs))
    steering[:, 2] += 0.05  # run 2's steering fits one lane far better: it prunes early
    z = np.stack([speed, camera, steering], axis=-1)
    acc = 0.05 * rng.standard_normal((steps, runs, 2))
    arx = GeneralizedModel.paper().arx()
    settings = FilterSettings(  # (the aim cap off: it keeps weights far above 1e-10)
        steering_ratio=15.0, prune_threshold=1e-10 if prune else 0.0, aim_offset_std=0.0
    )
    batch = GaussianMixtureEKF(arx, settings)
    batch.reset(z[0], [0.0, -1.8])
    alone = [GaussianMixtureEKF(arx, settings) for _ in range(runs)]
    for r, f in enumerate(alone):
        f.reset(z[0, r], [0.0, -1.8])
    pruned = not prune
    for k in range(1, steps):
        est = batch.step(z[k], acc[k])
        pruned |= bool(np.isinf(est.log_weights).any())
        for r, f in enumerate(alone):
            one = f.step(z[k, r], acc[k, r])
            assert np.array_equal(one.log_weights, est.log_weights[r]), (k, r)
            assert np.array_equal(one.component_means, est.component_means[r]), (k, r)
            assert one.decision == est.decision[r], (k, r)
    assert pruned, "no run pruned a hypothesis: the test checks nothing"
