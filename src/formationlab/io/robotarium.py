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

The plan (the scaling, the testbed's constants, the refusals) is :mod:`.robotarium_plan`'s.
"""

from __future__ import annotations

import os
import textwrap

import numpy as np
from numpy.typing import NDArray

from ..controllers.signed_area import desired_areas
from ..integrators import Euler
from ..models import get_model
from ..resources import package_version
from ..safety import SafetyFilter
from ..scenario.parse import Scenario
from ..simulation.run import SimulationResult, simulate
from .robotarium_code import MAIN, law_function
from .robotarium_plan import (
    BARRIER_GAIN,
    MAX_SPEED,
    MAX_TURN_RATE,
    MAX_WHEEL_SPEED,
    PROJECTION_DISTANCE,
    SAFETY_RADIUS,
    TIME_STEP,
    TOLERANCE,
    RobotariumPlan,
    robotarium_plan,
)
from .scenario import load_scenario

__all__ = ["robotarium_script", "twin_simulation"]

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
