"""Results recorded before the engine was made one loop, and the runs that reproduce them.

``python tests/engine_reference.py record`` runs every example file (as ``formationlab run``
runs it, on the default backend and on the numpy driver, for at most ``STEPS`` steps so that
the whole set runs in the test suite) and seeded studies of the triangle, square, hexagon,
safety and sensing examples, and writes what they end with to ``data/engine_reference.json``:
the final states (floats written with ``repr``, so they read back bit for bit) and every
trial's status, outcome and final positions. ``tests/test_engine_reference.py`` runs the same
and compares: statuses, outcomes and steps identical, positions to a tolerance that another
processor's kernels meet (its docstring says which and why; never bit for bit: a last bit
recorded on one processor is not a property of the code).

The recording was made at commit 5de2f44 (before the engine refactoring of issue 24);
``record new`` adds the example files made since (the bearing law's and the learned law's),
leaving the others as recorded.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
DATA = Path(__file__).with_name("data") / "engine_reference.json"

#: steps of each example run (the full duration when shorter)
STEPS = 1500
#: steps of an example of more than :data:`LARGE` robots (a swarm's step costs a thousand
#: small ones; 200 steps exercise every stage and keep the suite short)
LARGE_STEPS = 200
LARGE = 500
#: examples left out of the test-suite comparison for their size (minutes per run)
TOO_LARGE = ("lattice-100000.toml", "lattice-100000-angle.toml")
#: studies compared trial by trial: (example, trials per group, seed)
STUDIES = (
    ("study-triangle.toml", 48, 11),
    ("study-square.toml", 48, 12),
    ("study-square-heading.toml", 24, 13),
    ("study-square-di.toml", 24, 14),
    ("drifting/hexagon-complete.toml", 24, 15),
    ("square-safety.toml", 16, 16),
    ("triangle-obstacle.toml", 16, 17),
    ("agents/robustness-triangle.toml", 16, 18),
)


def example_files() -> list[Path]:
    """Every scenario file of examples/ but the largest lattices, sorted."""
    files = sorted(EXAMPLES.rglob("*.toml"))
    return [f for f in files if f.name not in TOO_LARGE]


def key(path: Path) -> str:
    return path.relative_to(EXAMPLES).as_posix()


def run_example(path: Path, backend: str) -> dict[str, object]:
    """Final state, status and steps of ``path`` run for at most ``STEPS`` steps
    (``LARGE_STEPS`` for a swarm)."""
    import formationlab as fl
    from formationlab.io.scenario import load_scenario

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = load_scenario(path)
    dt = float(getattr(sc.integrator, "dt", 1e-3))
    steps = LARGE_STEPS if sc.formation.n > LARGE else STEPS
    duration = min(sc.duration, steps * dt)
    kwargs = dict(
        duration=duration, integrator=sc.integrator, model=sc.model, marching=sc.marching,
        obstacles=sc.obstacles, safety=sc.safety, sensing=sc.sensing, faults=sc.faults,
        save_every=max(1, round(duration / dt)),
    )  # fmt: skip
    if sc.asynchronous is not None:
        from formationlab.agents import run_async

        res = run_async(
            sc.formation, sc.law, sc.x0, duration=duration, dt=sc.integrator.dt,
            periods=sc.asynchronous["periods"], jitter=sc.asynchronous["jitter"],
            sensing=sc.sensing, faults=sc.faults, model=sc.model,
        )  # fmt: skip
    else:
        if getattr(sc.integrator, "name", "") not in ("euler",):
            backend = "auto"  # only explicit Euler has a compiled path
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = fl.simulate(sc.formation, sc.law, sc.x0, backend=backend, **kwargs)
    return {
        "x": np.asarray(res.x[-1]).tolist(),
        "t": float(res.t[-1]),
        "status": str(res.status),
        "law": sc.law.name,
        "sensed": sc.sensing is not None or sc.asynchronous is not None,
        # the centralized filter's QP: Clarabel in the numpy driver, exact in the compiled loop
        "qp": sc.safety is not None and sc.safety.filter == "barrier",
    }


def run_seeded_study(name: str, trials: int, seed: int) -> dict[str, object]:
    """Every trial's status, outcome and final positions of a seeded study."""
    from formationlab.io.scenario import load_scenario
    from formationlab.studies.config import parse_study
    from formationlab.studies.runner import StudySetup, run_study

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = load_scenario(EXAMPLES / name)
        setup = StudySetup.from_scenario(sc, parse_study(sc.study, trials=trials))
        res = run_study(setup, seed=seed)
    df = res.trials.sort_values(["group", "trial"]) if "group" in res.trials else res.trials
    out: dict[str, object] = {c: [str(v) for v in df[c]] for c in ("law", "group", "outcome")}
    out["steps"] = [int(v) for v in df["steps"]]
    n = sum(1 for c in df.columns if c.startswith("x") and c[1:].isdigit())
    cols = [f"{a}{i}" for i in range(1, n + 1) for a in "xy"]
    out["final"] = df[cols].to_numpy().tolist()
    return out


def record(*, new_only: bool = False) -> None:
    """Record every example and study; ``new_only``: only the example files and studies the
    data file does not hold yet, keeping what it holds as it was recorded."""
    old = json.loads(DATA.read_text()) if new_only and DATA.exists() else {}
    runs, studies = dict(old.get("runs", {})), dict(old.get("studies", {}))
    for path in example_files():
        for backend in ("auto", "numpy"):
            name = f"{key(path)}|{backend}"
            if name not in runs:
                print(f"{key(path)} [{backend}]", flush=True)
                runs[name] = run_example(path, backend)
    for name, trials, seed in STUDIES:
        if name not in studies:
            print(f"study {name}", flush=True)
            studies[name] = run_seeded_study(name, trials, seed)
    DATA.parent.mkdir(exist_ok=True)
    DATA.write_text(json.dumps({"runs": runs, "studies": studies}, indent=0) + "\n")


if __name__ == "__main__":
    if sys.argv[1:2] == ["record"]:  # `record new`: only what the data file does not hold
        sys.path.insert(0, str(ROOT / "src"))
        record(new_only=sys.argv[2:] == ["new"])
    else:
        print(__doc__)
