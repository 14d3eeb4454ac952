"""A scenario as a controller script for the Robotarium, scaled to its arena.

The Robotarium (Pickem et al., "The Robotarium: a remotely accessible swarm robotics
research testbed", ICRA 2017; simulator: github.com/robotarium/robotarium_python_simulator,
module ``rps``) runs a Python script on up to 50 differential-drive robots in an arena of
3.2 m x 2 m. :func:`robotarium_script` writes such a script for a scenario: it imports numpy
and ``rps`` only, holds the scenario's law with every number written as a literal constant
at its top (:mod:`.robotarium_code` has its text), limits each robot's speed and turn rate
(both wheels within 0.2 m/s), moves the law's points with the Robotarium's own
single-integrator barrier certificate (with the arena's walls) and its near-identity map to
unicycles, and stops when the formation is reached or its step budget ends. The script
cannot import formationlab, so its text writes the laws' formulas a second time;
``tests/test_robotarium.py`` holds them against the package's laws on random states.

Scaling (:func:`robotarium_plan`). Every length of the law is multiplied by one factor
``sigma`` (distances, diameters, the template, Khatib's range ``s0``) and the gains so that
``u'(sigma q) = sigma u(q)`` (:func:`scaled_law`): the scaled closed loop is the scenario's,
``sigma`` times smaller, on the same clock (``q'(t) = sigma q(t)`` for single integrators;
``tests/test_robotarium.py`` checks it for every law). ``sigma`` is the largest factor with
which the start and the formation fit in the arena, ``WALL_MARGIN`` from its walls; when it
would bring two neighbours closer than ``DISTANCE_MARGIN`` times the barrier's safety radius,
the formation takes the smallest factor that keeps them apart and the start its own factor.
The start's bounding box is centred on the arena; the formation ends around the start's
centroid, which every law keeps.

What the testbed cannot honour is refused by name (a formation in space, more than 50
robots, double integrators or quadrotors, a unicycle's heading map, marching, obstacles,
sensing, faults, asynchronous robots, a law without a scaling here); a scenario's
``[safety]`` table and integrator are replaced by the Robotarium's certificate and its
0.033 s steps, with a warning and a note.
"""

from __future__ import annotations

import dataclasses
import math
import os
import textwrap
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path

from ..controllers import Law
from ..controllers.signed_area import desired_areas
from ..formation.spec import Formation
from ..integrators import Euler
from ..models import get_model
from ..resources import package_version
from ..safety import SafetyFilter
from ..scenario.parse import Scenario
from ..simulation.run import SimulationResult, simulate
from .robotarium_code import MAIN, law_function
from .scenario import load_scenario

__all__ = [
    "ARENA",
    "MAX_ROBOTS",
    "RobotariumPlan",
    "robotarium_plan",
    "robotarium_script",
    "scaled_law",
    "twin_simulation",
]

#: the arena: x in [-1.6, 1.6], y in [-1, 1] (rps ``RobotariumABC.boundaries``)
ARENA = (-1.6, 1.6, -1.0, 1.0)
#: the most robots the Robotarium runs (rps asserts 0 <= number_of_robots <= 50)
MAX_ROBOTS = 50
#: rps ``time_step``, s; ``max_linear_velocity``, m/s; ``base_length`` (axle), m
TIME_STEP = 0.033
MAX_WHEEL_SPEED = 0.2
BASE_LENGTH = 0.105
#: the near-identity point's distance ahead of the centre (rps ``create_si_to_uni_mapping``)
PROJECTION_DISTANCE = 0.05
#: the barrier certificate's gain (rps default) and safety radius between points, m: the
#: testbed counts a collision when discs of 0.135 m, 0.025 m ahead of the centres, touch;
#: points 0.05 m ahead and 0.2 m apart keep those 0.2 - 2 (0.05 - 0.025) = 0.15 m apart
BARRIER_GAIN = 100.0
SAFETY_RADIUS = 0.2
#: the unicycles' limits, v and omega scaled down together (formationlab's
#: ``limit_unicycle``, the unicycle model's ``max_speed`` and ``max_turn_rate``):
#: |v| + BASE_LENGTH |omega| / 2 = 0.1 + 0.09975 keeps both wheels within 0.2 m/s, and omega
#: within the Robotarium's 3.6 rad/s, so that no later limit of rps changes a command
MAX_SPEED = 0.1
MAX_TURN_RATE = 1.9
#: the start's centres stay this far from the walls, m
WALL_MARGIN = 0.2
#: the smallest desired distance is at least this many safety radii
DISTANCE_MARGIN = 1.25
#: the stop rule's largest distance error, m
TOLERANCE = 0.01

#: per law, each gain's power of sigma in the scaled law (module docstring); Khatib's
#: ``eta`` scales by sigma^2 and its range by sigma in every law
_POWERS: dict[str, dict[str, int]] = {
    "distance": {"k_c": 2},
    "angle-restricted": {"k_c": 2, "k_a": 0, "theta": 2},
    "squared-distance": {"k": -2, "k_r": 2},
    "signed-area": {"k": -2, "k_s": 0, "k_r": 2},
    "bearing": {"k": 1, "k_r": 2},
}

#: each law's edge term, other terms, gains (script name: the law's field) and equation
_TERMS: dict[str, tuple[str, tuple[str, ...], str, str]] = {
    "distance": ("log-barrier", ("repulsion",), "k_c", "u_i = -k_c grad_i phi_i (eq. 8)"),
    "angle-restricted": (
        "log-barrier", ("repulsion", "restriction"), "k_c",
        "u_i = -k_c grad_i phi_i - k_a grad_i psi_i (eq. 11)",
    ),
    "squared-distance": (
        "squared", ("repulsion",), "k_r", "u = -k grad V - k_r grad Gamma (Krick et al. 2009)",
    ),
    "signed-area": (
        "squared", ("repulsion", "area"), "k_r",
        "u = -k grad (V_d + k_s V_A) - k_r grad Gamma (Anderson et al. 2017)",
    ),
    "bearing": (
        "bearing", ("repulsion",), "k_r",
        "u_i = -k sum_j P_(g_ij) g*_ij - k_r grad_i Gamma (Zhao and Zelazo 2016, eq. 11)",
    ),
}  # fmt: skip


def scaled_law(law: Law, sigma: float) -> Law:
    """``law`` for the formation ``sigma`` times larger: ``u'(sigma q) = sigma u(q)``.

    A gain multiplies a term that is homogeneous of some degree in the lengths; it takes the
    power of ``sigma`` that makes the term scale as ``sigma`` (``phi`` of eq. 5 is
    scale-free, so ``k_c`` scales by ``sigma^2``; ``theta`` compares with ``c_ijk``, an area,
    so by ``sigma^2``; Krick's term is cubic, so ``k`` by ``sigma^-2``; Khatib's ``gamma``
    stays the same function of the scaled clearance with ``eta sigma^2`` and ``s0 sigma``).
    """
    powers = _POWERS[law.name]
    change = {name: getattr(law, name) * sigma**p for name, p in powers.items()}
    rep = law.repulsion  # type: ignore[attr-defined]
    change["repulsion"] = dataclasses.replace(
        rep, eta=rep.eta * sigma**2, influence=rep.influence * sigma
    )
    return dataclasses.replace(law, **change)


def scaled_formation(formation: Formation, sigma: float) -> Formation:
    """The same formation ``sigma`` times larger (distances, diameters, template; bearings
    and alpha are unchanged)."""
    t = None if formation.template is None else formation.template * sigma
    return dataclasses.replace(
        formation, diameters=formation.diameters * sigma, distances=formation.distances * sigma,
        template=t,
    )  # fmt: skip


def _extent(formation: Formation) -> float:
    """An upper bound of the distance from the formation's centroid to any robot: exact with a
    template, else the longest shortest path through the desired distances (by the triangle
    inequality, no two robots end farther apart)."""
    if formation.template is not None:
        t = formation.template
        return float(np.max(np.linalg.norm(t - t.mean(axis=0), axis=1)))
    e, n = formation.edges, formation.n
    graph = csr_matrix((formation.distances, (e[:, 0], e[:, 1])), shape=(n, n))
    far = shortest_path(graph, directed=False)
    return float(np.max(far[np.isfinite(far)]))


@dataclass(frozen=True, kw_only=True)
class RobotariumPlan:
    """A scenario as the Robotarium runs it (:func:`robotarium_plan`).

    Attributes
    ----------
    scenario : Scenario
        The scenario as given.
    formation : Formation
        Scaled by ``sigma``, as the law judges it (bearings derived for the bearing law).
    law : Law
        Scaled (:func:`scaled_law`).
    sigma : float
        The law's and the formation's factor.
    start_scale : float
        The start's factor (``sigma`` unless the start had to shrink further).
    q0 : ndarray, shape (n, 2)
        The robots' centres at the start, m, on the arena.
    headings : ndarray, shape (n,)
        Their headings, radians.
    steps : int
        The step budget.
    tolerance : float
        The stop rule's largest distance error, m.
    notes : tuple of str
        What was scaled or replaced, and by how much.
    warnings : tuple of str
        Parts of the scenario the Robotarium runs otherwise.
    """

    scenario: Scenario
    formation: Formation
    law: Law
    sigma: float
    start_scale: float
    q0: NDArray[np.float64]
    headings: NDArray[np.float64]
    steps: int
    tolerance: float
    notes: tuple[str, ...]
    warnings: tuple[str, ...]

    @property
    def points(self) -> NDArray[np.float64]:
        """The near-identity points at the start, ``(n, 2)``."""
        h = np.column_stack([np.cos(self.headings), np.sin(self.headings)])
        return self.q0 + PROJECTION_DISTANCE * h


def _refuse_parts(sc: Scenario) -> list[str]:
    """Refuse what the testbed cannot honour; the warnings of what it runs otherwise."""
    if sc.formation.dim != 2:
        sc.in_plane("the Robotarium export", "the Robotarium's robots drive on the floor")
    if sc.n > MAX_ROBOTS:
        raise sc.error(
            "robots.positions",
            f"the Robotarium runs at most {MAX_ROBOTS} robots and this scenario has {sc.n}",
        )
    model = sc.model
    if model.name not in ("single-integrator", "unicycle"):
        raise sc.error(
            "robots.model",
            f"the Robotarium's robots are unicycles driven by velocities; a {model.name}'s "
            "command is not a velocity: export the scenario with model = "
            '"single-integrator" or "unicycle"',
        )
    if getattr(model, "mapping", "near-identity") != "near-identity":
        raise sc.error(
            "robots.mapping",
            "the Robotarium export moves near-identity points (the barrier certificate "
            'holds them); the "heading" map is not exported: use mapping = "near-identity"',
        )
    for key, what in (
        ("marching", "[marching] moves the formation along a reference"),
        ("obstacles", "[[obstacles]] stand in the simulated plane, not in the arena"),
        ("sensing", "[sensing] (frames, noise, range, delay, losses) is the simulation's"),
        ("faults", "[faults] stop robots on purpose"),
        ("asynchronous", "[asynchronous] steps robots on their own clocks"),
    ):
        if getattr(sc, key) not in (None, ()):
            raise sc.error(key, f"{what}; the Robotarium export does not write it: remove "
                                "the table to export the rest")  # fmt: skip
    if sc.law.name not in _POWERS:
        raise sc.error(
            "controller.law",
            f"the Robotarium export writes the laws {', '.join(sorted(_POWERS))}; the law "
            f"{sc.law.name!r} is not among them",
        )
    warnings = []
    if sc.safety is not None and sc.safety.enabled:
        warnings.append(
            f"[safety] filter {sc.safety.filter!r} is replaced by the Robotarium's barrier "
            f"certificate (safety radius {SAFETY_RADIUS} m, gain {BARRIER_GAIN:g}, the walls)"
        )
    for key in ("max_speed", "max_turn_rate"):
        if getattr(model, key, None) is not None:
            warnings.append(
                f"robots.{key} = {getattr(model, key):g} is replaced by the Robotarium's "
                f"limits (|v| <= {MAX_SPEED} m/s, |omega| <= {MAX_TURN_RATE} rad/s)"
            )
    offset = getattr(model, "offset", PROJECTION_DISTANCE)
    if offset != PROJECTION_DISTANCE:
        warnings.append(
            f"robots.offset = {offset:g} is replaced by the Robotarium's projection distance "
            f"{PROJECTION_DISTANCE} m"
        )
    return warnings


def robotarium_plan(
    scenario: Scenario, *, steps: int | None = None, tolerance: float = TOLERANCE
) -> RobotariumPlan:
    """How the Robotarium runs ``scenario``: the scaled formation, law and start (module
    docstring), or a :class:`~formationlab.errors.ScenarioError` naming what cannot be run.

    Parameters
    ----------
    scenario : Scenario
    steps : int, optional
        The step budget; default the scenario's duration in steps of 0.033 s.
    tolerance : float
        The stop rule's largest distance error, m.
    """
    sc = scenario
    warnings = _refuse_parts(sc)
    formation = sc.law.formation_for(sc.formation)
    x0, x1, y0, y1 = ARENA
    room = np.array([(x1 - x0) / 2 - WALL_MARGIN, (y1 - y0) / 2 - WALL_MARGIN])
    centre = 0.5 * (sc.q0.max(axis=0) + sc.q0.min(axis=0))
    q = sc.q0 - centre  # the start's box centred on the arena
    off = np.abs(sc.q0.mean(axis=0) - centre)  # where the formation ends (the centroid)
    reach = _extent(formation)
    spread = np.maximum(np.max(np.abs(q), axis=0), 1e-300)
    fit_start = float(np.min(room / spread))
    sigma = min(fit_start, float(np.min(room / (off + reach))))  # any turn of it fits
    d_min = float(formation.distances.min())
    start_scale = sigma
    smallest = DISTANCE_MARGIN * SAFETY_RADIUS
    if sigma * d_min < smallest:  # the formation's own factor; the start shrinks further
        sigma = smallest / d_min
        left = (room - sigma * reach) / np.maximum(off, 1e-300)  # the centroid's room
        start_scale = min(fit_start, float(np.min(left)))
        if start_scale <= 0:
            raise sc.error(
                "formation.distances",
                f"the formation cannot fit the arena: its smallest distance {d_min:g} must "
                f"become at least {smallest:g} m (the barrier's safety radius "
                f"{SAFETY_RADIUS} m times {DISTANCE_MARGIN}), and then it reaches "
                f"{sigma * reach:.2f} m from its centre, more than the "
                f"{room[1]:g} m the arena has; give distances closer to one another",
            )
    law = scaled_law(sc.law, sigma)
    formation = scaled_formation(formation, sigma)
    headings = sc.x0[:, 2] if sc.model.name == "unicycle" else np.zeros(sc.n)
    q0 = start_scale * q
    steps = math.ceil(sc.duration / TIME_STEP - 1e-9) if steps is None else int(steps)
    notes = [
        f"lengths x {sigma:.4g} (distances, diameters, template, Khatib's range): the "
        f"smallest distance {d_min:g} -> {sigma * d_min:.3f} m",
        "gains: " + ", ".join(
            f"{k} x {sigma**p:.4g}" for k, p in _POWERS[sc.law.name].items() if p
        ) + f", eta x {sigma**2:.4g} (the same closed loop, {sigma:.4g} times smaller)",
        f"start x {start_scale:.4g}, its box centred on (0, 0)"
        + ("" if start_scale == sigma else " (the start spreads wider than the formation fits)"),
        f"robots: unicycles, the law on points {PROJECTION_DISTANCE} m ahead (near-identity), "
        + ("headings from the scenario" if sc.model.name == "unicycle" else "headings 0"),
        f"integrator: {steps} steps of {TIME_STEP} s (the scenario's {sc.duration:g} s)",
        f"|v| <= {MAX_SPEED} m/s, |omega| <= {MAX_TURN_RATE} rad/s, then the barrier "
        f"certificate (safety radius {SAFETY_RADIUS} m, gain {BARRIER_GAIN:g}, the walls)",
    ]  # fmt: skip
    plan = RobotariumPlan(
        scenario=sc, formation=formation, law=law, sigma=sigma, start_scale=start_scale,
        q0=q0, headings=np.asarray(headings, dtype=float), steps=steps, tolerance=tolerance,
        notes=tuple(notes), warnings=tuple(warnings),
    )  # fmt: skip
    p = plan.points
    gap = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.diag(np.full(sc.n, np.inf))
    i, j = np.unravel_index(np.argmin(gap), gap.shape)
    if gap[i, j] <= SAFETY_RADIUS:
        raise sc.error(
            "robots.positions",
            f"robots {i + 1} and {j + 1} start {gap[i, j]:.3f} m apart on the arena (scaled by "
            f"{start_scale:.3g}), within the barrier's safety radius {SAFETY_RADIUS} m: "
            "place the start positions farther apart",
        )
    return plan


def _array(values: NDArray, ints: bool = False) -> str:
    """A numpy literal of ``values`` (1-D or 2-D), exact (shortest round-trip floats)."""
    a = np.asarray(values)

    def num(x: float) -> str:
        return str(int(x)) if ints else repr(float(x))

    if a.ndim == 1:
        return "np.array([" + ", ".join(num(x) for x in a) + "])"
    rows = ["[" + ", ".join(num(x) for x in row) + "]" for row in a]
    lines, line = [], ""
    for r in rows:
        if line and len(line) + len(r) > 80:
            lines.append(line)
            line = ""
        line += r + ", "
    lines.append(line)
    body = "\n    ".join(x.rstrip() for x in lines)
    shape = f".reshape(-1, {a.shape[1]})" if a.size == 0 else ""  # (an empty list of rows)
    return f"np.array([\n    {body}\n]){shape}"


def _constants(plan: RobotariumPlan, headless: bool) -> list[str]:
    """The literal constants of the script: formation, law, start, Robotarium."""
    f, law = plan.formation, plan.law
    edge, extra, rep_gain, _ = _TERMS[law.name]
    rep = law.repulsion  # type: ignore[attr-defined]
    out = [
        "# ---- the formation (robot numbers 1-based, as in the scenario file) ----",
        f"N = {f.n}",
        f"EDGES = {_array(f.edges + 1, ints=True)}  # j in N_i: the graph",
        f"D = {_array(f.distances)}  # d_ij of each edge, m",
        f"DIAMETERS = {_array(f.diameters)}  # rho_i, m: a_ij = (rho_i + rho_j) / 2 (eq. 5)",
    ]
    reached = ["bearings"] if law.name == "bearing" else ["distances"]
    if f.has_orientation:
        out += [
            "# restricted triples (i, j, k), j < k, and alpha_ijk: the desired orientation",
            "# is sign(c_ijk) = -sign(alpha_ijk) (eq. 14); alpha_ikj = -alpha_ijk (eq. 3)",
            f"TRIPLES = {_array(f.restricted_halves + 1, ints=True)}",
            f"ALPHA = {_array(f.half_alpha().astype(float))}",
        ]
        reached.append("orientation")
    if law.name == "bearing":
        out.append(f"BEARINGS = {_array(f.bearings)}  # g*_ij of each edge, unit vectors")
    if "area" in extra:
        tris, target = desired_areas(f)
        out += [
            f"AREAS = {_array(tris + 1, ints=True)}  # triangles (a, b, c)",
            f"AREA_TARGET = {_array(target)}  # desired signed areas A*_abc, m^2",
        ]
    gains = {"K_EDGE": law.k_c if edge == "log-barrier" else law.k}  # type: ignore[attr-defined]
    gains["K_REPULSION"] = getattr(law, rep_gain)
    gains |= {"ETA": rep.eta, "S0": rep.influence}
    if "restriction" in extra:
        gains |= {"K_A": law.k_a, "THETA": law.theta}  # type: ignore[attr-defined]
    if "area" in extra:
        gains["K_AREA"] = law.k * law.k_s  # type: ignore[attr-defined]
    out.append(f"# ---- the law: {law.name} ----")
    out += [f"{k} = {float(v)!r}" for k, v in gains.items()]
    poses = np.vstack([plan.q0.T, plan.headings])
    out += [
        "# ---- the start: centres x, y (m) and headings (rad), one column per robot ----",
        f"INITIAL_POSES = {_array(poses)}",
        "# ---- the Robotarium ----",
        f"TIME_STEP = {TIME_STEP}  # s per step",
        f"MAX_STEPS = {plan.steps}  # the step budget",
        f"TOLERANCE = {plan.tolerance!r}  # m: the largest error of a reached formation",
        f"REACHED_BY = {tuple(reached)!r}",
        f"PROJECTION_DISTANCE = {PROJECTION_DISTANCE}  # m: the points the law moves",
        f"SAFETY_RADIUS = {SAFETY_RADIUS}  # m between points (barrier certificate)",
        f"BARRIER_GAIN = {BARRIER_GAIN}",
        f"MAX_WHEEL_SPEED = {MAX_WHEEL_SPEED}  # m/s: the certificate's input limit",
        f"MAX_SPEED = {MAX_SPEED}  # m/s: |v|; with MAX_TURN_RATE both wheels stay within "
        f"{MAX_WHEEL_SPEED} m/s",
        f"MAX_TURN_RATE = {MAX_TURN_RATE}  # rad/s: |omega|",
        f"SHOW_FIGURE = {not headless}  # the simulator's window",
        f"SIM_IN_REAL_TIME = {not headless}  # the simulator's 0.033 s per step",
        "",
        "# ---- indices (0-based) derived from the constants above ----",
        "I, J = EDGES.T - 1",
        "A = 0.5 * (DIAMETERS[I] + DIAMETERS[J])  # a_ij of each edge",
        "_pairs = [(i, j) for i in range(N) for j in range(i + 1, N)",
        "          if [i + 1, j + 1] not in EDGES.tolist()]",
        "PI, PJ = np.array(_pairs, dtype=int).reshape(-1, 2).T  # pairs that are not edges",
        "PA = 0.5 * (DIAMETERS[PI] + DIAMETERS[PJ])",
    ]
    if f.has_orientation:
        out.append("TI, TJ, TK = TRIPLES.T - 1")
    if "area" in extra:
        out.append("AA, AB, AC = AREAS.T - 1")
    return out


def _wrapped(lines: tuple[str, ...]) -> list[str]:
    """``lines`` as the script's docstring shows them: indented, within 88 columns."""
    return [w for line in lines for w in textwrap.wrap(line, 86, initial_indent="  ",
                                                        subsequent_indent="    ")]  # fmt: skip


def robotarium_script(
    scenario: Scenario | RobotariumPlan | str | os.PathLike[str],
    *,
    steps: int | None = None,
    tolerance: float = TOLERANCE,
    headless: bool = False,
) -> str:
    """The Robotarium controller script of ``scenario`` (a scenario, its file, or a plan).

    ``headless``: the script runs the simulator without its window and as fast as it
    computes (``SHOW_FIGURE`` and ``SIM_IN_REAL_TIME`` False), for checks before a
    submission; the testbed ignores both.

    Returns
    -------
    str
        A standalone Python script (numpy and ``rps``): module docstring.
    """
    if isinstance(scenario, str | os.PathLike):
        scenario = load_scenario(scenario)
    plan = (
        scenario
        if isinstance(scenario, RobotariumPlan)
        else robotarium_plan(scenario, steps=steps, tolerance=tolerance)
    )
    sc, law = plan.scenario, plan.law
    edge, extra, _, equation = _TERMS[law.name]
    if not plan.formation.has_orientation or getattr(law, "k_a", 0.0) == 0.0:
        extra = tuple(e for e in extra if e != "restriction")
    if getattr(law, _TERMS[law.name][2]) == 0.0:
        extra = tuple(e for e in extra if e != "repulsion")
    header = [
        f'"""Robotarium controller of the scenario {sc.name!r} ({os.path.basename(sc.source)}).',
        "",
        f"Written by formationlab {package_version()} (formationlab export robotarium) from",
        '"Formation Control of Multiple Robots Avoiding Local Minima" and its scenario; it needs',
        "numpy and the Robotarium's rps only. Every number is a constant below.",
        "",
        "Scaled to the arena (3.2 m x 2 m):",
        *_wrapped(plan.notes),
        *(["", "Not as in the scenario:", *_wrapped(plan.warnings)] if plan.warnings else []),
        "",
        "Run:  python controller.py [--save-poses FILE.npz]   (the poses of every step)",
        '"""',
        "",
        "import sys",
        "",
        "import numpy as np",
        "import rps.robotarium as robotarium",
        "from rps.utilities.barrier_certificates import (",
        "    create_single_integrator_barrier_certificate_with_boundary,",
        ")",
        "from rps.utilities.transformations import create_si_to_uni_mapping",
        "",
    ]  # fmt: skip
    body = "\n".join([*header, *_constants(plan, headless)])
    return body + "\n" + law_function(edge, extra, equation) + MAIN


def twin_simulation(
    plan: RobotariumPlan, steps: int | None = None, *, certificate: bool = True
) -> SimulationResult:
    """formationlab's own run of the plan: the unicycle model with the near-identity map at
    the projection distance and the script's limits (``max_speed``, ``max_turn_rate``),
    explicit Euler at the Robotarium's step, and the centralized barrier filter on the points
    with the certificate's safety radius and gain, for ``steps`` steps (default the plan's).

    The script limits each robot's command before the certificate (whose own input limit,
    ``|u_i| <= 0.2``, then changes nothing) and slows every robot by one factor where the
    certificate sped one past its limits; here the filter comes first and the model limits
    each robot after it. The two are the same arithmetic wherever the certificate changes
    nothing (``tests/test_robotarium.py``).
    ``certificate=False`` leaves the filter out (the script run without its certificate)."""
    model = get_model(
        "unicycle", mapping="near-identity", offset=PROJECTION_DISTANCE, max_speed=MAX_SPEED,
        max_turn_rate=MAX_TURN_RATE,
    )  # fmt: skip
    safety = SafetyFilter(  # (the Robotarium's certificate: the continuous condition)
        filter="barrier" if certificate else "none", distance=SAFETY_RADIUS, gamma=BARRIER_GAIN,
        condition="continuous",
    )  # fmt: skip
    n = plan.steps if steps is None else steps
    return simulate(
        plan.formation, plan.law, plan.q0, duration=n * TIME_STEP,
        integrator=Euler(dt=TIME_STEP), model=model, safety=safety, headings=plan.headings,
        backend="numpy",
    )  # fmt: skip
