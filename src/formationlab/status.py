"""How a run, a trial or a settling ended: one vocabulary for every path.

:class:`Status` is a string enumeration, so ``result.status == "success"`` and
``json.dumps(result.status)`` work as with plain strings. Each member carries
its integer ``code`` (what the compiled kernels write into their ``int8``
status arrays) and a sentence that explains it (``status.explanation``); the
message of a particular run adds the time, the robots and what to change.
"""

from __future__ import annotations

from enum import StrEnum

import numpy as np
from numpy.typing import NDArray

__all__ = ["DIVERGED_SCALE", "Status", "status_from_codes"]


class Status(StrEnum):
    """How an integration ended."""

    #: integrated to the end of the requested duration
    SUCCESS = "success"
    #: the robots stopped moving before the end (batches and settling stop there)
    CONVERGED = "converged"
    #: a step would end with two robots in contact (r_ij <= a_ij); the last state is kept
    COLLISION = "step-collision"
    #: a step would carry two robots through each other (contact inside the step, both
    #: ends clear): the step is too large for the field, not a contact of the flow
    STEP_TOO_LARGE = "step-too-large"
    #: a step produced NaN or infinite numbers, or positions beyond about 1e154 (whose
    #: squares, and so squared distances and the law's forces, overflow)
    NON_FINITE = "non-finite"
    #: an event-driven integrator met more switching events than it allows
    EVENT_LIMIT = "event-limit"
    #: the user interrupted the run (Ctrl-C); the states so far are kept
    INTERRUPTED = "interrupted"
    #: the state grew without bound: finite, but the robots spread beyond
    #: ``DIVERGED_SCALE`` times the formation's size (judged on a batch's final states)
    DIVERGED = "diverged"

    @property
    def code(self) -> int:
        """The integer the kernels use for this status (its position in the enumeration)."""
        return _CODES[self]

    @property
    def explanation(self) -> str:
        """One sentence on what the status means."""
        return _EXPLANATIONS[self]

    @property
    def failed(self) -> bool:
        """Whether the run stopped before its end for a numerical or user reason."""
        return self not in (Status.SUCCESS, Status.CONVERGED)

    @property
    def contact(self) -> bool:
        """Whether the run was stopped by a step that reaches contact (outcome ``collision``)."""
        return self in (Status.COLLISION, Status.STEP_TOO_LARGE)

    @classmethod
    def from_code(cls, code: int) -> Status:
        """The member whose :attr:`code` is ``code``."""
        return _MEMBERS[int(code)]


_MEMBERS = tuple(Status)
_CODES = {s: c for c, s in enumerate(_MEMBERS)}
_EXPLANATIONS = {
    Status.SUCCESS: "integrated to the end",
    Status.CONVERGED: "the robots stopped moving",
    Status.COLLISION: "a step would end with two robots in contact",
    Status.STEP_TOO_LARGE: "a step would carry two robots through each other",
    Status.NON_FINITE: "a step produced NaN, infinite or overflowing positions",
    Status.EVENT_LIMIT: "too many switching events",
    Status.INTERRUPTED: "interrupted by the user",
    Status.DIVERGED: "the robots spread beyond a million times the formation's size",
}

#: A trial has diverged when its robots spread (largest distance from their centroid)
#: beyond this many times the formation's size (its largest desired distance or diameter).
DIVERGED_SCALE = 1e6


def status_from_codes(codes: NDArray[np.integer]) -> NDArray[np.object_]:
    """``Status`` members of an array of kernel codes, same shape (object array)."""
    table = np.array(_MEMBERS, dtype=object)
    return table[np.asarray(codes, dtype=np.int64)]
