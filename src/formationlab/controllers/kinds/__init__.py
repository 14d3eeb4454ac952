"""Kinds of term: each formula of the laws written once, for numpy and for compiled loops.

A law is its gains plus the kinds of term it composes (as JAX MD composes pair energies
over neighbour lists). Each kind is a module here with its formulas as plain functions of
numbers: the numpy laws call them on arrays (elementwise, so the same arithmetic), and the
compiled loops call them on scalars, where numba compiles them inline (:func:`formula`).
The robots' own-frame commands (:mod:`formationlab.sensing.local`) call them too. So a
formula such as ``k_c phi'(r) / r`` exists once in the package, with its equation cited
on its line.

============================  ====================================================
:mod:`.log_barrier`           the paper's edge potential ``phi_ij`` (eqs. 5, 7, 8)
:mod:`.squared_distance`      Krick et al.'s ``1/4 (r^2 - d^2)^2``
:mod:`.edges`                 an edge's force factor, by its potential's integer kind
:mod:`.khatib`                Khatib's repulsion ``gamma`` (robots and obstacles)
:mod:`.restriction`           the angular restriction of eqs. (13), (14), (23)
:mod:`.signed_area`           the signed-area penalty (Anderson et al. 2017)
============================  ====================================================

A formula takes and returns numbers only (no allocation, no branch that numpy arrays
could not take, or a branch written as arithmetic), so that both worlds run it. A law
with a new kind of term adds a module here and the loop over its items in the law's own
module; see docs/architecture.md ("How to add").
"""

from __future__ import annotations

from ..._jit import formula

__all__ = ["formula"]
