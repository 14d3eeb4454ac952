"""Frames per second of the viewer, measured in headless chromium (Debian's, via Playwright).

Usage::

    python benchmarks/bench_viewer.py                  # all cases, 5 s each
    python benchmarks/bench_viewer.py --seconds 3
    python benchmarks/bench_viewer.py --screenshot docs/figures/viewer-simulation-2.png

A frame counts when the page has drawn a new state from the server (the page
asks for one per display frame; ``data-frames`` on the page counts them). The
reference, measured in the same run, is the display's own rate: how often a
blank page gets ``requestAnimationFrame`` in the same browser; "ratio" is
viewer fps / that rate (1.0: every display frame shows a new state).

Cases:

* ``simulation 2``: ``examples/paper-simulation-2.toml`` live (3 robots).
* ``100 robots live``: a ring of 100 robots with the ring and skip-one chords
  as edges (200 edges), the angle-restricted law with the template's
  orientation, stepped live on the server (the step budget per frame keeps
  the display rate; the simulation then runs slower than real time).
* ``100 robots, distance``: the same with the distance law (eq. 8). Above 64
  robots both laws sum over lists (edges, restricted triples, close pairs), so
  neither step bounds the frame rate here.
* ``10000 robots replay``: a synthetic stored run of 10,000 robots (20,000
  edges) replayed; positions travel as float32 buffers; the case measures what
  the page and the transport sustain.

Targets (issue 16): 100 robots >= 30 fps, 10,000 robots >= 10 fps.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from formationlab.io.scenario import load_scenario
from formationlab.scenario import parse_scenario
from formationlab.viewer import Controller, LiveSession, ReplaySession
from formationlab.viewer.server import BackgroundServer

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = "/usr/bin/chromium"


def ring_scenario(n: int, law: str = "angle-restricted") -> dict:
    """``n`` robots to form a ring (neighbours 1 apart), started on a wider, noisy ring."""
    rng = np.random.default_rng(7)
    radius = 0.5 / np.sin(np.pi / n)
    a = 2 * np.pi * np.arange(n) / n
    template = np.c_[radius * np.cos(a), radius * np.sin(a)]
    start = template * 1.3 + rng.normal(0, 0.05, (n, 2))
    edges = [[i + 1, (i + 1) % n + 1] for i in range(n)] + [
        [i + 1, (i + 2) % n + 1] for i in range(n)
    ]
    return {
        "name": f"ring-{n}",
        "robots": {"positions": start.tolist(), "diameters": 0.2},
        "formation": {"edges": edges, "template": template.tolist(), "orientation": "template"},
        "controller": {"law": law, "k_c": 2.0}
        | ({"k_a": 3.0, "theta": 0.5} if law == "angle-restricted" else {}),
        "simulation": {"integrator": "euler", "dt": 1e-3, "duration": 60.0},
    }


def synthetic_run(n: int, frames: int):
    """An xarray Dataset shaped like ``trajectory.nc`` of ``n`` robots on a breathing ring."""
    import xarray as xr

    t = np.linspace(0.0, 10.0, frames)
    a = 2 * np.pi * np.arange(n) / n
    radius = 0.5 / np.sin(np.pi / n) * 0.02  # a 10,000-robot ring, shrunk to fit
    r = radius * (1.0 + 0.2 * np.sin(t))[:, None]
    ang = a[None, :] + 0.1 * t[:, None]
    q = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=-1)
    e = np.r_[
        np.c_[np.arange(n), (np.arange(n) + 1) % n], np.c_[np.arange(n), (np.arange(n) + 2) % n]
    ]
    d = np.linalg.norm(q[:, e[:, 1]] - q[:, e[:, 0]], axis=-1)
    return xr.Dataset(
        {
            "q": (("time", "robot", "axis"), q),
            "V": (("time",), np.exp(-t)),
            "distance_error": (("time", "edge"), d - d[0]),
            "diameter": (("robot",), np.full(n, 0.002)),
            "edge_robots": (("edge", "end"), e + 1),
            "desired_distance": (("edge",), d[0]),
        },
        coords={"time": t},
        attrs={"scenario_name": f"synthetic-{n}"},
    )


def measure(browser, session, seconds: float, screenshot: Path | None = None) -> float:
    with BackgroundServer(Controller(session)) as srv:
        page = browser.new_page(viewport={"width": 1280, "height": 760})
        page.goto(srv.url)
        page.wait_for_selector(".flv-root[data-state=ready]", timeout=60_000)
        page.wait_for_timeout(1500)  # warm up
        f0, t0 = int(page.get_attribute(".flv-root", "data-frames")), time.perf_counter()
        page.wait_for_timeout(seconds * 1000)
        f1, t1 = int(page.get_attribute(".flv-root", "data-frames")), time.perf_counter()
        drawn = int(page.get_attribute(".flv-root", "data-robots"))
        draw_ms = page.get_attribute(".flv-root", "data-draw-ms")
        if screenshot is not None:
            page.screenshot(path=str(screenshot))
        page.close()
    fps = (f1 - f0) / (t1 - t0)
    print(f"    ({drawn} robots drawn, {draw_ms} ms per draw)", flush=True)
    return fps


def raf_rate(browser, seconds: float) -> float:
    page = browser.new_page(viewport={"width": 1280, "height": 760})
    page.set_content("<canvas></canvas>")
    n = page.evaluate(
        """(ms) => new Promise((done) => { let k = 0; const t0 = performance.now();
            const f = () => { k++; if (performance.now() - t0 < ms) requestAnimationFrame(f);
            else done(k * 1000 / (performance.now() - t0)); }; requestAnimationFrame(f); })""",
        seconds * 1000,
    )
    page.close()
    return float(n)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--screenshot", type=Path, help="also save a screenshot of simulation 2")
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    cases = [
        (
            "simulation 2",
            lambda: LiveSession(load_scenario(ROOT / "examples/paper-simulation-2.toml")),
            30.0,
        ),
        ("100 robots live", lambda: LiveSession(parse_scenario(ring_scenario(100))), 30.0),
        (
            "100 robots, distance",
            lambda: LiveSession(parse_scenario(ring_scenario(100, "distance"))),
            30.0,
        ),
        ("10000 robots replay", lambda: ReplaySession(synthetic_run(10_000, 300)), 10.0),
    ]
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True)
        ref = raf_rate(browser, args.seconds)
        print(f"reference: display rate (requestAnimationFrame, blank page) {ref:.1f} fps")
        rows = []
        for k, (name, make, target) in enumerate(cases):
            print(f"  {name} ...", flush=True)
            shot = args.screenshot if (k == 0 and args.screenshot) else None
            fps = measure(browser, make(), args.seconds, shot)
            rows.append((name, fps, target))
        browser.close()
    print(f"\n{'case':<22}{'fps':>8}{'ratio':>8}{'target':>8}  ok")
    ok = True
    for name, fps, target in rows:
        good = fps >= target
        ok &= good
        print(f"{name:<22}{fps:8.1f}{fps / ref:8.2f}{target:8.0f}  {'yes' if good else 'NO'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
