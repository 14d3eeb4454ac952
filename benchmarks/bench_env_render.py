"""Frames per second of the PettingZoo environment's ``render()`` (issue 28, item 6).

Target: at least 30 frames per second for 10 robots (``render_mode="rgb_array"``, frames
of 480 x 480 pixels), so that an episode can be watched as it runs.

Printed beside it, measured in the same run on the same machine: the reference cost of a
plain ``fig.canvas.draw()`` of a figure of the same size holding one empty axes (with its
ticks: matplotlib's cost of a plain frame), and the cost of building a new figure for
every frame (``agent_frame``, how ``render()`` drew before it kept one figure). The
ratios to the reference mean something on any machine; the frames per second only when
the load (printed) is low.

Run ``python benchmarks/bench_env_render.py`` (``--frames N``, default 150).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

import formationlab as fl
from formationlab.envs import parallel_env
from formationlab.plotting.agent_frame import agent_frame

N = 10
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def scenario_text() -> str:
    """The ten robots of ``examples/ten-robots.toml`` as near-identity unicycles (their
    headings are drawn too)."""
    text = (EXAMPLES / "ten-robots.toml").read_text()
    unicycles = 'diameters = 0.2\nmodel = "unicycle"\nmapping = "near-identity"\noffset = 0.05\n'
    return text.replace("diameters = 0.2\n", unicycles, 1)


def per_second(call, frames: int) -> float:
    call()  # the first frame (figure and fonts made) is not counted
    start = time.perf_counter()
    for _ in range(frames):
        call()
    return frames / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=150)
    frames = parser.parse_args().frames
    env = parallel_env(scenario_text(), render_mode="rgb_array")
    env.reset(seed=0)
    rng = np.random.default_rng(0)

    def step_and_render() -> None:
        env.step({a: rng.uniform(-0.5, 0.5, 2) for a in env.agents})
        env.render()

    stepping = per_second(lambda: env.step({a: np.zeros(2) for a in env.agents}), frames)
    env.reset(seed=0)
    render = per_second(step_and_render, frames)
    fig = Figure(figsize=(5, 5), dpi=96)
    canvas = FigureCanvasAgg(fig)
    fig.add_subplot()
    empty = per_second(canvas.draw, frames)
    fresh = per_second(lambda: agent_frame(env.formation, env.state(), model=env.model), 30)
    load = os.getloadavg()[0]
    print(f"formationlab {fl.__version__}, {N} unicycles, 480 x 480 px, load {load:.2f}")
    print(f"reference: empty axes, canvas.draw()      {empty:7.1f} frames/s")
    print(
        f"new figure every frame (agent_frame)      {fresh:7.1f} frames/s "
        f"({fresh / empty:.2f} x reference)"
    )
    print(
        f"env.step + env.render() (one kept figure) {render:7.1f} frames/s "
        f"({render / empty:.2f} x reference; step alone {stepping:.0f}/s)"
    )
    print(f"target >= 30 frames/s: {'met' if render >= 30 else 'NOT met'}")


if __name__ == "__main__":
    main()
