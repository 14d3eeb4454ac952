"""Explicit-Euler trajectories of the paper's runs are what they were before the stepping core.

The final positions below were recorded, to full precision, with the per-run Euler loop that
the batched stepping driver replaced (``PaperSetup()``: rho = 0.2, dt = 1e-3, 10 s). The driver
must reproduce them bit for bit: the same arithmetic, step by step.
"""

import numpy as np
import pytest

from formationlab.paper import PaperSetup

BEFORE = {
    (1, 0.0): [
        -0.49999999999999434, -1.2886751345948408, 0.49999999999999434,
        -1.2886751345948408, 0.0, -0.42264973081039287,
    ],
    (2, 1e-6): [
        0.5755753416005244, -0.9547590540379507, -0.24860736230588285,
        -1.5210830519238934, -0.3269669792946475, -0.5241578940381976,
    ],
    (2, 0.0): [
        -0.313907215665713, -1.18123887358757, 0.313907215665713,
        -1.18123887358757, 0.0, -0.6375222528248402,
    ],
}  # fmt: skip


@pytest.mark.parametrize(("simulation", "perturbation"), list(BEFORE))
def test_paper_runs_are_unchanged_to_the_last_bit(simulation, perturbation):
    result = PaperSetup().run(simulation, perturbation=perturbation)
    np.testing.assert_array_equal(result.q[-1].ravel(), np.array(BEFORE[simulation, perturbation]))
    assert result.status == "success"
