"""Robots as agents: each robot acting on its own view of the formation.

* :mod:`.asynchronous`: every robot an asyncio task with its own control period and
  jitter, exchanging measurements over a bus with delay and losses (:func:`run_async`).
"""

from .asynchronous import AsyncResult, arun, run_async
from .bus import Bus, Message

__all__ = ["AsyncResult", "Bus", "Message", "arun", "run_async"]
