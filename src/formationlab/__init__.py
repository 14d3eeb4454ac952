"""formationlab: distance-based multi-robot formation control with angular restrictions.

Implements "Formation Control of Multiple Robots Avoiding Local Minima"
(single-integrator robots, logarithmic attractive-repulsive potential, Khatib
repulsion, and the angle-restricted sliding-mode law) and goes beyond it.

Examples
--------
>>> import formationlab as fl
>>> f = fl.Formation.from_template([[0, 0], [1, 0], [0.5, 0.8]], diameters=0.2)
>>> law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
>>> res = fl.simulate(f, law, [[-3, -3], [3, -3], [0, 3]], duration=15.0)
>>> res.outcome(), str(res.status)
('desired', 'success')
"""

from . import (
    _command_start,  # noqa: F401 - Ctrl-C while the command starts: no traceback
    _numba_cache,  # noqa: F401 - checks numba's cache before any kernel is imported
)
from .controllers import (
    LAWS,
    AngleRestrictedLaw,
    BearingLaw,
    ChiralityRestrictedLaw,
    DistanceLaw,
    Law,
    Repulsion,
    get_law,
)
from .controllers.potentials import dphi_dr, khatib, phi, psi, triple_products
from .dynamics import SingleIntegrator, System
from .formation.graphs import build_edges
from .formation.spec import Formation, FormationError
from .formation.templates import lattice
from .integrators import (
    INTEGRATORS,
    RK4,
    Euler,
    Filippov,
    ImplicitEuler,
    Integrator,
    get_integrator,
)
from .outcomes.analysis import OUTCOMES, Tolerances, classify, distance_errors, triangle_orientation
from .resources import package_version
from .sensing import Faults, Sensing, Stop
from .simulation.run import SimulationResult, simulate

__version__ = package_version()


def __getattr__(name: str) -> object:
    """``fl.Viewer``, the notebook widget, imported on first use (it needs the ``view`` extra);
    ``fl.robotarium_script``, a scenario as a Robotarium controller (docs/robots.md)."""
    if name == "Viewer":
        from .viewer.widget import Viewer  # anywidget, the view extra: when asked for

        return Viewer
    if name == "robotarium_script":
        from .io.robotarium import robotarium_script  # start-up time: scenario files, scipy

        return robotarium_script
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "INTEGRATORS",
    "LAWS",
    "OUTCOMES",
    "RK4",
    "AngleRestrictedLaw",
    "BearingLaw",
    "ChiralityRestrictedLaw",
    "DistanceLaw",
    "Euler",
    "Faults",
    "Filippov",
    "Formation",
    "FormationError",
    "ImplicitEuler",
    "Integrator",
    "Law",
    "Repulsion",
    "Sensing",
    "SimulationResult",
    "SingleIntegrator",
    "Stop",
    "System",
    "Tolerances",
    "__version__",
    "build_edges",
    "classify",
    "distance_errors",
    "dphi_dr",
    "get_integrator",
    "get_law",
    "khatib",
    "lattice",
    "phi",
    "psi",
    "robotarium_script",
    "simulate",
    "triangle_orientation",
    "triple_products",
]
