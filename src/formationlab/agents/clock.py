"""Simulated time for asyncio tasks: a deterministic scheduler of wake-ups.

Every robot of an asynchronous run is an asyncio task that sleeps until its next
control time with ``await clock.sleep_until(t, robot)``. Nothing waits on the wall
clock: the world coroutine asks :meth:`VirtualClock.next_time` for the earliest
pending wake-up, moves the physics there, and wakes the robots due at that time one at
a time, in robot order (ties are broken by robot number), with :meth:`VirtualClock.wake`,
which returns once the woken task is asleep again (or has finished). Only one task
runs at a time and the order is fixed, so a run is the same on every machine and as
fast as its arithmetic.
"""

from __future__ import annotations

import asyncio
import heapq
from collections.abc import Coroutine
from typing import Any

__all__ = ["VirtualClock"]


class VirtualClock:
    """The simulated time of one run and the wake-ups of its tasks (module docstring)."""

    def __init__(self) -> None:
        self.now = 0.0
        self._heap: list[tuple[float, int, int, asyncio.Future[None]]] = []
        self._count = 0  # a tie-break that keeps heap entries comparable
        self._tasks: list[asyncio.Task[None]] = []
        self._busy = 0  # tasks that run now (not asleep, not finished)
        self._idle: asyncio.Future[None] | None = None

    def start(self, coroutines: list[Coroutine[Any, Any, None]]) -> None:
        """Start the tasks; each must sleep (or return) before it does anything else."""
        loop = asyncio.get_running_loop()
        for c in coroutines:
            task = loop.create_task(c)
            task.add_done_callback(self._finished)
            self._tasks.append(task)
        self._busy = len(coroutines)

    def sleep_until(self, t: float, robot: int) -> asyncio.Future[None]:
        """A future resolved when the world's time reaches ``t`` (robots due together in order)."""
        if t < self.now:
            raise RuntimeError(f"robot {robot + 1} asked to wake at t = {t:g} s, before now")
        fut: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._heap, (t, robot, self._count, fut))
        self._count += 1
        self._settle()
        return fut

    def _finished(self, task: asyncio.Task[None]) -> None:
        self._settle()

    def _settle(self) -> None:
        self._busy -= 1
        if self._busy == 0 and self._idle is not None and not self._idle.done():
            self._idle.set_result(None)

    async def idle(self) -> None:
        """Wait until every task is asleep or finished; re-raise a task's exception."""
        if self._busy > 0:
            self._idle = asyncio.get_running_loop().create_future()
            await self._idle
        for task in self._tasks:
            if task.done() and not task.cancelled() and task.exception() is not None:
                raise task.exception()  # type: ignore[misc]

    def next_time(self) -> float | None:
        """The earliest pending wake-up, or None when no task will wake again."""
        return self._heap[0][0] if self._heap else None

    async def wake(self, t: float) -> None:
        """Set the time to ``t`` and run every task due at ``t``, one after the other."""
        self.now = t
        while self._heap and self._heap[0][0] <= t:
            _, _, _, fut = heapq.heappop(self._heap)
            self._busy = 1
            fut.set_result(None)
            await self.idle()

    async def close(self) -> None:
        """Cancel the tasks still asleep (a run that ended early) and wait for them."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
