"""Obstacles (validation, distances against shapely, gradients against finite differences,
barrier rows, start checks) and the near-identity point of unicycles."""

import numpy as np
import pytest
import shapely

from formationlab.errors import ObstacleError, ParameterError
from formationlab.safety import (
    Circle,
    Polygon,
    check_obstacle_starts,
    clearances,
    grad_obstacle_potential,
    obstacle_barrier_rows,
    obstacle_contacts,
    obstacle_from_mapping,
    obstacle_potential,
    point_safety_distance,
    point_to_unicycle,
    point_velocity,
    unicycle_points,
    unicycle_velocity,
)

CONCAVE = Polygon(vertices=[[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [1.0, 0.8], [0.0, 2.0]])
OBSTACLES = (Circle(center=[-2.0, 0.5], radius=0.6), CONCAVE)


def test_invalid_obstacles_are_rejected_with_clear_errors():
    with pytest.raises(ObstacleError, match="radius must be a finite number > 0"):
        Circle(center=[0, 0], radius=0.0)
    with pytest.raises(ObstacleError, match="radius must be a finite number > 0"):
        Circle(center=[0, 0], radius=float("inf"))
    with pytest.raises(ObstacleError, match="two finite numbers"):
        Circle(center=[0, float("nan")], radius=1.0)
    with pytest.raises(ObstacleError, match="not simple"):
        Polygon(vertices=[[0, 0], [1, 1], [1, 0], [0, 1]])  # a bow tie
    with pytest.raises(ObstacleError, match="at least 3 vertices"):
        Polygon(vertices=[[0, 0], [1, 1]])
    with pytest.raises(ObstacleError, match="finite"):
        Polygon(vertices=[[0, 0], [1, np.inf], [1, 0]])
    with pytest.raises(ObstacleError, match=r"not simple|not valid"):
        Polygon(vertices=[[0, 0], [1, 0], [2, 0]])  # no area
    with pytest.raises(ObstacleError, match="either circle"):
        obstacle_from_mapping({"square": 1})
    c = obstacle_from_mapping({"circle": {"center": [0.0, 0.0], "radius": 0.5}})
    assert isinstance(c, Circle) and c.radius == 0.5
    p = obstacle_from_mapping({"polygon": [[1.0, 1.0], [2.0, 1.0], [2.0, 2.0]]})
    assert isinstance(p, Polygon) and p.vertices.shape == (3, 2)


def test_signed_distance_matches_shapely(rng):
    q = rng.uniform(-1.0, 3.0, (400, 2))
    sd, grad = CONCAVE.signed_distance(q)
    shape = shapely.Polygon(CONCAVE.vertices)
    dist = shapely.distance(shape.exterior, shapely.points(q))
    inside = shapely.contains_xy(shape, q[:, 0], q[:, 1])
    np.testing.assert_allclose(np.abs(sd), dist, atol=1e-12)
    np.testing.assert_array_equal(sd < 0, inside)
    assert inside.sum() > 50 and (~inside).sum() > 50
    np.testing.assert_allclose(np.linalg.norm(grad, axis=-1), 1.0)
    c = OBSTACLES[0]
    sd_c, _ = c.signed_distance(q)
    np.testing.assert_allclose(
        sd_c, shapely.distance(shapely.Point(c.center), shapely.points(q)) - 0.6
    )


def test_clearance_and_repulsion_gradients_match_finite_differences(rng):
    radii = np.array([0.1, 0.05, 0.1])
    q = np.array([[-2.0, -0.3], [1.25, 1.3], [2.3, 0.5]])  # near the circle, in the notch, outside
    _, grad = clearances(q, radii, OBSTACLES)
    eps = 1e-6
    for axis in range(2):
        dq = np.zeros_like(q)
        dq[:, axis] = eps
        fd = (clearances(q + dq, radii, OBSTACLES)[0] - clearances(q - dq, radii, OBSTACLES)[0]) / (
            2 * eps
        )
        np.testing.assert_allclose(grad[..., axis], fd, atol=1e-7)
    kw = {"eta": 1.0, "influence": 0.6}
    g = grad_obstacle_potential(q, radii, OBSTACLES, **kw)
    assert np.count_nonzero(np.abs(g) > 1e-3) >= 2  # some robots are within the influence
    for i in range(3):
        for axis in range(2):
            dq = np.zeros_like(q)
            dq[i, axis] = eps
            fd = (obstacle_potential(q + dq, radii, OBSTACLES, **kw)
                  - obstacle_potential(q - dq, radii, OBSTACLES, **kw)) / (2 * eps)  # fmt: skip
            assert g[i, axis] == pytest.approx(fd, rel=1e-6, abs=1e-8)


def test_khatib_value_by_hand():
    """Robot of radius 0.1 at 0.3 from the circle's edge: s = 0.2, gamma = 1/2 (1/0.2 - 1/0.5)^2."""
    c = Circle(center=[0.0, 0.0], radius=1.0)
    q = np.array([[1.3, 0.0]])
    v = obstacle_potential(q, [0.1], [c], eta=1.0, influence=0.5)
    assert v == pytest.approx(0.5 * (5.0 - 2.0) ** 2)
    g = grad_obstacle_potential(q, [0.1], [c], eta=1.0, influence=0.5)
    np.testing.assert_allclose(g, [[-(5.0 - 2.0) / 0.2**2, 0.0]])  # dgamma/ds along +x


def test_contacts_and_start_check_name_robot_and_obstacle():
    q = np.array([[5.0, 5.0], [1.0, 0.05], [-2.0, 1.2]])
    radii = np.full(3, 0.1)
    contact = obstacle_contacts(q, radii, OBSTACLES)
    assert contact.tolist() == [[False, False], [False, True], [True, False]]
    with pytest.raises(
        ObstacleError, match=r"robot 2 starts inside or touching obstacle 2 \(polygon"
    ):
        check_obstacle_starts(q, radii, OBSTACLES)
    check_obstacle_starts(q[:1], radii[:1], OBSTACLES)
    batch = np.stack([q[:1], q[2:]])
    with pytest.raises(
        ObstacleError, match=r"robot 1 .* obstacle 1 \(circle at \(-2, 0.5\).* in trial 2"
    ):
        check_obstacle_starts(batch, radii[:1], OBSTACLES)


def test_barrier_rows_by_hand_and_against_shapely(rng):
    q = rng.uniform(-3.0, 3.0, (50, 2))
    rows = obstacle_barrier_rows(q, OBSTACLES, distance=0.2, gamma=3.0)
    assert rows.owner.tolist() == [0] + [1] * 5
    w = q - OBSTACLES[0].center
    np.testing.assert_allclose(rows.h[:, 0], np.sum(w * w, -1) - 0.8**2)  # rho = R + D_o
    np.testing.assert_allclose(rows.a[:, 0], -2.0 * w)
    a, b = CONCAVE.edges
    for e in range(5):
        seg = shapely.LineString([a[e], b[e]])
        d = shapely.distance(seg, shapely.points(q))
        np.testing.assert_allclose(rows.h[:, 1 + e], d**2 - 0.2**2, atol=1e-12)
    np.testing.assert_allclose(rows.b, 3.0 * rows.h**3)
    # a is -grad h (finite differences)
    eps = 1e-6
    for axis in range(2):
        dq = np.zeros_like(q)
        dq[:, axis] = eps
        hp = obstacle_barrier_rows(q + dq, OBSTACLES, distance=0.2, gamma=3.0).h
        hm = obstacle_barrier_rows(q - dq, OBSTACLES, distance=0.2, gamma=3.0).h
        np.testing.assert_allclose(-rows.a[..., axis], (hp - hm) / (2 * eps), atol=1e-6)


def test_unicycle_near_identity_point(rng):
    q = rng.normal(size=(4, 3, 2))
    theta = rng.uniform(-np.pi, np.pi, (4, 3))
    ell = 0.05
    p = unicycle_points(q, theta, ell)
    np.testing.assert_allclose(np.linalg.norm(p - q, axis=-1), ell)
    np.testing.assert_allclose(point_to_unicycle(p, theta, ell), q)
    v, omega = rng.normal(size=(2, 4, 3))
    p_dot = point_velocity(v, omega, theta, ell)
    v2, w2 = unicycle_velocity(p_dot, theta, ell)
    np.testing.assert_allclose(v2, v)
    np.testing.assert_allclose(w2, omega)
    # p_dot is the time derivative of p along the unicycle's motion
    dt = 1e-6
    heading = np.stack([np.cos(theta), np.sin(theta)], axis=-1)

    def p_at(t):
        return unicycle_points(q + t * v[..., None] * heading, theta + t * omega, ell)

    np.testing.assert_allclose((p_at(dt) - p_at(-dt)) / (2 * dt), p_dot, atol=1e-7)
    assert point_safety_distance(0.25, ell) == pytest.approx(0.35)
    with pytest.raises(ParameterError, match="offset l must be a finite number > 0"):
        unicycle_points(q, theta, 0.0)


def test_points_kept_apart_keep_the_centres_apart(rng):
    """|p_i - p_j| >= D_s + 2 l implies |q_i - q_j| >= D_s for any headings."""
    ell, d_s = 0.1, 0.3
    theta = rng.uniform(-np.pi, np.pi, (20000, 2))
    q1 = np.zeros((20000, 2))
    direction = rng.normal(size=(20000, 2))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    p1 = unicycle_points(q1, theta[:, 0], ell)
    p2 = p1 + point_safety_distance(d_s, ell) * direction  # exactly at the point distance
    q2 = point_to_unicycle(p2, theta[:, 1], ell)
    assert np.linalg.norm(q2 - q1, axis=-1).min() >= d_s - 1e-12
