"""A message bus with the delay and loss models of :class:`~formationlab.sensing.Sensing`.

Everything the robots of an asynchronous run learn reaches them as a :class:`Message`
(topic, sender, recipient, time stamp, payload) through a :class:`Bus`:

* a message stamped ``s`` is delivered at ``s + delay`` (``Sensing.delay``, seconds; any
  non-negative number, not only a multiple of a step), so delivery keeps the order of
  sending;
* a message is lost with probability ``drop`` (``Sensing.drop``), drawn from the
  recipient's own generator, so one robot's losses do not depend on what the others
  receive; a message published with ``lossy=False`` is never lost;
* :meth:`Bus.latest` gives a recipient, per sender, the newest message of a topic
  delivered by now. A lost message never arrives, so the last one received stays in
  place.

The bus does not know what payloads mean: the runner publishes measurements on the
topic ``"relative-position"``, and any other topic (a neighbour's heading, its command)
travels the same way.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["TIE", "Bus", "Message"]

#: times within this many seconds count as equal (a delivery due "now" has arrived)
TIE = 1e-12


@dataclass(frozen=True, kw_only=True)
class Message:
    """One message on the bus.

    Attributes
    ----------
    topic : str
        What it is about (``"relative-position"`` for a measurement).
    sender : int
        0-based robot it comes from (for a measurement: the robot measured).
    recipient : int
        0-based robot it goes to.
    stamp : float
        When it was sent (for a measurement: when it was taken), seconds.
    payload : object
        What it carries; None for "nothing to report" (a robot out of range).
    """

    topic: str
    sender: int
    recipient: int
    stamp: float
    payload: Any = None


class Bus:
    """Messages between ``n`` robots with a delay and losses (module docstring).

    Parameters
    ----------
    n : int
        Robots (recipients ``0 .. n-1``).
    delay : float
        Seconds from sending to delivery.
    drop : float
        Probability in ``[0, 1)`` that a lossy message is lost.
    rngs : sequence of numpy.random.Generator
        One per recipient, the losses of its messages.
    """

    def __init__(
        self, n: int, *, delay: float, drop: float, rngs: Sequence[np.random.Generator]
    ) -> None:
        if len(rngs) != n:
            raise ValueError(f"the bus needs one generator per robot: {len(rngs)} for {n}")
        self.n, self.delay, self.drop, self._rngs = n, float(delay), float(drop), list(rngs)
        self._pending: dict[tuple[int, str], deque[Message]] = {}
        self._held: dict[tuple[int, str], dict[int, Message]] = {}
        self.sent = 0
        self.lost = 0

    def publish(self, message: Message, *, lossy: bool = True) -> bool:
        """Send ``message``; False when it is lost (it will never be delivered)."""
        self.sent += 1
        if lossy and self.drop > 0 and self._rngs[message.recipient].random() < self.drop:
            self.lost += 1
            return False
        key = (message.recipient, message.topic)
        self._pending.setdefault(key, deque()).append(message)
        return True

    def latest(self, recipient: int, topic: str, now: float) -> dict[int, Message]:
        """The newest message of ``topic`` from each sender delivered to ``recipient`` by ``now``.

        Delivered means ``stamp + delay <= now`` (to :data:`TIE`). A sender from which
        nothing has arrived is absent.
        """
        key = (recipient, topic)
        held = self._held.setdefault(key, {})
        queue = self._pending.get(key)
        while queue and queue[0].stamp + self.delay <= now + TIE:
            m = queue.popleft()
            held[m.sender] = m
        return held
