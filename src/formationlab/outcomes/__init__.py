"""Outcomes: how a run or a batch of trials ended, and what its final motion is.

* :mod:`.tolerances`: the outcomes' names and the :class:`~.tolerances.Tolerances` that
  decide between them;
* :mod:`.analysis`: one run's outcome, distance errors, convergence time and net speed;
* :mod:`.batch`: the outcomes of a batch of trials at once;
* :mod:`.rigid_motion`: the best rigid motion between two configurations (drifting and
  rotating formations).
"""
