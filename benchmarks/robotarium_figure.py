"""The figure of docs/robots.md: exported controllers run in the Robotarium's simulator.

For the paper's simulation 1 (a triangle) and the square with diagonals, the controller that
``formationlab export robotarium`` writes runs headless in ``rps`` (the
robotarium-python-simulator package, in a fresh interpreter, saving its poses); formationlab's
own unicycle run of the same plan (``formationlab.io.robotarium.twin_simulation``) is drawn
over it. Usage (needs ``pip install robotarium-python-simulator``)::

    python benchmarks/robotarium_figure.py docs/figures/robotarium-runs.png
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from formationlab.io.figures import save_figure
from formationlab.io.robotarium import (
    ARENA,
    PROJECTION_DISTANCE,
    robotarium_plan,
    robotarium_script,
    twin_simulation,
)
from formationlab.io.scenario import load_scenario
from formationlab.plotting.colors import robot_colors

ROOT = Path(__file__).resolve().parents[1]
RUNS = ("paper-simulation-1", "square-with-diagonals")


def rps_points(name: str, folder: Path) -> tuple[object, np.ndarray, int]:
    """The plan, rps's points ``(steps + 1, n, 2)`` and its step count."""
    plan = robotarium_plan(load_scenario(ROOT / "examples" / f"{name}.toml"))
    script, saved = folder / f"{name}.py", folder / f"{name}.npz"
    script.write_text(robotarium_script(plan, headless=True))
    subprocess.run([sys.executable, str(script), "--save-poses", str(saved)], check=True,
                   capture_output=True, env={"MPLBACKEND": "Agg", "PATH": ""})  # fmt: skip
    with np.load(saved) as data:
        poses, steps = data["poses"], int(data["steps"])
    h = np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], axis=-1)
    return plan, np.transpose(poses[:, :2], (0, 2, 1)) + PROJECTION_DISTANCE * h, steps


def main(target: str) -> None:
    fig = Figure(figsize=(10, 3.6), layout="constrained")
    axes = fig.subplots(1, len(RUNS))
    with tempfile.TemporaryDirectory() as tmp:
        for ax, name in zip(axes, RUNS, strict=True):
            plan, theirs, steps = rps_points(name, Path(tmp))
            ours = twin_simulation(plan, steps).points
            gap = np.linalg.norm(ours - theirs, axis=-1).max()
            colors = robot_colors(plan.formation.n)
            x0, x1, y0, y1 = ARENA
            ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, color="0.3"))
            for i in range(plan.formation.n):
                ax.plot(*theirs[:, i].T, color=colors[i], lw=1.6, label="rps" if i == 0 else None)
                ax.plot(*ours[:, i].T, color="k", lw=0.8, ls="--",
                        label="formationlab" if i == 0 else None)  # fmt: skip
                ax.plot(*theirs[0, i], "o", color=colors[i], ms=4)
            end = theirs[-1]
            for i, j in plan.formation.edges:
                ax.plot(*end[[i, j]].T, color="0.5", lw=0.8)
            ax.set_aspect("equal")
            ax.set_xlim(x0 - 0.05, x1 + 0.05)
            ax.set_ylim(y0 - 0.05, y1 + 0.05)
            ax.set_title(f"{name}\nreached in rps after {steps} steps ({steps * 0.033:.1f} s); "
                         f"paths within {100 * gap:.1f} cm", fontsize=9)  # fmt: skip
            ax.legend(fontsize=8, loc="upper right")
    print(f"wrote {save_figure(fig, target)}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "docs/figures/robotarium-runs.png")
