"""Cost per trial-step of each robot model in the compiled kernel, against single integrators.

Target (issue 12): the unicycle (either transform) and the double integrator at most
2x the single integrator's cost per trial-step in the kernel. Measured on the paper's
triangle (simulation 2's alpha table, k_c = 2, k_a = 3, theta = 0.5) and the square
with both diagonals, explicit Euler dt = 1e-3, early stopping switched off (every trial
runs every step), box starts in [-3, 3]^2 (unicycles: headings uniform on the circle),
the same starts for every model. The kernel (``kernels.run_chunks``, as ``run_batch``
calls it) runs on one thread, so that a cost is CPU time per trial-step; the rounds
interleave the models, each figure is the best of the rounds, and the reference (single
integrators) is measured in the same rounds. "met" / "NOT met" is each model's ratio
against the target.

Where a unicycle's cost goes: it makes one ``sincos`` call of the C library per robot and
step (``math.cos`` and ``math.sin`` of one heading, merged by the compiler), the heading
transform also one ``atan2``; a call keeps its loop from being vectorised, the kernel's
other loops are. Column "bare": the unicycle's ratio in the same kernel with the calls
replaced by stand-ins of a dozen vectorised operations (:func:`kernel_without_library`);
"calls": the ratio minus "bare", a lower bound of what the library calls cost (the
stand-ins' arithmetic is in "bare"). Also printed: one call's cost, in a loop like the
kernel's over the arguments the model's calls get at its start and at its end (mean).

Run ``python benchmarks/bench_models.py`` (``--quick`` for a smaller run, ``--rounds N``).
The load average is printed: on a shared machine absolute figures drift with it, the
ratios less so.
"""

from __future__ import annotations

import argparse
import inspect
import math
import os
import time
import types

import numba
import numpy as np
from numba import njit

import formationlab as fl
from formationlab.models import DoubleIntegrator, SingleIntegrator, Unicycle
from formationlab.studies import kernels
from formationlab.studies.config import BoxInitial
from formationlab.studies.model_terms import model_terms
from formationlab.studies.sampling import model_initial_states, trial_initial_states

MODELS = {
    "single-integrator": SingleIntegrator(),
    "unicycle near-identity": Unicycle(mapping="near-identity"),
    "unicycle heading": Unicycle(mapping="heading"),
    "double-integrator": DoubleIntegrator(),
    "unicycle near-identity, limits": Unicycle(max_speed=0.5, max_turn_rate=3.0),
    "unicycle heading, limits": Unicycle(mapping="heading", max_speed=0.5, max_turn_rate=3.0),
    "double-integrator, limit": DoubleIntegrator(max_speed=0.5),
}
TARGET = 2.0
CHUNK = 256  # trials per chunk, as run_batch chooses for a few thousand trials
DT = 1e-3


@njit(cache=False, fastmath=False, error_model="numpy")
def _sincos_loop(theta, h, reps):  # the kernel's _headings
    for _ in range(reps):
        for i in range(theta.shape[0]):
            for b in range(theta.shape[1]):
                h[i, 0, b] = math.cos(theta[i, b])
                h[i, 1, b] = math.sin(theta[i, b])


@njit(cache=False, fastmath=False, error_model="numpy")
def _atan2_loop(y, x, out, reps):  # the heading transform's turn
    for _ in range(reps):
        for i in range(x.shape[0]):
            for b in range(x.shape[1]):
                out[i, b] = math.atan2(y[i, b], x[i, b])


@njit(cache=False, fastmath=False, error_model="numpy", inline="always")
def _stand_in_cos_sin(theta):
    """cos and sin to about 0.2: ``theta`` wrapped to [-pi, pi], four Taylor terms."""
    t = theta - TWO_PI * np.floor(theta * (1.0 / TWO_PI) + 0.5)
    t2 = t * t
    c = 1.0 + t2 * (-1 / 2 + t2 * (1 / 24 + t2 * (-1 / 720)))
    s = t * (1.0 + t2 * (-1 / 6 + t2 * (1 / 120 + t2 * (-1 / 5040))))
    return c, s


@njit(cache=False, fastmath=False, error_model="numpy", inline="always")
def _stand_in_atan2(y, x):
    """atan2 to about 4e-3 rad (octant, then a * (pi/4 + 0.273 (1 - a)))."""
    ax, ay = abs(x), abs(y)
    a = min(ax, ay) / max(max(ax, ay), 1e-300)
    r = a * (0.25 * math.pi + 0.273 * (1.0 - a))
    r = 0.5 * math.pi - r if ay > ax else r
    r = math.pi - r if x < 0.0 else r
    return -r if y < 0.0 else r


#: the kernel's library calls and their stand-ins
STAND_INS = {
    "h[i, 0, b] = math.cos(th)\n            h[i, 1, b] = math.sin(th)\n": (
        "h[i, 0, b], h[i, 1, b] = _stand_in_cos_sin(th)\n"
    ),
    "math.atan2(across, along)": "_stand_in_atan2(across, along)",
}
TWO_PI = 2.0 * math.pi


def kernel_without_library() -> types.ModuleType:
    """``studies.kernels`` with ``cos``, ``sin`` and ``atan2`` replaced by stand-ins.

    The same loops and arrays; the stand-ins are a dozen vectorised operations each, near
    enough to the true values (within 0.2 and 4e-3 rad) that the trials move about as they
    do. The time a unicycle takes in it is what it costs besides the library calls, plus
    the stand-ins' own arithmetic: "calls", the difference, is a lower bound of what the
    library calls cost.
    """
    source = inspect.getsource(kernels).replace("cache=True", "cache=False")
    for call, stand_in in STAND_INS.items():
        assert source.count(call) == 1, f"the kernel changed ({call!r}): update the stand-ins"
        source = source.replace(call, stand_in)
    module = types.ModuleType("kernels_without_library")
    module.__package__ = kernels.__package__  # its relative imports
    module.__dict__.update(_stand_in_cos_sin=_stand_in_cos_sin, _stand_in_atan2=_stand_in_atan2)
    exec(compile(source, "<kernels without library calls>", "exec"), module.__dict__)
    return module


def call_arguments(formation, law, model, x):
    """What the library calls of a unicycle get at the states ``x`` ``(B, n, 3)``.

    The headings ``(n, B)`` (sincos) and, for the heading transform, ``(across, along)``
    ``(n, B)`` (atan2), from the law's control at the centres.
    """
    theta = np.ascontiguousarray(x[..., 2].T)
    if model.mapping != "heading":
        return theta, None, None
    u = law.control(formation, x[..., :2])
    c, s = np.cos(x[..., 2]), np.sin(x[..., 2])
    along = c * u[..., 0] + s * u[..., 1]
    across = -s * u[..., 0] + c * u[..., 1]
    return theta, np.ascontiguousarray(across.T), np.ascontiguousarray(along.T)


def library_cost(theta, across, along) -> tuple[float, float]:
    """Seconds per call of sincos over ``theta`` and of atan2 over ``(across, along)``."""
    reps = max(1, 40_000 // theta.size)
    h = np.empty((theta.shape[0], 2, theta.shape[1]))
    start = time.perf_counter()
    _sincos_loop(theta, h, reps)
    sincos = (time.perf_counter() - start) / (reps * theta.size)
    if across is None:
        return sincos, 0.0
    out = np.empty_like(theta)
    start = time.perf_counter()
    _atan2_loop(across, along, out, reps)
    return sincos, (time.perf_counter() - start) / (reps * theta.size)


def kernel_cost(formation, law, model, x0, steps, kernel=kernels) -> tuple[float, np.ndarray]:
    """Seconds per trial-step of one kernel run of ``x0`` (no trial stops early), final states."""
    terms = law.compiled_terms(formation).writable()
    robots = model_terms(model)
    b, n, k = x0.shape
    outs = (
        np.empty((b, n, k)), np.empty((b, n, k)), np.zeros(b, dtype=np.int64),
        np.zeros(b, dtype=np.int8), np.full(b, np.inf), np.full(b, np.nan),
    )  # fmt: skip
    q_window = np.full((b, n, 2), np.nan)
    start = time.perf_counter()
    kernel.run_chunks(
        x0, CHUNK, terms, robots, DT, steps, 10, 1e-300, *outs, -1, q_window
    )  # speed 1e-300: no trial counts as stopped, every trial runs every step
    wall = time.perf_counter() - start
    return wall / max(int(outs[2].sum()), 1), outs[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1024 trials x 300 steps")
    parser.add_argument("--rounds", type=int, default=5, help="best of this many rounds")
    args = parser.parse_args()
    trials, steps = (1024, 300) if args.quick else (4096, 1000)
    numba.set_num_threads(1)
    triangle = fl.Formation.from_alpha_table(
        [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]], n=3, distances=1.0, diameters=0.2
    )
    square = fl.Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], diameters=0.2)
    print(f"load average {os.getloadavg()}; {trials} trials x {steps} steps, one thread, "
          f"best of {args.rounds} rounds")  # fmt: skip
    bare = kernel_without_library()
    worst: dict[str, float] = {}
    floor: dict[str, float] = {}
    for shape, f in (("triangle", triangle), ("square", square)):
        q0 = trial_initial_states(f, BoxInitial(half_width=3.0), 1, np.arange(trials))
        for law in (fl.DistanceLaw(), fl.AngleRestrictedLaw()):
            starts = {
                name: np.ascontiguousarray(model_initial_states(f, m, q0, 1, np.arange(trials)))
                for name, m in MODELS.items()
            }
            for name, m in MODELS.items():  # compile
                kernel_cost(f, law, m, starts[name][:64], 2)
                kernel_cost(f, law, m, starts[name][:64], 2, bare)
            best = dict.fromkeys(MODELS, np.inf)
            best_bare = dict.fromkeys(MODELS, np.inf)
            lib: dict[tuple[str, str], np.ndarray] = {}  # (model, start | end): best costs
            for _ in range(args.rounds):
                for name, m in MODELS.items():
                    cost, x_end = kernel_cost(f, law, m, starts[name], steps)
                    best[name] = min(best[name], cost)
                    if not isinstance(m, Unicycle):
                        continue
                    cost, _ = kernel_cost(f, law, m, starts[name], steps, bare)
                    best_bare[name] = min(best_bare[name], cost)
                    for when, x in (("start", starts[name]), ("end", x_end)):  # its calls
                        c = np.array(library_cost(*call_arguments(f, law, m, x)))
                        lib[name, when] = np.minimum(lib.get((name, when), c), c)
            ref = best["single-integrator"]
            print(f"\n{shape}, {law.name} law: single integrator {ref * 1e9:.1f} ns/trial-step")
            print(f"  {'model':31s} {'ns/trial-step':>13s} {'ratio':>6s} {'bare':>6s} "
                  f"{'calls':>6s}  {'sincos, atan2 ns/call':21s} "
                  f"target <= {TARGET:g}x")  # fmt: skip
            for name, m in MODELS.items():
                ratio = best[name] / ref
                columns = f"{'':6s} {'':6s}  {'':21s}"
                if isinstance(m, Unicycle):  # n robots: n sincos (and n atan2) per trial-step
                    rest = best_bare[name] / ref
                    floor[name] = max(floor.get(name, 0.0), ratio - rest)
                    mean = (lib[name, "start"] + lib[name, "end"]) / 2 * 1e9
                    per_call = f"{mean[0]:5.1f}" + (
                        f", {mean[1]:5.1f}" if m.mapping == "heading" else ""
                    )
                    columns = f"{rest:5.2f}x {ratio - rest:5.2f}x  {per_call:21s}"
                verdict = ""
                if name != "single-integrator":
                    verdict = "met" if ratio <= TARGET else "NOT met"
                    worst[name] = max(worst.get(name, 0.0), ratio)
                print(f"  {name:31s} {best[name] * 1e9:13.1f} {ratio:5.2f}x {columns} {verdict}")
    print("\nworst ratio over the formations and laws (unicycles: the library calls' share):")
    for name, ratio in worst.items():
        calls = f"  calls up to {floor[name]:4.2f}x" if name in floor else ""
        print(f"  {name:32s} {ratio:5.2f}x  {'met' if ratio <= TARGET else 'NOT met'}{calls}")
    print(f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
