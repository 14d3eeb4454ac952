"""Marching: a reference for every robot, a leader, Garcia de Marina et al.'s motion parameters."""

import numpy as np
import pytest

import formationlab as fl
from formationlab.errors import FormationError, ParameterError
from formationlab.marching import Marching, MotionParameters, shape_realization
from formationlab.models import DoubleIntegrator, Unicycle

SQUARE = fl.Formation.from_template([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
TRIANGLE = fl.Formation.from_template([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]])
START = np.array([[-1.0, -1.1], [1.3, -0.8], [1.1, 1.4], [-0.9, 1.0]])
DIST = fl.DistanceLaw(k_c=2.0)
V_REF = np.array([0.3, -0.1])


def test_the_centroid_moves_at_the_reference_and_the_shape_as_without_marching():
    still = fl.simulate(SQUARE, DIST, START, duration=8.0)
    moving = fl.simulate(SQUARE, DIST, START, duration=8.0, marching=Marching(velocity=V_REF))
    # the distance law sums to zero, so each Euler step moves the centroid by v_ref dt
    c = moving.q.mean(axis=1)
    np.testing.assert_allclose(c - c[0], moving.t[:, None] * V_REF, atol=1e-10)
    # and is translation invariant: the run is the still run carried along
    np.testing.assert_allclose(moving.q - moving.t[:, None, None] * V_REF, still.q, atol=1e-9)
    np.testing.assert_allclose(moving.shape_error, still.shape_error, atol=1e-9)
    assert moving.shape_error[-1] < 1e-6
    m = moving.summary()["marching"]
    assert m["centroid_velocity_error_final"] < 1e-9 and m["leader"] is None


def test_a_reference_that_is_a_function_of_time_reaches_the_loop():
    def v(t):
        return [0.2 * np.cos(t), 0.2 * np.sin(t)]

    res = fl.simulate(
        SQUARE, DIST, START, duration=3.0, marching=Marching(velocity=v),
        integrator=fl.RK4(dt=1e-2),
    )  # fmt: skip
    c = res.q.mean(axis=1)
    exact = np.stack([0.2 * np.sin(res.t), 0.2 * (1 - np.cos(res.t))], axis=-1)
    np.testing.assert_allclose(c - c[0], exact, atol=1e-9)  # RK4 integrates v(t) to 1e-10
    with pytest.raises(ParameterError, match="constant velocity"):
        fl.simulate(SQUARE, DIST, START, duration=0.1, marching=Marching(velocity=v),
                    integrator="filippov")  # fmt: skip


@pytest.mark.parametrize("model", [None, DoubleIntegrator(damping=3.0), Unicycle(offset=0.1)])
def test_the_leader_takes_the_formation_along_at_the_reference(model):
    law = fl.DistanceLaw(k_c=4.0)
    res = fl.simulate(
        TRIANGLE, law, START[:3], duration=40.0, model=model,
        marching=Marching(velocity=V_REF, leader=2), integrator=fl.Euler(dt=1e-2),
    )  # fmt: skip
    w = res.point_velocity[-1]
    np.testing.assert_allclose(w, np.broadcast_to(V_REF, w.shape), atol=1e-3)
    # the followers' laws pull with the command that holds them at v_ref: a steady
    # distortion of the shape, of order velocity_gain |v_ref| / k_c
    u = law.control(TRIANGLE, res.points[-1])
    gain = res.model.velocity_gain
    np.testing.assert_allclose(u[[0, 2]], np.broadcast_to(gain * V_REF, (2, 2)), atol=1e-3)
    assert 0 < res.shape_error[-1] < gain * np.linalg.norm(V_REF)
    assert np.ptp(res.shape_error[-100:]) < 1e-4
    assert res.summary()["marching"]["leader"] == 2


def test_a_leader_must_be_a_robot():
    with pytest.raises(ParameterError, match="leader 5 is not a robot"):
        fl.simulate(TRIANGLE, DIST, START[:3], duration=1.0,
                    marching=Marching(velocity=V_REF, leader=5))  # fmt: skip
    with pytest.raises(ParameterError, match="1-based"):
        Marching(velocity=V_REF, leader=0)
    with pytest.raises(ParameterError, match="velocity"):
        Marching(velocity=[0.1, np.inf])


def test_motion_parameters_give_the_rigid_motion_at_the_shape():
    p = np.asarray(SQUARE.template)
    mp = MotionParameters.design(SQUARE, [0.2, 0.1], angular_velocity=0.5)
    u = mp.command(SQUARE, p, np.zeros_like(p), 0.0)
    c = p.mean(axis=0)
    expected = np.array([0.2, 0.1]) + 0.5 * np.stack([-(p - c)[:, 1], (p - c)[:, 0]], axis=-1)
    np.testing.assert_allclose(u, expected, atol=1e-12)
    # the terms turn with the formation: the same at the shape rotated and moved
    rot = np.array([[0.0, -1.0], [1.0, 0.0]])
    u2 = mp.command(SQUARE, p @ rot.T + 3.0, np.zeros_like(p), 0.0)
    np.testing.assert_allclose(u2, expected @ rot.T, atol=1e-12)


def test_motion_parameters_translate_and_rotate_the_formation():
    p = np.asarray(TRIANGLE.template)
    omega = 0.4
    mp = MotionParameters.design(TRIANGLE, [0.3, 0.0], angular_velocity=omega)
    res = fl.simulate(TRIANGLE, DIST, p, duration=5.0, marching=mp, integrator=fl.RK4(dt=1e-2))
    assert res.shape_error.max() < 1e-8  # rigid: the law stays at rest
    edge = res.q[:, 1] - res.q[:, 0]
    angle = np.unwrap(np.arctan2(edge[:, 1], edge[:, 0]))
    np.testing.assert_allclose(angle - angle[0], omega * res.t, atol=1e-8)
    # the centroid turns on a circle of radius |v| / omega
    c = res.q.mean(axis=1)
    speed = np.linalg.norm(np.gradient(c, res.t, axis=0), axis=-1)
    np.testing.assert_allclose(speed[1:-1], 0.3, atol=1e-4)


def test_motion_parameters_from_distances_and_their_errors():
    f = fl.Formation.from_distances(3, distances=1.0)
    shape = shape_realization(f)
    r = np.linalg.norm(shape[:, None] - shape[None], axis=-1)
    np.testing.assert_allclose(r[np.triu_indices(3, 1)], 1.0, atol=1e-12)
    path = fl.Formation.from_distances(3, edges=[[1, 2], [2, 3]], distances=1.0)
    with pytest.raises(FormationError, match="template"):
        MotionParameters.design(path, [0.1, 0.0])
    line = fl.Formation.from_template([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]], edges=[[1, 2], [2, 3]])
    with pytest.raises(FormationError, match="robot 1 cannot"):
        MotionParameters.design(line, [0.0, 0.1])
