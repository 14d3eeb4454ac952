"""One step of ``B`` formations under given commands, on the compiled loop's stages.

A learning environment replaces the law's field by the commands of a policy
(:mod:`formationlab.envs.vector`): per step the model's stage turns each robot's command
into its state's rate (:func:`formationlab.models.stage.rates`, with the model's limits;
unicycles' ``cos theta`` and ``sin theta`` from :func:`~formationlab.models.stage.headings`),
the faults hold the stopped robots (the host zeroes their rates, as
:func:`formationlab.sensing.stage.halt` does with one time for all trials: here every
formation has its own), and the explicit Euler step (:func:`.euler.euler`) is judged by the
contact rule (:func:`.contact.contact`, :func:`.contact.verdict`). These are the functions
the batch loop (:func:`.loop.step_chunk`) calls at its stages 5 and 8; what this module
leaves out of that loop is what an environment does on the host or not at all: the law,
the stop rule (an environment ends an episode by its own rule) and the compaction of
finished trials (an environment resets them instead). States are the loop's layout,
``(n, k, B)`` with the formations innermost.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..models.stage import headings, rates
from ..models.terms import HEADING, NEAR_IDENTITY
from .contact import contact, verdict
from .euler import PLANE, euler

__all__ = ["commanded_rates", "commanded_step"]


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def commanded_rates(x, u, f, model):
    """``f = x_dot`` ``(n, k, B)`` of states ``x`` under commands ``u`` ``(n, 2, B)``.

    ``u`` is in the common frame, at the law's points (``System.rhs_commanded`` takes it
    so): :func:`formationlab.models.stage.rates`, with the model's limits.
    """
    n = x.shape[0]
    B = x.shape[2]
    turns = model.kind == NEAR_IDENTITY or model.kind == HEADING
    hc = np.empty((n, B) if turns else (1, 1))
    hs = np.empty_like(hc)
    if turns:  # the library's cos and sin of each heading (nothing carried between calls)
        headings(x, hc, hs, np.empty_like(hc), np.empty_like(hc), B)
    rates(x, hc, hs, u, f, np.empty(B), B, model, PLANE)


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def commanded_step(x, f, xn, dt, terms, code):
    """``xn = x + dt f`` for ``B`` formations, each step judged by the contact rule.

    ``terms``: the law's :class:`~formationlab.controllers.terms.KernelTerms` (its pairs
    and contact distances ``a_ij``). ``code[b]`` becomes 0 for an accepted step, else the
    rejecting ``Status.code`` (:func:`.contact.verdict`); a rejected step's ``xn`` is not
    meant to be kept. Returns the pairs' lengths ``(P, B)`` at ``xn``.
    """
    n = x.shape[0]
    B = x.shape[2]
    disp = np.zeros(B)
    fin = np.zeros(B)
    gap = np.empty(B)
    swept = np.empty(B)
    near = np.empty(B)
    rr = np.empty((terms.pair_i.shape[0], B))
    euler(x, f, xn, dt, 0, n, B, disp, fin, PLANE)  # (the environments are planar)
    for b in range(B):
        disp[b] = math.sqrt(disp[b])
    contact(xn, x, disp, gap, swept, near, B, terms, rr, PLANE)
    for b in range(B):
        code[b] = verdict(fin[b], gap[b], swept[b])
    return rr
