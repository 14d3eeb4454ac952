"""Robots that sense their neighbours: local frames, noise, delay, losses, mismatch, faults.

* :mod:`.config`: the ``[sensing]`` and ``[faults]`` tables (:class:`Sensing`,
  :class:`Faults`, :class:`Stop`);
* :mod:`.local`: every robot's command from its own measurements, in its own frame
  (:func:`local_controls`), from the law's kernel terms;
* :mod:`.channel`: what the robots of a batch of trials measure, step by step
  (:class:`Channel`).

The closed loop (:class:`formationlab.System`) takes a :class:`Sensing` and
:class:`Faults`; the stepping driver makes the channel of its trials.
"""

from .channel import BLOCK, SENSING_LIMIT, Channel, Seed
from .config import FRAMES, Faults, Sensing, Stop, delay_ring, delay_steps
from .local import from_frames, local_controls, measured, rotate, to_frames, uniform_rotations

__all__ = [
    "BLOCK",
    "FRAMES",
    "SENSING_LIMIT",
    "Channel",
    "Faults",
    "Seed",
    "Sensing",
    "Stop",
    "delay_ring",
    "delay_steps",
    "from_frames",
    "local_controls",
    "measured",
    "rotate",
    "to_frames",
    "uniform_rotations",
]
