"""Monte-Carlo studies: how often does each law reach the desired formation?

* :mod:`~formationlab.studies.config`: the ``[study]`` table of a scenario;
* :mod:`~formationlab.studies.sampling`: random initial states, seeded by trial number;
* :mod:`~formationlab.studies.groups`: laws x sweep points;
* :mod:`~formationlab.studies.chunks`: the unit of work, one call of the kernel;
* :mod:`~formationlab.studies.executors`: this process, a process pool, or dask.distributed;
* :mod:`~formationlab.studies.runner`: :func:`run_study`, resume, the summary;
* :mod:`~formationlab.studies.summary`: outcome fractions and Wilson intervals;
* :mod:`~formationlab.studies.batch`: the batched kernel every chunk calls;
* :mod:`~formationlab.studies.paper`: the reproduction of the paper's section 4
  (``formationlab paper``): its simulations, the symmetry scan and the diameter scan.
"""

from .batch import BatchResult, run_batch
from .config import StudyConfig, parse_study
from .runner import StudyResult, run_study, study_groups
from .sampling import trial_initial_states
from .summary import wilson_interval

__all__ = [
    "BatchResult",
    "StudyConfig",
    "StudyResult",
    "parse_study",
    "run_batch",
    "run_study",
    "study_groups",
    "trial_initial_states",
    "wilson_interval",
]
