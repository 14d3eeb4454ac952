"""Safety filters and obstacles: barrier certificates that minimally change the commands.

The barrier certificate of Wang, Ames and Egerstedt ("Safety barrier certificates
for collisions-free multirobot systems", IEEE Transactions on Robotics 33(3), 2017),
centralized (one sparse QP, Clarabel) and decentralized (each robot half the
responsibility per pair, exact 2-D projection in numba; in space each robot's 3-D QP by
the dual active set); static circle and polygon obstacles in the plane, sphere and box
obstacles in space, with clearances, Khatib repulsion and barrier rows; the near-identity
point of unicycles. See ``docs/safety.md``.

This package depends on ``potentials`` and ``errors`` only, so laws and models can use it.
"""

from ..errors import require_extra
from .barrier import (
    BarrierConstraints,
    QPSolution,
    barrier_constraints,
    barrier_filter,
    pair_barrier_rows,
    solve_barrier_qp,
)
from .condition import CONDITIONS, barrier_bound, barrier_bounds
from .config import FILTERS, SafetyFilter
from .contact import segment_distances, swept_clearances
from .decentralized import (
    decentralized_commands,
    decentralized_filter,
    decentralized_reference,
    project_onto_halfplanes,
)
from .obstacles import (
    Circle,
    Obstacle,
    Polygon,
    check_obstacle_starts,
    clearances,
    grad_obstacle_potential,
    obstacle_barrier_rows,
    obstacle_contacts,
    obstacle_from_mapping,
    obstacle_potential,
)
from .pairs import neighbour_lists, sensed_pairs
from .record import SafetyRecord, describe_obstacle
from .result import FilterResult, FilterStatus
from .solids import Box, Sphere
from .unicycle import (
    point_safety_distance,
    point_to_unicycle,
    point_velocity,
    unicycle_points,
    unicycle_velocity,
)


def check_extra() -> None:
    """Raise :class:`~formationlab.errors.MissingExtraError` naming ``formationlab[safety]``
    unless the extra's solvers and geometry (qpsolvers, Clarabel, shapely) import.

    The package imports without them; a scenario with obstacles or a filter checks here first.
    """
    require_extra("safety", ("qpsolvers", "clarabel", "shapely"), "safety filters and obstacles")


__all__ = [
    "CONDITIONS",
    "FILTERS",
    "BarrierConstraints",
    "Box",
    "Circle",
    "FilterResult",
    "FilterStatus",
    "Obstacle",
    "Polygon",
    "QPSolution",
    "SafetyFilter",
    "SafetyRecord",
    "Sphere",
    "barrier_bound",
    "barrier_bounds",
    "barrier_constraints",
    "barrier_filter",
    "check_extra",
    "check_obstacle_starts",
    "clearances",
    "decentralized_commands",
    "decentralized_filter",
    "decentralized_reference",
    "describe_obstacle",
    "grad_obstacle_potential",
    "neighbour_lists",
    "obstacle_barrier_rows",
    "obstacle_contacts",
    "obstacle_from_mapping",
    "obstacle_potential",
    "pair_barrier_rows",
    "point_safety_distance",
    "point_to_unicycle",
    "point_velocity",
    "project_onto_halfplanes",
    "segment_distances",
    "sensed_pairs",
    "solve_barrier_qp",
    "swept_clearances",
    "unicycle_points",
    "unicycle_velocity",
]
