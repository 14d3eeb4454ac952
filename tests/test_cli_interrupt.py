"""Ctrl-C and runs too large to keep: nothing lost, no traceback, an honest refusal.

The SIGINT tests start ``formationlab`` as a subprocess, as a user's shell does,
and send it a real SIGINT: to the process alone, and to its process group (what
Ctrl-C in a terminal does, reaching ffmpeg too).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from _scenarios import triangle
from typer.testing import CliRunner, Result

import formationlab as fl
from formationlab.cli import _load_commands, _plan, app
from formationlab.scenario import parse_scenario

_load_commands()
runner = CliRunner()

SCENARIO = triangle("long-triangle", "DURATION")

CLI = [sys.executable, "-c", "from formationlab.cli import main; main()"]


def invoke(*args: object) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def _default_sigint() -> None:
    """In the child before it runs: SIGINT as a shell leaves it (default, not blocked).

    A child inherits an ignored or blocked SIGINT from its parent, and the test runner's
    worker processes need not have the disposition a user's shell gives a program.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def start(args: list[str], *, group: bool) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [*CLI, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=group,  # its own process group, to signal it as a terminal does
        preexec_fn=_default_sigint,
    )


def _read_until(proc: subprocess.Popen[str], marker: str) -> list[str]:
    """The lines of stderr up to the first that holds ``marker``."""
    assert proc.stderr is not None
    seen = []
    for line in proc.stderr:
        seen.append(line)
        if marker in line:
            return seen
    raise AssertionError(f"{marker!r} never printed: {''.join(seen)}")


def interrupt_after(proc: subprocess.Popen[str], marker: str, *, group: bool) -> str:
    """Wait for ``marker`` on stderr, then SIGINT; returns all of stderr.

    The marker is what the program prints once it is where the test wants it stopped, so
    the test holds however fast or loaded the machine is (no waiting by the clock).
    """
    seen = _read_until(proc, marker)
    if group:
        os.killpg(proc.pid, signal.SIGINT)
    else:
        proc.send_signal(signal.SIGINT)
    _, rest = proc.communicate(timeout=120)
    return "".join(seen) + rest


@pytest.mark.parametrize("group", [False, True], ids=["process", "process-group"])
def test_ctrl_c_during_a_long_run_writes_the_trajectory_so_far(tmp_path: Path, group: bool) -> None:
    scenario = tmp_path / "long.toml"
    # 10^6 steps of RK4 on the stepping driver: minutes (explicit Euler's compiled path
    # would finish them in seconds; its Ctrl-C is tested in tests/test_compiled.py)
    long = SCENARIO.replace("DURATION", "1000.0").replace('"euler"', '"rk4"')
    scenario.write_text(long)
    out = tmp_path / "out"
    proc = start(["run", str(scenario), "--out", str(out)], group=group)
    # printed at the driver's first progress call, after its first step
    err = interrupt_after(proc, "running (at t = ", group=group)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert "\ninterrupted by the user at t = " in err and "error:" not in err
    assert f"the results up to then are in {out}" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    t_end = summary["final_time"]
    assert 0 < t_end < 1000.0
    assert summary["message"] == f"interrupted by the user at t = {t_end:g} s"
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        assert ds.attrs["status"] == "interrupted"
        assert float(ds["time"][-1]) == pytest.approx(t_end, abs=0)
        q_end = ds["q"].values[-1]
    # the saved states are the run's own: the same run, stopped at t_end, ends there too
    sc = parse_scenario(scenario.read_text())
    again = fl.simulate(sc.formation, sc.law, sc.q0, duration=t_end, integrator=sc.integrator)
    np.testing.assert_allclose(q_end, again.q[-1], rtol=0, atol=1e-12)
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary files
    assert set(summary["manifest"]) == {p.name for p in out.iterdir()}


@pytest.mark.parametrize("group", [False, True], ids=["process", "process-group"])
def test_ctrl_c_while_animating_keeps_the_simulation_results(tmp_path: Path, group: bool) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO.replace("DURATION", "1.0"))
    out = tmp_path / "out"
    proc = start(
        ["run", str(scenario), "--out", str(out), "--animate", "--frames", "400"], group=group
    )
    err = interrupt_after(proc, "writing animation.", group=group)  # its first file started
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "CalledProcessError" not in err
    assert "\ninterrupted while animating; the run's results are in " in err
    assert "error:" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "success" and summary["final_time"] == pytest.approx(1.0)
    assert (out / "trajectory.nc").is_file() and (out / "trajectories.png").is_file()
    names = {p.name for p in out.iterdir()}
    assert not [n for n in names if n.startswith(".")]  # no half-written animation
    assert set(summary["manifest"]) == names


def test_ctrl_c_during_mp4_export_of_animate(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO.replace("DURATION", "1.0"))
    out = tmp_path / "out"
    assert invoke("run", scenario, "--out", out, "-q").exit_code == 0
    proc = start(["animate", str(out), "--format", "mp4", "--frames", "600"], group=True)
    # the line that the encoding of 600 frames (tens of seconds) has started
    err = interrupt_after(proc, "writing animation.mp4", group=True)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    said = f"interrupted before an animation was written whole; {out} is as it was"
    assert err.strip().splitlines()[-1] == said and "error:" not in err
    assert not (out / "animation.mp4").exists()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_the_interrupted_status_in_the_api(tmp_path: Path) -> None:
    sc = parse_scenario(SCENARIO.replace("DURATION", "1.0"))
    full = fl.simulate(sc.formation, sc.law, sc.q0, duration=1.0, integrator=sc.integrator)

    def ctrl_c_at_half(t: float) -> None:
        if t >= 0.5:
            raise KeyboardInterrupt

    run = {"duration": 1.0, "integrator": sc.integrator, "progress": ctrl_c_at_half}
    with pytest.raises(KeyboardInterrupt):  # by default Ctrl-C stops the caller too
        fl.simulate(sc.formation, sc.law, sc.q0, **run)
    part = fl.simulate(sc.formation, sc.law, sc.q0, interruptible=True, **run)
    assert part.status == "interrupted"
    t_end = float(part.t[-1])
    assert 0.5 <= t_end < 1.0
    assert part.message == f"interrupted by the user at t = {t_end:g} s"
    k = int(np.flatnonzero(np.isclose(full.t, t_end, rtol=0, atol=1e-12))[0])
    np.testing.assert_array_equal(part.q, full.q[: k + 1])  # every state kept, none invented
    assert part.stats["steps"] == k


# ------------------------------------------------------------ the size of a run


def test_the_plan_counts_steps_and_saved_states() -> None:
    sc = parse_scenario(SCENARIO.replace("DURATION", "1.0"))
    plan = _plan.plan_run(sc, 1)
    assert (plan.steps, plan.saved) == (1000, 1001)
    sparse = _plan.plan_run(sc, 300)  # 300, 600, 900 and the last step 1000
    assert (sparse.steps, sparse.saved) == (1000, 5)
    res = fl.simulate(
        sc.formation, sc.law, sc.q0, duration=1.0, integrator=sc.integrator, save_every=300
    )
    assert len(res.t) == sparse.saved


def test_the_estimates_bound_what_a_run_takes(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO.replace("DURATION", "5.0"))
    sc = parse_scenario(scenario.read_text())
    plan = _plan.plan_run(sc, 1)
    # the first run in a process loads the compiled kernels (Python objects of their own):
    # a short run first, so that what is traced is the run's memory in any test order
    fl.simulate(sc.formation, sc.law, sc.q0, duration=0.01, integrator=sc.integrator)
    tracemalloc.start()
    res = fl.simulate(sc.formation, sc.law, sc.q0, duration=5.0, integrator=sc.integrator)
    res.summary()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak <= plan.memory <= 3 * peak  # an upper bound, and not a wild one
    out = tmp_path / "out"
    assert invoke("run", scenario, "--out", out, "-q").exit_code == 0
    size = (out / "trajectory.nc").stat().st_size
    assert size <= plan.output  # compressed: at most the data's size
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        data = sum(v.nbytes for v in ds.variables.values() if v.dtype.kind in "fiub")
    assert 0.8 * data <= plan.output <= 1.25 * data  # the data before compression


def test_a_run_too_large_to_keep_is_refused_with_a_save_every_that_fits(tmp_path: Path) -> None:
    scenario = tmp_path / "huge.toml"
    scenario.write_text(
        SCENARIO.replace("DURATION", "1000.0").replace("dt = 1e-3", "dt = 1e-6")
    )  # 10^9 steps
    out = tmp_path / "out"
    res = invoke("run", scenario, "--out", out)
    assert res.exit_code == 2
    assert "Traceback" not in res.output
    line = next(ln for ln in res.stderr.splitlines() if ln.startswith("error:"))
    assert line.startswith(
        "error: the run is too large: 1,000,000,000 steps, 1,000,000,001 saved states need ~"
    )
    assert "--force" in line
    k = int(line.split("--save-every ")[1].split()[0])
    assert not out.exists()  # refused before anything was written
    sc = parse_scenario(scenario.read_text())
    assert _plan.check_plan(_plan.plan_run(sc, k), out, save_every_given=True) is None
    still = invoke("run", scenario, "--out", out, "--save-every", max(k // 4, 1))
    assert still.exit_code == 2 and "too large with --save-every" in still.stderr
    checked = invoke("validate", scenario)  # validate says so too, and is not an error
    assert checked.exit_code == 0
    assert "1,000,000,000 steps, all saved: ~" in checked.stdout
    assert f"warning: {scenario}: the run is too large:" in checked.stderr


def test_force_runs_a_run_that_looks_too_large(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO.replace("DURATION", "0.1"))
    monkeypatch.setattr(_plan, "available_memory", lambda: 10e3)  # 10 kB free
    res = invoke("run", scenario, "--out", tmp_path / "a", "-q")
    assert res.exit_code == 2 and "of memory, 10 kB available" in res.stderr
    assert not (tmp_path / "a").exists()
    res = invoke("run", scenario, "--out", tmp_path / "b", "-q", "--force")
    assert res.exit_code == 0, res.output
    assert "warning: the run is too large" in res.stderr and "running it anyway" in res.stderr
    assert (tmp_path / "b" / "summary.json").is_file()


def test_the_progress_callback_comes_at_least_twice_a_second() -> None:
    # 10^7 steps: 1 % of the run (the step-based report) is minutes apart; the callback
    # stops the run with Ctrl-C after 2.5 s of calls
    sc = parse_scenario(SCENARIO.replace("DURATION", "10000.0"))
    wall: list[float] = []
    begin = time.perf_counter()

    def record(t: float) -> None:
        wall.append(time.perf_counter())
        if wall[-1] - begin > 2.5:
            raise KeyboardInterrupt

    res = fl.simulate(
        sc.formation, sc.law, sc.q0, duration=1e4, integrator=sc.integrator,
        save_every=10**6, progress=record, interruptible=True,
    )  # fmt: skip
    assert res.status == "interrupted"
    gaps = np.diff([begin, *wall])
    assert len(wall) >= 5 and np.max(gaps) < 1.0, gaps


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_during_a_long_compiled_run_keeps_the_run_so_far(tmp_path: Path, sig) -> None:
    # explicit Euler's compiled loop (2e8 steps, minutes): a Ctrl-C inside numba code ended
    # in SystemError ("returned a result with an exception set"), exit 1 and no files
    scenario = tmp_path / "long.toml"
    scenario.write_text(SCENARIO.replace("DURATION", "20000.0").replace("dt = 1e-3", "dt = 1e-4"))
    out = tmp_path / "out"
    proc = start(["run", str(scenario), "--out", str(out), "--save-every", "10000"], group=False)
    seen = _read_until(proc, "running (at t = ")  # printed by the loop's first progress call
    proc.send_signal(sig)
    _, rest = proc.communicate(timeout=120)
    err = "".join(seen) + rest
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err and "SystemError" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    t_end = summary["final_time"]
    assert 0 < t_end < 20000.0
    assert f"\ninterrupted by the user at t = {t_end:g} s; the results up to then are in" in err
    assert "error:" not in err
    with xr.open_dataset(out / "trajectory.nc", engine="h5netcdf") as ds:
        assert ds.attrs["status"] == "interrupted"
        t = ds["time"].values
    # every 10,000th step (1 s), and the state the run had reached when it stopped
    assert t[-1] == pytest.approx(t_end, abs=0)
    np.testing.assert_allclose(t[:-1], np.arange(len(t) - 1) * 1.0, rtol=0, atol=1e-9)
    assert set(summary["manifest"]) == {p.name for p in out.iterdir()}


#: the console script, started with an import that waits (for the signal) on its stdin in
#: the middle of the package's import, before the command line's own handling is in place
_PAUSED_START = """\
import importlib.abc, runpy, sys

class Pause(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "formationlab.outcomes.analysis":
            print("paused in the package import", file=sys.stderr, flush=True)
            sys.stdin.readline()
        return None

sys.meta_path.insert(0, Pause())
sys.argv = sys.argv[1:]
runpy.run_path(sys.argv[0], run_name="__main__")
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_the_command_starts_prints_no_traceback(tmp_path: Path, sig) -> None:
    script = Path(sys.executable).with_name("formationlab")
    assert script.is_file(), f"{script}: the console script (pip install -e .)"
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO.replace("DURATION", "1.0"))
    proc = subprocess.Popen(
        [sys.executable, "-c", _PAUSED_START, str(script), "run", str(scenario), "--out",
         str(tmp_path / "out")],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=_default_sigint,
    )  # fmt: skip
    seen = _read_until(proc, "paused in the package import")
    proc.send_signal(sig)
    _, rest = proc.communicate(timeout=120)
    err = "".join(seen) + rest
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err
    assert err.splitlines()[-1] == "interrupted" and "error:" not in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("fmt", ["gif", "mp4", "html"])
def test_ctrl_c_at_the_first_frame_of_an_animation_is_an_interrupt(tmp_path: Path, fmt) -> None:
    # a Ctrl-C while the first frame is drawn: Pillow's clean-up then fails on no frames
    # (IndexError) and matplotlib warned that the animation was never rendered
    from formationlab.io.animation import save_animation
    from formationlab.plotting.animation import animate_run

    q = np.array([[[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]]] * 3)
    anim = animate_run(
        np.arange(3.0), q, edges=np.array([[0, 1], [1, 2]]), diameters=np.full(3, 0.1), title="t"
    )

    def ctrl_c(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    anim._fig.savefig = ctrl_c  # every writer draws a frame through the figure's savefig
    with pytest.raises(KeyboardInterrupt):
        save_animation(anim, tmp_path / "animation", formats=[fmt])
    assert anim._draw_was_started  # no "deleted without rendering anything" warning
    del anim
    assert list(tmp_path.iterdir()) == []  # no half-written file, no temporary one
