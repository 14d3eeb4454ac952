"""Robot models: unicycles (both transforms), double integrators, actuator limits.

Checked against the single-integrator loop they reduce to (near-identity hand points,
convergence order in dt), invariances (rotation of the scene with its headings,
relabelling), the double integrator's energy ``E = V + sum |q_dot|^2 / k_c``
(derivation in ``formationlab.models.double_integrator``), hand-derived transform values,
and the limits (speed, turn rate; ``V`` non-increasing under direction-preserving
saturation).
"""

import math

import numpy as np
import pytest

import formationlab as fl
from formationlab.errors import FormationError, ParameterError
from formationlab.models import (
    DoubleIntegrator,
    HeadingTransform,
    NearIdentity,
    SingleIntegrator,
    Unicycle,
    energy,
    limit_speed,
    limit_unicycle,
)

TRIANGLE = fl.Formation.from_template(
    [[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]], diameters=0.2
)
START = np.array([[-1.2, -0.9], [1.4, -0.7], [0.1, 1.3]])
HEADINGS = np.array([0.3, 2.0, -1.9])
DIST = fl.DistanceLaw(k_c=2.0)


def rotation(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


# ------------------------------------------------------------------ transforms by hand


def test_near_identity_values_by_hand():
    t = NearIdentity(offset=0.1)
    theta = np.array([0.0, np.pi / 2])
    u = np.array([[1.0, 2.0], [1.0, 2.0]])
    v, omega = t.commands(u, theta)
    # heading (1, 0): v = u_x, omega = u_y / l; heading (0, 1): v = u_y, omega = -u_x / l
    np.testing.assert_allclose(v, [1.0, 2.0], atol=1e-15)
    np.testing.assert_allclose(omega, [20.0, -10.0], atol=1e-12)
    p = t.points(np.zeros((2, 2)), theta)
    np.testing.assert_allclose(p, [[0.1, 0.0], [0.0, 0.1]], atol=1e-15)


def test_the_heading_transform_values_by_hand():
    t = HeadingTransform(linear_gain=2.0, turn_gain=1.5)
    theta = np.zeros(4)
    u = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [1.0, -1.0]])
    v, omega = t.commands(u, theta)
    np.testing.assert_allclose(v, [2.0, 0.0, -2.0, 2.0])
    # omega = omega_max atan2(u.h_perp, u.h) / (pi / 2): 0, omega_max, 2 omega_max, -omega_max/2
    np.testing.assert_allclose(omega, [0.0, 1.5, 3.0, -0.75])
    back = HeadingTransform(linear_gain=2.0, turn_gain=1.5, backwards=True)
    v, omega = back.commands(u, theta)  # turns towards -u when that is nearer: u behind: none
    np.testing.assert_allclose(v, [2.0, 0.0, -2.0, 2.0])
    np.testing.assert_allclose(omega, [0.0, 1.5, 0.0, -0.75])
    np.testing.assert_array_equal(t.points(u, theta), u)  # the law acts on the centres


def test_limits_keep_directions_and_the_curvature():
    u = np.array([[3.0, 4.0], [0.3, 0.4], [0.0, 0.0]])
    out = limit_speed(u, 1.0)
    np.testing.assert_allclose(out, [[0.6, 0.8], [0.3, 0.4], [0.0, 0.0]])
    v, w = limit_unicycle(np.array([2.0, 0.5, 0.0, 0.3]), np.array([1.0, 4.0, 0.0, 0.0]), 1.0, 2.0)
    # factors min(1/2, 2/1) = 1/2; then 2/4; none for a robot at rest or driving straight
    np.testing.assert_allclose(v, [1.0, 0.25, 0.0, 0.3])
    np.testing.assert_allclose(w, [0.5, 2.0, 0.0, 0.0])


# ------------------------------------------------------------------ near-identity


def _hand_vs_single(integ: str, dt: float, duration: float = 2.0) -> float:
    uni = fl.simulate(
        TRIANGLE, DIST, START, duration=duration, model=Unicycle(offset=0.2),
        headings=HEADINGS, integrator=fl.get_integrator(integ, dt=dt),
    )  # fmt: skip
    p0 = uni.points[0]
    si = fl.simulate(
        TRIANGLE, DIST, p0, duration=duration, integrator=fl.get_integrator(integ, dt=dt)
    )
    np.testing.assert_allclose(si.t, uni.t, atol=1e-12)
    return float(np.max(np.abs(uni.points - si.q)))


@pytest.mark.parametrize(("integ", "dts", "order"), [
    ("euler", (4e-3, 2e-3, 1e-3), 1.0),
    ("rk4", (0.02, 0.01, 0.005), 4.0),
])  # fmt: skip
def test_near_identity_hand_points_follow_the_single_integrator_loop(integ, dts, order):
    # p_dot = u(p) exactly, so both runs are the same ODE; the difference is the
    # discretisation error of two different coordinates, which shrinks at the order
    errors = [_hand_vs_single(integ, dt) for dt in dts]
    slopes = np.diff(np.log(errors)) / np.diff(np.log(dts))
    assert np.all(np.abs(slopes - order) < 0.25), (errors, slopes)
    assert errors[-1] < (1e-3 if integ == "euler" else 1e-7)


def test_contact_is_tested_on_the_centres_and_the_start_on_both():
    # hand points of robots 1 and 2 turned towards each other overlap while the centres do not
    model = Unicycle(offset=0.3)
    q0 = [[0.0, 0.0], [0.5, 0.0], [0.2, 2.0]]
    with pytest.raises(FormationError, match=r"hand points.*smaller offset"):
        fl.simulate(TRIANGLE, DIST, q0, duration=0.1, model=model, headings=[0.0, np.pi, 0.0])
    res = fl.simulate(TRIANGLE, DIST, q0, duration=0.1, model=model, headings=[np.pi, 0, 0])
    assert res.status == "success"


def test_headings_are_validated():
    with pytest.raises(ParameterError, match="one heading or one per robot"):
        Unicycle().initial_state(START, headings=[0.0, 1.0])
    with pytest.raises(ParameterError, match="finite"):
        Unicycle().initial_state(START, headings=[0.0, np.nan, 1.0])
    with pytest.raises(ParameterError, match="offset"):
        Unicycle(offset=0.0)
    with pytest.raises(ParameterError, match="mapping"):
        Unicycle(mapping="near_identity")
    with pytest.raises(ParameterError, match="max_turn_rate"):
        Unicycle(max_turn_rate=-1.0)
    x = Unicycle().initial_state(START, headings=0.5)
    np.testing.assert_array_equal(x[:, 2], 0.5)


# ------------------------------------------------------------------ invariances


MODELS_AND_STARTS = [
    (Unicycle(offset=0.1), {"headings": HEADINGS}),
    (Unicycle(mapping="heading", max_turn_rate=2.0), {"headings": HEADINGS}),
    (DoubleIntegrator(damping=1.5), {"velocities": [[0.3, 0.0], [0.0, -0.2], [0.1, 0.1]]}),
]


@pytest.mark.parametrize(("model", "extra"), MODELS_AND_STARTS)
@pytest.mark.parametrize("law", ["distance", "angle-restricted"])
def test_rotating_the_scene_rotates_the_run(model, extra, law):
    angle = 0.7
    rot = rotation(angle)
    base = fl.simulate(TRIANGLE, law, START, duration=1.0, model=model, **extra)
    turned = dict(extra)
    if "headings" in extra:
        turned["headings"] = HEADINGS + angle
    else:
        turned["velocities"] = np.asarray(extra["velocities"]) @ rot.T
    # the template turns with the scene, so that the desired orientation is the same
    f = fl.Formation.from_template(np.asarray(TRIANGLE.template) @ rot.T, diameters=0.2)
    other = fl.simulate(f, law, START @ rot.T, duration=1.0, model=model, **turned)
    np.testing.assert_allclose(other.q, base.q @ rot.T, atol=1e-9)
    if "headings" in extra:
        d = np.angle(np.exp(1j * (other.x[..., 2] - base.x[..., 2] - angle)))
        np.testing.assert_allclose(d, 0.0, atol=1e-9)
    else:
        np.testing.assert_allclose(other.x[..., 2:], base.x[..., 2:] @ rot.T, atol=1e-9)
    assert np.abs(base.q[-1] - base.q[0]).max() > 0.1


@pytest.mark.parametrize(("model", "extra"), MODELS_AND_STARTS)
def test_relabelling_the_robots_relabels_the_run(model, extra):
    perm = [2, 0, 1]
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0)
    base = fl.simulate(TRIANGLE, law, START, duration=1.0, model=model, **extra)
    f = fl.Formation.from_template(np.asarray(TRIANGLE.template)[perm], diameters=0.2)
    moved = {k: np.asarray(v)[perm] for k, v in extra.items()}
    other = fl.simulate(f, law, START[perm], duration=1.0, model=model, **moved)
    np.testing.assert_allclose(other.x, base.x[:, perm], atol=1e-9)


# ------------------------------------------------------------------ double integrator


def test_the_double_integrator_energy_decreases_at_the_derived_rate():
    model = DoubleIntegrator(damping=1.5)
    v0 = [[0.5, 0.0], [0.0, -0.4], [0.2, 0.3]]
    res = fl.simulate(
        TRIANGLE, DIST, START, duration=6.0, model=model, velocities=v0,
        integrator=fl.RK4(dt=2e-3),
    )  # fmt: skip
    E = energy(res.V, res.x, DIST.k_c)
    assert np.all(np.diff(E) <= 1e-9)
    # E_dot = -(2 k_d / k_c) sum |q_dot|^2: E(t) - E(0) against the integral (trapezoid)
    rate = -(2 * model.damping / DIST.k_c) * np.sum(res.x[..., 2:] ** 2, axis=(-2, -1))
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(res.t))])
    np.testing.assert_allclose(E - E[0], integral, atol=1e-5)
    assert E[-1] < 0.5 * E[0]


def test_from_rest_the_double_integrator_reaches_the_single_integrators_shape():
    euler = fl.Euler(dt=5e-3)
    si = fl.simulate(TRIANGLE, DIST, START, duration=20.0, integrator=euler)
    di = fl.simulate(
        TRIANGLE, DIST, START, duration=20.0, model=DoubleIntegrator(damping=2.0), integrator=euler
    )
    assert si.outcome() == di.outcome() == "desired"
    assert np.max(np.abs(di.distance_errors[-1])) < 1e-4
    assert di.summary()["orientation"] == si.summary()["orientation"]


@pytest.mark.slow
def test_the_angle_restricted_energy_falls_between_switches_and_jumps_with_V():
    law = fl.AngleRestrictedLaw(k_c=2.0, k_a=3.0, theta=0.5)
    f = fl.Formation.from_alpha_table(
        [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]], n=3, distances=1.0, diameters=0.2
    )
    res = fl.simulate(
        f, law, START, duration=15.0, model=DoubleIntegrator(damping=2.0),
        integrator=fl.RK4(dt=1e-3),
    )  # fmt: skip
    assert res.outcome() == "desired"
    E = energy(res.V, res.x, law.k_c)
    same = np.all(res.active[1:] == res.active[:-1], axis=-1)
    assert (~same).sum() >= 1  # the restriction switched off on the way
    assert np.all(np.diff(E)[same] <= 1e-9)  # no switch in the step: E falls
    # at a switch the kinetic part is continuous: E jumps with V, by about theta times the
    # weight of the switched terms (each restricted triple counts twice, eq. 13): up when off
    jump = np.diff(E)[~same]
    np.testing.assert_allclose(jump, np.diff(res.V)[~same], atol=0.02)
    assert np.all(jump > 0) and np.all(~res.active[-1])


# ------------------------------------------------------------------ limits


def test_saturated_single_integrators_descend_V_within_the_speed():
    res = fl.simulate(
        TRIANGLE, fl.DistanceLaw(k_c=4.0), START * 2, duration=10.0,
        model=SingleIntegrator(max_speed=0.3),
    )  # fmt: skip
    speed = np.linalg.norm(res.u, axis=-1)
    assert speed.max() <= 0.3 + 1e-12 and speed[0].max() == pytest.approx(0.3)
    assert np.all(np.diff(res.V) <= 1e-12)
    assert res.outcome() == "desired"


def test_saturated_unicycles_keep_their_limits_and_V_falls_for_near_identity():
    model = Unicycle(offset=0.1, max_speed=0.4, max_turn_rate=1.0)
    res = fl.simulate(
        TRIANGLE, fl.DistanceLaw(k_c=4.0), START, duration=15.0, model=model, headings=HEADINGS,
        integrator=fl.Euler(dt=4e-3),
    )  # fmt: skip
    v = np.linalg.norm(res.xdot[..., :2], axis=-1)
    w = np.abs(res.xdot[..., 2])
    assert v.max() <= 0.4 + 1e-12 and w.max() <= 1.0 + 1e-12
    assert v.max() > 0.39 or w.max() > 0.99  # a limit was reached
    assert np.all(np.diff(res.V) <= 1e-12)  # V of the hand points
    heading = fl.simulate(
        TRIANGLE, fl.DistanceLaw(k_c=4.0), START, duration=2.0, headings=HEADINGS,
        model=Unicycle(mapping="heading", max_speed=0.4, max_turn_rate=1.0),
    )  # fmt: skip
    assert np.abs(heading.xdot[..., 2]).max() <= 1.0 + 1e-12
    assert np.linalg.norm(heading.xdot[..., :2], axis=-1).max() <= 0.4 + 1e-12


def test_a_speed_limited_double_integrator_keeps_the_speed_and_loses_energy():
    model = DoubleIntegrator(damping=0.5, max_speed=0.4)
    res = fl.simulate(
        TRIANGLE, DIST, START * 2, duration=10.0, model=model, integrator=fl.RK4(dt=2e-3)
    )
    # positions move within the limit (the state's q_dot may pass it by a step's worth:
    # the brake acts from the limit on)
    assert np.linalg.norm(res.u, axis=-1).max() <= 0.4 + 1e-12
    assert np.linalg.norm(res.u, axis=-1).max() > 0.399
    E = energy(res.V, res.x, DIST.k_c)
    assert np.all(np.diff(E) <= 1e-9)


def test_stop_rule_speeds_of_the_models():
    x = np.zeros((1, 3))
    v = np.array([[0.0, 0.0, 2.0]])  # turning on the spot
    assert Unicycle(offset=0.1).speed(x, v)[0] == pytest.approx(0.2)
    xd = np.zeros((1, 4))
    vd = np.array([[0.0, 0.0, 1.0, 0.0]])  # at rest but pushed: u / k_d = 0.5
    assert DoubleIntegrator(damping=2.0).speed(xd, vd)[0] == pytest.approx(0.5)
