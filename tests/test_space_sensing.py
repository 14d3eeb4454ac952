"""Robots that sense in space: frames of SO(3), the channel in three coordinates, faults, and
the helical motion of mismatched distances.

Sun, Mou, Anderson and Morse, "Rigid motions of 3-D undirected formations with mismatch
between desired distances" (IEEE Transactions on Automatic Control 62(8), 2017): when the
two robots of an edge want slightly different distances, a tetrahedron under the gradient
distance law ends in a rigid motion that is a constant rotation about a fixed axis and a
constant translation along it (a helix). Checked here on the fitted screws of equal
windows (Kabsch's fit, ``outcomes.rigid_motion``): constant distances, the same screw in
every window, and one fixed axis along which the formation advances.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import formationlab as fl
from formationlab.dynamics import System
from formationlab.errors import ParameterError
from formationlab.outcomes.rigid_motion import rigid_motion
from formationlab.sensing import (
    Channel,
    Faults,
    Sensing,
    Stop,
    local_controls,
    measured,
    uniform_rotations,
)

#: a regular tetrahedron of edge 1
TETRA = np.array(
    [[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0], [0.5, np.sqrt(3) / 6, np.sqrt(2 / 3)]]
)
F = fl.Formation.from_template(TETRA, diameters=0.2)
Q0 = TETRA * 1.3 + np.random.default_rng(1).normal(scale=0.1, size=(4, 3))
OFF = ~np.eye(4, dtype=bool)
EXAMPLES = Path(__file__).parents[1] / "examples" / "space"


def _channel(sensing: Sensing, trials: int = 1, dt: float = 0.1) -> Channel:
    seeds = [sensing.seed + t for t in range(trials)]
    return Channel(sensing, F, fl.DistanceLaw(), fl.SingleIntegrator(), seeds, dt)


def _lengths(q: np.ndarray) -> np.ndarray:
    e = F.edges
    return np.linalg.norm(q[..., e[:, 1], :] - q[..., e[:, 0], :], axis=-1)


# ----------------------------------------------------------------------------- frames of SO(3)


def test_uniform_rotations_are_rotations_with_the_haar_mean() -> None:
    r = uniform_rotations(np.random.default_rng(0), 20_000)
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape),
                               atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)  # no reflection
    # Haar measure: E[R] = 0 (each entry's std is 1/sqrt(3)); E[trace] = 0
    assert np.abs(r.mean(axis=0)).max() < 4 / np.sqrt(3 * 20_000)
    assert abs(np.trace(r, axis1=1, axis2=2).mean()) < 4 / np.sqrt(20_000)


def test_a_robot_measures_in_its_own_frame_and_commands_back() -> None:
    ch = _channel(Sensing(frames="local", seed=4))
    live = np.arange(1)
    rot = ch.frames(Q0[None], live)[0]  # (n, 3, 3)
    assert rot.shape == (4, 3, 3) and not np.allclose(rot[0], rot[1])
    z, seen = ch.field(Q0[None], live)
    assert seen is None
    for i in range(4):
        for j in range(4):
            np.testing.assert_allclose(z[0, i, j], rot[i].T @ (Q0[j] - Q0[i]), atol=1e-14)
    u = ch.world(ch.local(z, seen, live), Q0[None], live)[0]
    np.testing.assert_allclose(u, fl.DistanceLaw().control(F, Q0), atol=1e-12)
    # the frames come from the seed: the same seed the same frames, another seed others
    np.testing.assert_array_equal(_channel(Sensing(frames="local", seed=4)).fixed_rotations,
                                  ch.fixed_rotations)  # fmt: skip
    assert not np.allclose(_channel(Sensing(frames="local", seed=5)).fixed_rotations,
                           ch.fixed_rotations)  # fmt: skip


@pytest.mark.parametrize("law", ["distance", "squared-distance"])
def test_local_frames_in_space_give_the_run_of_the_common_frame(law: str) -> None:
    """The laws of distances commute with rotations: without noise a run in the robots' own
    frames is the centralized run (to rounding)."""
    scheme = fl.Euler(dt=0.01)
    a = fl.simulate(F, fl.get_law(law), Q0, duration=4.0, integrator=scheme)
    b = fl.simulate(F, fl.get_law(law), Q0, duration=4.0, integrator=scheme,
                    sensing=Sensing(frames="local", seed=2))  # fmt: skip
    assert b.q.shape == a.q.shape == (401, 4, 3)
    np.testing.assert_allclose(b.q, a.q, rtol=0, atol=1e-9)
    assert np.abs(a.q[-1] - a.q[0]).max() > 0.1  # (the robots moved)


def test_each_robots_command_rotates_with_its_frame() -> None:
    """``local_controls`` in space is equivariant: rotating robot i's measurements by R
    rotates its command by R (the terms are along the measured relative positions)."""
    terms = fl.DistanceLaw().sensed_terms(F)
    z = measured(Q0, None)
    rot = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    u = local_controls(terms, z)
    u_turned = local_controls(terms, z @ rot.T)
    np.testing.assert_allclose(u_turned, u @ rot.T, atol=1e-12)


# ----------------------------------------------------------------------------- the channel


def test_noise_is_on_each_of_the_three_coordinates() -> None:
    ch = _channel(Sensing(noise=0.05), trials=3)
    live = np.arange(3)
    errors = [ch.observe(np.broadcast_to(Q0, (3, 4, 3)), live, k)[0] - measured(Q0, None)
              for k in range(300)]  # fmt: skip
    e = np.array(errors)[:, :, OFF, :]  # (steps, trials, pairs, 3)
    assert e.shape[-1] == 3
    for c in range(3):  # x, y and z alike
        assert abs(e[..., c].std() - 0.05) < 0.003 and abs(e[..., c].mean()) < 0.003
    assert np.all(np.array(errors)[:, :, ~OFF] == 0)  # a robot's view of itself is exact


def test_a_delay_of_m_steps_uses_the_state_m_steps_ago() -> None:
    ch = _channel(Sensing(delay=0.3), dt=0.1)  # m = 3 steps
    assert ch.m == 3
    live = np.arange(1)
    step = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0], [0.5, 0.5, 0.5]])
    states = [Q0 + 0.1 * k * step for k in range(8)]
    for k, q in enumerate(states):
        z, seen = ch.observe(q[None], live, k)
        if k < 3:  # nothing has arrived yet: a robot sees no one
            assert not seen[0][OFF].any()
        else:
            np.testing.assert_array_equal(z[0], measured(states[k - 3], None))
            assert seen[0].all()


def test_a_delayed_run_lags_the_undelayed_one() -> None:
    scheme = fl.Euler(dt=0.01)
    a = fl.simulate(F, fl.DistanceLaw(), Q0, duration=2.0, integrator=scheme)
    b = fl.simulate(F, fl.DistanceLaw(), Q0, duration=2.0, integrator=scheme,
                    sensing=Sensing(delay=0.05))  # fmt: skip
    np.testing.assert_array_equal(b.q[:6], np.broadcast_to(Q0, (6, 4, 3)))  # waits 5 steps
    assert np.abs(b.q[6] - Q0).max() > 0
    assert np.abs(b.q[-1] - a.q[-1]).max() > 1e-6
    assert np.max(np.abs(fl.distance_errors(F, b.q[-1]))) < np.max(np.abs(
        fl.distance_errors(F, b.q[0])))  # fmt: skip


def test_a_lost_measurement_leaves_the_last_one_received() -> None:
    ch = _channel(Sensing(drop=0.5))
    live = np.arange(1)
    last = measured(Q0, None)
    fresh_count = 0
    for k in range(200):
        q = Q0 + 1e-3 * k * np.arange(4)[:, None] * np.array([1.0, -1.0, 0.5])
        z, seen = ch.observe(q[None], live, k)
        fresh = np.all(np.isclose(z[0], measured(q, None)), axis=-1) & OFF
        held = np.all(np.isclose(z[0], last), axis=-1) & OFF
        never = ~seen[0] & OFF
        assert np.all((fresh | held | never)[OFF])
        fresh_count += int(fresh[OFF].sum())
        last = z[0]
    assert 0.4 < fresh_count / (200 * 12) < 0.6  # lost with probability 1/2


def test_robots_out_of_range_are_not_seen_and_their_terms_drop_out() -> None:
    q = np.array([[0.0, 0.0, 0.0], [0.9, 0.0, 1.2], [5.0, 5.0, 5.0], [5.0, 5.0, 6.5]])
    law = fl.DistanceLaw()
    u = System(formation=F, law=law, sensing=Sensing(range=2.0)).rhs(q)
    pair = fl.Formation.from_distances(2, distances=1.0, diameters=0.2, dim=3)
    np.testing.assert_allclose(u[:2], law.control(pair, q[:2]), atol=1e-12)  # 1 and 2 alone
    np.testing.assert_allclose(u[2:], law.control(pair, q[2:]), atol=1e-12)  # 3 and 4 alone
    assert np.abs(u).max() > 0.1


def test_a_stopped_robot_stays_where_it_stopped_in_space() -> None:
    res = fl.simulate(F, fl.ChiralityRestrictedLaw(), Q0 * 2, duration=3.0,
                      faults=Faults(stop=[Stop(robot=2, at=1.0)]))  # fmt: skip
    k = int(np.searchsorted(res.t, 1.0))
    assert np.all(res.q[k:, 1] == res.q[k, 1])
    assert np.abs(res.q[k - 10, 1] - res.q[0, 1]).max() > 0.05  # it moved before
    assert np.abs(res.q[-1, 0] - res.q[k, 0]).max() > 1e-3  # the others go on


# ----------------------------------------------------------------------------- refusals


def test_what_sensing_cannot_do_in_space_is_refused_by_name() -> None:
    with pytest.raises(ParameterError, match="frame_error turns the common frame by an angle"):
        System(formation=F, law=fl.DistanceLaw(), sensing=Sensing(frame_error=0.1))
    with pytest.raises(ParameterError, match="'chirality-restricted' computes its robots' own"):
        System(formation=F, law=fl.ChiralityRestrictedLaw(), sensing=Sensing(noise=0.01))
    with pytest.raises(ParameterError, match='backend="numba"'):  # the compiled loop is planar
        fl.simulate(F, fl.DistanceLaw(), Q0, duration=0.1, backend="numba",
                    sensing=Sensing(noise=0.01))  # fmt: skip


def _invoke(*args: object):
    from typer.testing import CliRunner

    from formationlab.cli import _load_commands, app

    _load_commands()
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.mark.parametrize(
    "table, key, fix",
    [
        ("[marching]\nvelocity = [0.1, 0.0]\n", "marching.velocity", "give [vx, vy, vz]"),
        ("[[obstacles]]\ncircle = { center = [9.0, 9.0], radius = 0.5 }\n", "obstacles",
         "use sphere = { center = [x, y, z]"),
    ],
)  # fmt: skip
def test_a_scenario_in_space_with_planar_parts_is_refused_by_name(tmp_path, table, key, fix):
    text = (EXAMPLES / "tetrahedron-mismatch.toml").read_text() + "\n" + table
    path = tmp_path / "bad.toml"
    path.write_text(text)
    res = _invoke("run", path, "--out", tmp_path / "out")
    assert res.exit_code == 2, res.output
    assert f"{key}" in res.output and "(line " in res.output, res.output
    assert fix in res.output and "Traceback" not in res.output, res.output
    assert not (tmp_path / "out" / "trajectory.nc").exists()


def test_sensing_and_a_safety_filter_in_space_are_accepted(tmp_path) -> None:
    """Robots that sense each other in space under the decentralized filter: validate takes
    the file (the filter's rows in space are docs/safety.md's "In space")."""
    text = (EXAMPLES / "tetrahedron-mismatch.toml").read_text()
    path = tmp_path / "ok.toml"
    path.write_text(text + '\n[safety]\nfilter = "barrier-decentralized"\ndistance = 0.3\n')
    res = _invoke("validate", path)
    assert res.exit_code == 0, res.output


# ----------------------------------------------------------------------------- the helix


def test_the_fit_in_space_recovers_a_hand_built_screw() -> None:
    """A shape moved by a known screw (rate, axis through a known point, advance): the fit
    gives them back, and the centroid's velocity at the end is the screw's,
    ``tau a + omega a x (q_bar - c)``; a pure translation has no rate and no centre."""
    rng = np.random.default_rng(3)
    shape = rng.normal(size=(5, 3))
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    point, omega, tau, window = np.array([0.7, 0.2, -1.0]), 0.6, -0.25, 2.0
    rot = Rotation.from_rotvec(axis * omega * window).as_matrix()
    after = point + (shape - point) @ rot.T + axis * tau * window
    m = rigid_motion(shape, after, window)
    assert m.omega == pytest.approx(omega, rel=1e-12)
    np.testing.assert_allclose(m.axis, axis, atol=1e-12)
    assert m.axial_velocity == pytest.approx(tau, rel=1e-12)
    assert m.pitch == pytest.approx(tau / omega, rel=1e-12)
    qc = after.mean(axis=0)
    nearest = point + axis * np.dot(qc - point, axis)
    np.testing.assert_allclose(m.centre, nearest, atol=1e-12)
    np.testing.assert_allclose(m.velocity, tau * axis + omega * np.cross(axis, qc - point),
                               atol=1e-12)  # fmt: skip
    assert m.shape_rate < 1e-12
    shift = np.array([0.3, -0.1, 0.2])
    still = rigid_motion(shape, shape + shift * window, window)
    assert still.omega == pytest.approx(0.0, abs=1e-7)
    np.testing.assert_allclose(still.velocity, shift, atol=1e-7)


def _screws(result, starts: tuple[float, ...], window: float):
    t = result.t
    out = []
    for a in starts:
        i0, i1 = np.searchsorted(t, [a - 1e-9, a + window - 1e-9])
        out.append((result.q[i0], result.q[i1], rigid_motion(result.q[i0], result.q[i1],
                                                             t[i1] - t[i0])))  # fmt: skip
    return out


@pytest.mark.parametrize("seed", [0, 1])
def test_mismatched_distances_end_in_a_helical_motion(seed: int) -> None:
    """Sun, Mou, Anderson and Morse (TAC 2017): with d_ij != d_ji the tetrahedron ends in a
    rigid motion of constant angular velocity about a fixed axis and constant velocity along
    it. After the transient (20 s), over four windows of 5 s: (a) the distances are constant
    and not the desired ones; (b) the fitted screw (rate, axis, advance) is the same in every
    window; (c) the screw axis is one fixed line: the point of the axis nearest the centroid
    moves along the axis at the advance's rate, and the screw about it carries every robot.
    """
    r = fl.simulate(F, fl.DistanceLaw(), Q0, duration=40.0, integrator=fl.get_integrator(
        "rk4", dt=0.01), sensing=Sensing(mismatch=0.01, seed=seed))  # fmt: skip
    late = r.q[r.t >= 20.0 - 1e-9]
    lengths = _lengths(late)
    # (a) a rigid shape (to the integrator's rounding), distorted by the mismatch (~1e-2)
    assert np.abs(lengths - lengths[0]).max() < 1e-9
    assert np.abs(lengths[0] - F.distances).max() > 2e-3
    starts = (20.0, 25.0, 30.0, 35.0)
    screws = _screws(r, starts, 5.0)
    first = screws[0][2]
    assert first.omega > 1e-2 and abs(first.axial_velocity) > 1e-3  # turning and advancing
    for p, q, m in screws:
        # (b) the same rigid motion in every window
        assert m.shape_rate < 1e-9
        assert m.omega == pytest.approx(first.omega, rel=1e-7)
        np.testing.assert_allclose(m.axis, first.axis, atol=1e-7)
        assert m.axial_velocity == pytest.approx(first.axial_velocity, rel=1e-6)
        # the screw itself: q = c + R(p - c) + tau a, R the turn by omega T about a
        rot = Rotation.from_rotvec(m.axis * m.omega * 5.0).as_matrix()
        c = m.centre  # a point of the screw axis
        moved = c + (p - c) @ rot.T + m.axis * m.axial_velocity * 5.0
        np.testing.assert_allclose(moved, q, atol=1e-9)
    # (c) one fixed axis: the centres lie on the line through the first along the axis,
    # advanced by the axial velocity over the time between the windows
    for (_, _, m), t0 in zip(screws[1:], starts[1:], strict=True):
        step = m.centre - first.centre
        np.testing.assert_allclose(np.cross(step, first.axis), 0.0, atol=1e-7)
        assert np.dot(step, first.axis) == pytest.approx(
            first.axial_velocity * (t0 - starts[0]), rel=1e-6
        )


def test_without_mismatch_the_same_start_comes_to_rest() -> None:
    r = fl.simulate(F, fl.DistanceLaw(), Q0, duration=40.0,
                    integrator=fl.get_integrator("rk4", dt=0.01))  # fmt: skip
    assert r.summary()["outcome"] in ("desired", "mirror")
    assert np.abs(r.q[-1] - r.q[-101]).max() < 1e-6


def test_the_example_reports_the_screw(tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = _invoke("run", EXAMPLES / "tetrahedron-mismatch.toml", "--out", out, "--quiet")
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    assert s["outcome"] == "rotating" and s["state_names"] == ["x", "y", "z"]
    m = s["rigid_motion"]
    axis, v = np.array(m["axis"]), np.array(m["velocity"])
    assert np.linalg.norm(axis) == pytest.approx(1.0, abs=1e-12)
    assert m["axial_velocity"] == pytest.approx(np.dot(v, axis), rel=1e-12)
    assert m["pitch"] == pytest.approx(m["axial_velocity"] / m["angular_velocity"], rel=1e-12)
    assert m["speed"] == pytest.approx(np.linalg.norm(v), rel=1e-12)
    assert m["angular_velocity"] > 1e-2 and abs(m["pitch"]) > 1e-2 and m["shape_rate"] < 1e-9
    # the centroid's velocity at the end: the advance along the axis and the turn about it
    q = np.array(s["final_positions"])
    across = m["angular_velocity"] * np.cross(axis, q.mean(axis=0) - np.array(m["centre"]))
    np.testing.assert_allclose(v, m["axial_velocity"] * axis + across, atol=1e-9)
