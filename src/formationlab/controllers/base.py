"""The control-law contract shared by every law, and its registry.

A law is a frozen, keyword-only dataclass holding gains only; the formation
and the positions are arguments. Every law maps positions ``q`` of shape
``(..., n, 2)`` to controls ``u = q_dot`` of the same shape, using relative
positions only (so translating all robots leaves ``u`` unchanged).

Extension contract
------------------
Subclass :class:`Law`, set ``name``, implement :meth:`Law.control` and
:meth:`Law.potential`, decorate with :func:`register`. A discontinuous law
(one with switching surfaces ``sigma(q) = 0``) also implements
:meth:`Law.switching` and :meth:`Law.control_with`, which the sliding-mode
integrators use to build Filippov convex combinations; its :meth:`Law.control`
must be ``control_with(q, Upsilon(switching(q)))``, so that the on/off decision
of every restriction is made in one place, the switching functions. A law the
compiled kernels can evaluate returns its data from :meth:`Law.kernel_terms`.
"""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass
from typing import ClassVar, NamedTuple, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError
from ..formation.spec import Formation
from ..registry import Registry
from ..validation import check_fields
from .terms import KernelTerms

__all__ = [
    "LAWS",
    "Law",
    "ObstacleRepulsion",
    "Repulsion",
    "file_keys",
    "get_law",
    "laws_in",
    "register",
]


@dataclass(frozen=True, kw_only=True)
class Repulsion:
    """Khatib's repulsion ``gamma_ij`` between robots that are not neighbours.

    Parameters
    ----------
    eta : float
        Gain ``eta`` of ``gamma = eta/2 (1/s - 1/s0)^2``. Default 1.0.
    influence : float
        Range ``s0`` of the clearance ``s = r_ij - a_ij`` below which it acts.
        Default 0.5 (half the paper's desired distance of 1).
    """

    eta: float = 1.0
    influence: float = 0.5

    def __post_init__(self) -> None:
        check_fields(self, positive=("eta", "influence"))


class ObstacleRepulsion(NamedTuple):
    """How a law repels robots from static obstacles (Khatib, IJRR 5(1), 1986).

    The closed loop adds ``-gain grad_i Gamma_o`` to robot ``i``'s command, with
    ``Gamma_o = sum_i sum_o gamma(s_io)`` Khatib's repulsion on the robot-obstacle
    clearances (:func:`formationlab.safety.obstacle_potential`, parameters ``eta`` and
    ``influence`` of ``repulsion``), and ``weight Gamma_o`` to the law's Lyapunov function,
    so the run's ``V`` is still the function the law descends.
    """

    gain: float
    weight: float
    repulsion: Repulsion


@dataclass(frozen=True, kw_only=True)
class Law:
    """Base class of control laws ``u = f(q)`` for single-integrator robots (eq. 1)."""

    name: ClassVar[str] = ""
    #: Whether the closed loop is continuous; discontinuous laws expose switching surfaces.
    smooth: ClassVar[bool] = True
    #: Whether every edge's potential is infinite at contact (the paper's phi, eq. 5), so
    #: that the exact flow cannot bring two robots into contact.
    barrier_at_contact: ClassVar[bool] = False
    #: Besides translations, the motion of all robots that leaves the field unchanged:
    #: ``"rotation"`` (``u(R q) = R u(q)``: laws of distances and orientation) or
    #: ``"scale"`` (``u(s q) = u(q)``, ``s > 0``: the bearing law). Equilibria are found,
    #: merged and classified modulo it (:mod:`formationlab.equilibria`).
    invariance: ClassVar[str] = "rotation"
    #: The spaces the law works in (``Formation.dim``), and what to use in the others.
    dims: ClassVar[tuple[int, ...]] = (2, 3)
    elsewhere: ClassVar[str] = ""
    #: The spaces in which robots that sense (:mod:`formationlab.sensing`) compute their own
    #: commands from the law's kernel terms (:meth:`sensed_terms`): the plane for every law
    #: with kernel terms; space for a law whose every term is an edge's or a pair's, a
    #: function of one measured relative position and its length (the laws of distances).
    sensed_dims: ClassVar[tuple[int, ...]] = (2,)
    #: The spaces in which the compiled loop (:mod:`formationlab.engine.loop`) steps the law
    #: (:meth:`compiled_terms`): the plane for every law with kernel terms; space for a law
    #: whose every term is an edge's along ``r_ij`` or Khatib's repulsion of a pair (the laws
    #: of distances); the others run on the numpy path there.
    compiled_dims: ClassVar[tuple[int, ...]] = (2,)
    #: Whether the law is built from its gains alone (its defaults run); False for a law
    #: that needs a file (the learned law's parameters), which :func:`laws_in` leaves out.
    from_gains: ClassVar[bool] = True

    def formation_for(self, formation: Formation) -> Formation:
        """The formation as this law is judged on it: a law of distances (and orientation)
        drops desired bearings (:attr:`Formation.bearings`), so that outcomes count its
        distances; the bearing law keeps or derives them. Every closed loop
        (:class:`formationlab.dynamics.System`, the batches) holds this formation.
        Refuses a formation in a space the law does not work in (:attr:`dims`)."""
        self.check_dim(formation)
        return formation.without_bearings()

    def check_dim(self, formation: Formation) -> None:
        """Refuse, by name, a formation in a space the law does not work in."""
        if formation.dim not in self.dims:
            space = {2: "in the plane", 3: "in space (3-D)"}
            raise ParameterError(
                f"the law {self.name!r} works {' and '.join(space[d] for d in self.dims)}, "
                f"and this formation is {space[formation.dim]}"
                + (f": {self.elsewhere}" if self.elsewhere else "")
            )

    def control(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Controls ``u``, shape ``(..., n, 2)``, at positions ``q`` of shape ``(..., n, 2)``."""
        raise NotImplementedError

    def potential(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """The law's Lyapunov function at ``q``; shape ``(...)``."""
        raise NotImplementedError

    def switching(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Switching functions ``sigma``, shape ``(..., s)``; a surface is ``sigma = 0``.

        A smooth law has none (``s = 0``).
        """
        return np.zeros((*np.shape(q)[:-2], 0))

    def control_with(
        self, formation: Formation, q: NDArray[np.float64], weights: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Controls with the step of each switching function replaced by ``weights`` in [0, 1].

        ``weights`` has the shape of :meth:`switching`. For a smooth law it is ignored.
        """
        return self.control(formation, q)

    def obstacle_repulsion(self) -> ObstacleRepulsion:
        """The gain, potential weight and Khatib parameters of the law's obstacle repulsion.

        The paper's laws use their repulsion gain: ``k_c`` for the distance and
        angle-restricted laws, ``k_r`` for the squared-distance and signed-area laws.
        A law without one refuses obstacles.
        """
        raise ParameterError(
            f"the law {self.name!r} ({type(self).__name__}) has no obstacle repulsion; "
            "implement Law.obstacle_repulsion or run it without obstacles"
        )

    def kernel_terms(self, formation: Formation, *, pairs: bool = True) -> KernelTerms:
        """The law as the arrays the compiled kernels step (:mod:`.terms`).

        ``pairs=False`` leaves out the batch kernel's all-pairs arrays (the compiled
        single run lists its pairs itself). Laws the kernels cannot evaluate keep this
        default, which says so; they run on the numpy path (``run_batch(...,
        backend="numpy")``).
        """
        raise ParameterError(
            f"the compiled kernel cannot run the law {self.name!r} ({type(self).__name__}); "
            'use backend="numpy"'
        )

    def compiled_terms(self, formation: Formation, *, pairs: bool = True) -> KernelTerms:
        """:meth:`kernel_terms`, refused when they cannot describe this law's control.

        A subclass that overrides :meth:`control` without overriding
        :meth:`kernel_terms` would otherwise inherit terms of another law.
        """

        if formation.dim not in self.compiled_dims:
            able = sorted(n for n, c in LAWS.items() if formation.dim in c.compiled_dims)
            raise ParameterError(
                f"the compiled loop steps formations in space under the laws "
                f"{', '.join(repr(a) for a in able)}; the law {self.name!r} runs there on the "
                'numpy path (backend="numpy", which "auto" chooses)'
            )
        return self._own_terms(formation, pairs=pairs)

    def sensed_terms(self, formation: Formation) -> KernelTerms:
        """The terms every robot's own command is computed from
        (:func:`formationlab.sensing.local_controls`, with pair arrays).

        In the plane :meth:`compiled_terms`; in space the kernel terms of a law that works
        there on its own measurements (:attr:`sensed_dims`), refused by name otherwise.
        """
        if formation.dim == 2:
            return self.compiled_terms(formation)
        if formation.dim not in self.sensed_dims:
            able = sorted(n for n, c in LAWS.items() if formation.dim in c.sensed_dims)
            raise ParameterError(
                f"robots that sense each other in space (the [sensing] table) run the laws "
                f"{', '.join(repr(a) for a in able)}; the law {self.name!r} computes its "
                "robots' own commands in the plane only so far: run it without [sensing]",
                key="sensing",
            )
        return self._own_terms(formation, pairs=True)

    @classmethod
    def compiles(cls) -> bool:
        """Whether the compiled loop can run the law: it has :meth:`kernel_terms` of its own,
        written where its :meth:`control` is (not inherited from another law). A law that
        does not compiles runs on the numpy path
        (:func:`formationlab.studies.batch.batch_backend`)."""

        def owner(name: str) -> type:
            return next(c for c in cls.__mro__ if name in c.__dict__)

        return owner("kernel_terms") is owner("control") and owner("kernel_terms") is not Law

    def _own_terms(self, formation: Formation, *, pairs: bool) -> KernelTerms:
        """:meth:`kernel_terms`, refused when they are another law's (``control`` overridden
        without them)."""

        if not self.compiles() and type(self).kernel_terms is not Law.kernel_terms:
            raise ParameterError(
                f"the law {self.name!r} ({type(self).__name__}) overrides control() but not "
                'kernel_terms(), so the compiled kernel cannot run it; use backend="numpy"'
            )
        if "pairs" not in inspect.signature(type(self).kernel_terms).parameters:
            return self.kernel_terms(formation)  # a law written before the keyword
        return self.kernel_terms(formation, pairs=pairs)

    def with_params(self, **params: float) -> Law:
        """A copy with some parameters changed (validated again)."""
        from dataclasses import replace

        return replace(self, **params)


#: The laws by name (as in scenario files); case-insensitive, with did-you-mean suggestions.
LAWS: Registry[Law] = Registry("law")
L = TypeVar("L", bound=type[Law])


def register(cls: L) -> L:
    """Class decorator: make a law available by its ``name``."""
    return LAWS.register(cls)


def file_keys(law: type[Law] | Law) -> tuple[str, ...]:
    """The parameters of a law that name files (fields marked ``metadata={"path": True}``,
    e.g. the learned law's ``parameters``): a scenario reads them relative to its own file,
    and an output folder keeps a copy of each."""
    if not dataclasses.is_dataclass(law):
        return ()
    return tuple(f.name for f in dataclasses.fields(law) if f.metadata.get("path"))


def laws_in(dim: int) -> list[str]:
    """The names of the registered laws that work in ``dim`` dimensions (2 or 3) and are
    built from their gains alone (:attr:`Law.from_gains`: not the learned law, which needs
    its parameters file), sorted."""
    return sorted(name for name, cls in LAWS.items() if dim in cls.dims and cls.from_gains)


def get_law(name: str, **params: object) -> Law:
    """The law registered as ``name`` (any case), built with ``params``.

    A parameter of another law is ignored with an
    :class:`~formationlab.errors.IgnoredKeyWarning`; an unknown one is an error.
    """
    return LAWS.build(name, **params)
