"""A learned law run as a study runs it: the fractions stored with its parameters.

:func:`evaluate_policy` is ``formationlab study`` of the training scenario with the law
swapped for the learned one (``law = "policy"``), ``trials`` trials of study seed
``seed``, on the numpy path; ``formationlab study`` of a scenario naming the saved
parameters file gives the same fractions with the same seed (tests/test_learning.py).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from ..controllers.policy import PolicyLaw
from ..scenario.parse import Scenario
from ..studies.config import StudyConfig, parse_study
from ..studies.runner import StudySetup, run_study

__all__ = ["evaluate_policy", "study_config"]


def study_config(scenario: Scenario, trials: int) -> StudyConfig:
    """The scenario's ``[study]`` table with ``trials`` trials, no sweep and one law."""
    config = parse_study(scenario.study, source=scenario.source, text=scenario.text)
    return config.model_copy(update={"trials": trials, "laws": None, "sweep": {}})


def evaluate_policy(
    scenario: Scenario, law: PolicyLaw, *, trials: int, seed: int
) -> dict[str, Any]:
    """The study's summary of ``law`` on ``scenario``'s formation and starts.

    Returns
    -------
    dict
        The group's entry of ``summary.json`` (``fractions``, ``counts``, ``ci95``,
        ``median_converged_time``, ...), with ``seed`` and ``trials``.
    """
    config = study_config(scenario, trials)
    setup = StudySetup.from_scenario(scenario, config)
    setup = dataclasses.replace(setup, law=law, laws={law.name: law})
    result = run_study(setup, seed=seed)
    (group,) = result.summary["groups"]
    return {**group, "seed": seed}
