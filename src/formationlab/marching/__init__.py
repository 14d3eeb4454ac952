"""A formation on the move: a reference velocity for every robot, a leader, or motion parameters.

* :mod:`.config`: the three ways to march (:class:`Marching` with or without a leader,
  :class:`MotionParameters`) and the metrics of a marching run;
* :mod:`.terms` and :mod:`.stage`: marching as a stage of the compiled loop
  (:mod:`formationlab.engine.loop`).

The closed loop (:class:`formationlab.System`) takes a :data:`March`; its
:meth:`~formationlab.System.command` adds it to the law's control.
"""

from .config import (
    March,
    Marching,
    MotionParameters,
    centroid_velocity,
    heading_spread,
    shape_realization,
)

__all__ = [
    "March",
    "Marching",
    "MotionParameters",
    "centroid_velocity",
    "heading_spread",
    "shape_realization",
]
