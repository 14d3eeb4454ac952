"""The paper's section 4: its two simulations, and what an exact simulation shows.

Three robots start at ``(-3, -3), (3, -3), (0, 3)``; all ``d_ij = 1``;
``k_c = 2, k_a = 3, theta = 0.5``. Simulation 1 uses
``alpha_123 = alpha_312 = -alpha_213 = -1`` ("restrictions not active"),
simulation 2 the opposite signs.

The paper gives no robot diameter, duration, integrator or step; the defaults
of :class:`PaperSetup` are ours (``docs/paper.md`` explains them).

The symmetric start
-------------------
The initial condition is mirror-symmetric about ``x = 0`` with robots 1 and 2
swapped, and the closed loop is equivariant under that mirror. An exact
simulation therefore stays in the symmetric subspace, where robots 1 and 2
cannot pass each other: simulation 2 then ends at an equilibrium created by
the angular term (a shrunken triangle with the wrong orientation). The
reproduction follows the paper's narrative with a documented perturbation of
``1e-6`` on robot 1's x coordinate, and also reports the unperturbed run.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..controllers import AngleRestrictedLaw
from ..errors import ParameterError
from ..formation.spec import Formation
from ..integrators import get_integrator
from ..outcomes.analysis import Tolerances, triangle_orientation
from ..simulation.batch import simulate_batch
from ..simulation.run import SimulationResult, simulate
from ..status import Status
from .batch import run_batch

__all__ = [
    "PAPER_ALPHA",
    "PAPER_Q0",
    "PaperReproduction",
    "PaperSetup",
    "diameter_scan",
    "paper_formation",
    "paper_law",
    "paper_runs",
    "paper_scans",
    "reproduce",
    "symmetry_scan",
]

#: Initial positions of section 4, robot 1 first.
PAPER_Q0: NDArray[np.float64] = np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])
PAPER_Q0.setflags(write=False)

#: The alpha tables of section 4 as printed (1-based): alpha_123 = alpha_312 = -alpha_213 = s.
PAPER_ALPHA: dict[int, dict[tuple[int, int, int], float]] = {
    1: {(1, 2, 3): -1.0, (3, 1, 2): -1.0, (2, 1, 3): 1.0},
    2: {(1, 2, 3): 1.0, (3, 1, 2): 1.0, (2, 1, 3): -1.0},
}


def paper_formation(simulation: Literal[1, 2], *, diameter: float = 0.2) -> Formation:
    """The formation of simulation 1 or 2: complete graph, ``d_ij = 1``, the printed alpha table."""
    if simulation not in PAPER_ALPHA:
        raise ParameterError(f"the paper has simulations 1 and 2, got {simulation!r}")
    return Formation.from_alpha_table(
        PAPER_ALPHA[simulation], n=3, distances=1.0, diameters=diameter, alpha_values="sign"
    )


def paper_law() -> AngleRestrictedLaw:
    """The law of section 4: ``k_c = 2, k_a = 3, theta = 0.5`` (eq. 11)."""
    return AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)


@dataclass(frozen=True, kw_only=True)
class PaperSetup:
    """The choices the paper leaves open, with our defaults.

    Parameters
    ----------
    diameter : float
        Robot diameter rho (all robots); must be < 1 so that ``a_ij < d_ij``.
    duration : float
        Simulated time, seconds.
    dt : float
        Step of the integrator.
    integrator : str
        ``"euler"`` (what the paper's figures need) or any registered integrator.
    perturbation : float
        Added to the x coordinate of robot ``perturbed_robot`` in simulation 2
        to leave the symmetric subspace (0 reproduces the exact, symmetric run).
    perturbed_robot : int
        1-based robot that is perturbed.
    save_every : int
        Keep every K-th step in the stored trajectories.
    scan : tuple of float
        Perturbations tried in the symmetry scan of the summary.
    diameters : tuple of float
        Diameters tried in the diameter-dependence table of the summary.
    """

    diameter: float = 0.2
    duration: float = 10.0
    dt: float = 1e-3
    integrator: str = "euler"
    perturbation: float = 1e-6
    perturbed_robot: int = 1
    save_every: int = 1
    scan: tuple[float, ...] = (0.0, 1e-15, 1e-12, 1e-10, 1e-9, 1e-6, 1e-3)
    diameters: tuple[float, ...] = (0.05, 0.1, 0.2, 0.4, 0.6, 0.8)
    tolerances: Tolerances = field(default_factory=Tolerances)

    def __post_init__(self) -> None:
        if not 0 < self.diameter < 1:
            raise ParameterError(
                f"diameter must be in (0, 1) so that a_ij < d_ij = 1, got {self.diameter}"
            )
        if self.perturbed_robot not in (1, 2, 3):
            raise ParameterError(f"perturbed_robot must be 1, 2 or 3, got {self.perturbed_robot}")

    def initial(self, perturbation: float | None = None) -> NDArray[np.float64]:
        """Initial positions with the perturbation on robot ``perturbed_robot``'s x."""
        q0 = PAPER_Q0.copy()
        q0[self.perturbed_robot - 1, 0] += (
            self.perturbation if perturbation is None else perturbation
        )
        return q0

    def run(
        self,
        simulation: Literal[1, 2],
        *,
        perturbation: float = 0.0,
        diameter: float | None = None,
        save_every: int | None = None,
    ) -> SimulationResult:
        """Simulate one of the paper's runs under this setup."""
        return simulate(
            paper_formation(simulation, diameter=self.diameter if diameter is None else diameter),
            paper_law(),
            self.initial(perturbation),
            duration=self.duration,
            integrator=get_integrator(self.integrator, dt=self.dt),
            save_every=self.save_every if save_every is None else save_every,
        )


@dataclass(frozen=True, kw_only=True)
class PaperReproduction:
    """Results of the reproduction: the three runs and the two scans."""

    setup: PaperSetup
    simulation_1: SimulationResult
    simulation_2: SimulationResult
    simulation_2_unperturbed: SimulationResult
    symmetry_scan: list[dict[str, Any]]
    diameter_scan: list[dict[str, Any]]

    def summary(self) -> dict[str, Any]:
        """The content of ``summary.json`` (see ``docs/paper.md``)."""
        law = paper_law()
        params = {
            "initial_positions": PAPER_Q0.tolist(),
            "d_ij": 1.0,
            "k_c": law.k_c,
            "k_a": law.k_a,
            "theta": law.theta,
            "diameter": self.setup.diameter,
            "duration": self.setup.duration,
            "dt": self.setup.dt,
            "integrator": self.setup.integrator,
            "alpha_values": "sign",
            "lambda": law.lam(paper_formation(1)),
        }
        out: dict[str, Any] = {}
        for key, res, sim, pert in (
            ("simulation_1", self.simulation_1, 1, 0.0),
            ("simulation_2", self.simulation_2, 2, self.setup.perturbation),
            ("simulation_2_unperturbed", self.simulation_2_unperturbed, 2, 0.0),
        ):
            s = res.summary(self.setup.tolerances)
            s["parameters"] = {
                **params,
                "alpha": {f"alpha_{i}{j}{k}": v for (i, j, k), v in PAPER_ALPHA[sim].items()},
                "perturbation": {"robot": self.setup.perturbed_robot, "axis": "x", "value": pert},
            }
            s["restrictions_ever_active"] = bool(np.any(res.active))
            s["lyapunov"] = lyapunov_report(res)
            s["exchanged_pairs"] = exchanged_pairs(res.q)
            out[key] = s
        out["symmetry_scan"] = self.symmetry_scan
        out["diameter_scan"] = self.diameter_scan
        return out


def lyapunov_report(res: SimulationResult) -> dict[str, Any]:
    """How monotone the run's Lyapunov function is: its largest rise between saved samples,
    and the rises at switches of a restriction (where ``V_n`` jumps, see docs/paper.md)."""
    dv = np.diff(res.V)
    switched = np.any(res.active[1:] != res.active[:-1], axis=-1) if res.sigma.shape[-1] else None
    rises = dv > 1e-12 * np.maximum(1.0, np.abs(res.V[:-1]))
    report = {
        "initial": float(res.V[0]),
        "final": float(res.V[-1]),
        "minimum": float(res.V.min()),
        "max_increase": float(max(dv.max(initial=0.0), 0.0)),
        "increases": int(rises.sum()),
    }
    if switched is not None:
        report["increases_at_switches"] = int((rises & switched).sum())
        report["switches"] = int(switched.sum())
    return report


def exchanged_pairs(q: NDArray[np.float64]) -> list[str]:
    """Pairs of robots whose paths cross each other (``"1-2"``), from a trajectory ``(T, n, 2)``.

    "Robots i and j exchange positions" in the paper's words; a path crossing is
    the visible trace of it in a trajectory plot.
    """
    n = q.shape[1]
    pairs = []
    for i in range(n):
        for j in range(i + 1, n):
            if _polylines_cross(q[:, i], q[:, j]):
                pairs.append(f"{i + 1}-{j + 1}")
    return pairs


def _polylines_cross(
    p: NDArray[np.float64], r: NDArray[np.float64], max_points: int = 1500
) -> bool:
    """Whether some segment of polyline ``p`` properly crosses one of ``r`` (both ``(T, 2)``,
    thinned to at most ``max_points`` points).

    Two segments cross only if their bounding boxes overlap, so the exact orientation test
    runs on those pairs only: the same answer as testing all pairs. Finding the pairs takes
    one boolean ``max_points^2`` array (about 2 MB), not the float arrays of the orientation
    test over all pairs.
    """
    step = max(1, len(p) // max_points)
    p, r = p[::step], r[::step]
    a, b, c, d = p[:-1], p[1:], r[:-1], r[1:]
    i, j = _overlapping_boxes(a, b, c, d)
    a, b, c, d = a[i], b[i], c[j], d[j]

    def orient(x: NDArray, y: NDArray, z: NDArray) -> NDArray:
        return np.sign(
            (y[..., 0] - x[..., 0]) * (z[..., 1] - x[..., 1])
            - (y[..., 1] - x[..., 1]) * (z[..., 0] - x[..., 0])
        )

    hit = (orient(a, b, c) * orient(a, b, d) < 0) & (orient(c, d, a) * orient(c, d, b) < 0)
    return bool(np.any(hit))


def _overlapping_boxes(
    a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64], d: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs ``(i, j)`` of segments ``a_i b_i`` and ``c_j d_j`` whose bounding boxes overlap."""
    lo1, hi1 = np.minimum(a, b), np.maximum(a, b)
    lo2, hi2 = np.minimum(c, d), np.maximum(c, d)
    box = (lo2[None, :, 0] <= hi1[:, None, 0]) & (hi2[None, :, 0] >= lo1[:, None, 0])
    box &= (lo2[None, :, 1] <= hi1[:, None, 1]) & (hi2[None, :, 1] >= lo1[:, None, 1])
    i, j = np.nonzero(box)
    return i, j


def paper_runs(
    setup: PaperSetup | None = None, *, progress: Callable[[str], None] | None = None
) -> dict[str, SimulationResult]:
    """The three runs of section 4 (stored every ``setup.save_every`` steps), by name:
    ``simulation_1``, ``simulation_2`` (perturbed) and ``simulation_2_unperturbed``."""
    setup = setup or PaperSetup()
    say = progress or (lambda _msg: None)
    say("simulation 1")
    sim1 = setup.run(1)
    say("simulation 2")
    sim2 = setup.run(2, perturbation=setup.perturbation)
    say("simulation 2, unperturbed")
    sim2u = setup.run(2, perturbation=0.0)
    return {"simulation_1": sim1, "simulation_2": sim2, "simulation_2_unperturbed": sim2u}


def paper_scans(
    setup: PaperSetup | None = None, *, progress: Callable[[str], None] | None = None
) -> dict[str, list[dict[str, Any]]]:
    """The symmetry scan and the diameter scan of the summary: ``symmetry_scan``,
    ``diameter_scan``, each run as batches when ``setup`` is the kernels' case (explicit
    Euler; :func:`symmetry_scan`, :func:`diameter_scan`).
    """
    setup = setup or PaperSetup()
    say = progress or (lambda _msg: None)
    batch = setup.integrator == "euler"
    say("symmetry scan")
    scan = symmetry_scan(setup, batch=batch)
    say("diameter scan")
    rows = diameter_scan(setup, batch=batch)
    return {"symmetry_scan": scan, "diameter_scan": rows}


def symmetry_scan(setup: PaperSetup, *, batch: bool = True) -> list[dict[str, Any]]:
    """Rows of the symmetry scan: simulation 2 with each perturbation of ``setup.scan``,
    stored every 10 steps (the paths show which robots exchange positions): the outcome,
    orientation, exchanged pairs and converged time of each run.

    ``batch``: the runs as one batch of the compiled single-run path
    (:func:`formationlab.simulation.batch.simulate_batch`: explicit Euler; each run the
    same numbers as its single run, tested); otherwise single runs (any integrator).
    """
    tol = setup.tolerances
    if batch:
        runs = simulate_batch(
            paper_formation(2, diameter=setup.diameter), paper_law(),
            np.stack([setup.initial(eps) for eps in setup.scan]), duration=setup.duration,
            integrator=get_integrator(setup.integrator, dt=setup.dt), save_every=10,
        )  # fmt: skip
    else:
        runs = [setup.run(2, perturbation=eps, save_every=10) for eps in setup.scan]
    return [
        {
            "perturbation": eps,
            "outcome": r.outcome(tol),
            "orientation": triangle_orientation(r.points[-1]),
            "exchanged_pairs": exchanged_pairs(r.q),
            "converged_time": r.converged_time(tol),
        }
        for eps, r in zip(setup.scan, runs, strict=True)
    ]


def diameter_scan(setup: PaperSetup, *, batch: bool = True) -> list[dict[str, Any]]:
    """Rows of the diameter scan: for each diameter, the outcome, status and converged time
    of simulation 1 and of simulation 2 with and without the perturbation.

    ``batch``: each formation's trials as one batch of the study kernel (explicit Euler);
    otherwise single runs stored every 10 steps (any integrator).
    """
    tol = setup.tolerances
    cases = (("simulation_1", 1, 0.0), ("simulation_2", 2, setup.perturbation),
             ("simulation_2_unperturbed", 2, 0.0))  # fmt: skip
    out = []
    for rho in setup.diameters:
        row: dict[str, Any] = {"diameter": rho}
        if not batch:
            for key, sim, eps in cases:
                r = setup.run(sim, perturbation=eps, diameter=rho, save_every=10)  # type: ignore[arg-type]
                row[key] = {
                    "outcome": r.outcome(tol),
                    "status": r.status,
                    "converged_time": r.converged_time(tol),
                }
            out.append(row)
            continue
        for sim in (1, 2):
            mine = [(key, eps) for key, s, eps in cases if s == sim]
            b = run_batch(
                paper_formation(sim, diameter=rho), paper_law(),  # type: ignore[arg-type]
                np.stack([setup.initial(eps) for _, eps in mine]), dt=setup.dt,
                duration=setup.duration, tolerances=tol,
            )  # fmt: skip
            for k, (key, _) in enumerate(mine):
                status = Status.from_code(int(b.status[k]))
                converged = float(b.converged_time[k])
                row[key] = {
                    "outcome": str(b.outcome[k]),
                    # a trial that stopped moving is a run that ends at its duration
                    "status": Status.SUCCESS if status is Status.CONVERGED else status,
                    "converged_time": converged if np.isfinite(converged) else None,
                }
        out.append(row)
    return out


def reproduce(
    setup: PaperSetup | None = None, *, progress: Callable[[str], None] | None = None
) -> PaperReproduction:
    """Run section 4: both simulations, the unperturbed simulation 2, and the two scans
    (:func:`paper_runs`, then :func:`paper_scans`)."""
    setup = setup or PaperSetup()
    runs = paper_runs(setup, progress=progress)
    scans = paper_scans(setup, progress=progress)
    return PaperReproduction(
        setup=setup,
        simulation_1=runs["simulation_1"],
        simulation_2=runs["simulation_2"],
        simulation_2_unperturbed=runs["simulation_2_unperturbed"],
        symmetry_scan=scans["symmetry_scan"],
        diameter_scan=scans["diameter_scan"],
    )
