"""Obstacles and the safety filter in space: spheres, boxes, the 3-D barrier rows, both
filters, marching, and the scenario's tables (docs/safety.md, "In space")."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_safety_scenario import BASE as PLANE  # the plane's triangle
from typer.testing import CliRunner

import formationlab as fl
from formationlab.cli import _load_commands, app
from formationlab.errors import ParameterError, ScenarioError
from formationlab.marching import Marching
from formationlab.safety import (
    Box,
    Circle,
    SafetyFilter,
    Sphere,
    clearances,
    decentralized_reference,
    obstacle_barrier_rows,
    swept_clearances,
)
from formationlab.safety.barrier import PAIR, barrier_constraints, solve_barrier_qp
from formationlab.safety.dual_active_set import centralized_command, workspace
from formationlab.safety.solids import segment_box_distance
from formationlab.scenario import parse_scenario

_load_commands()
EXAMPLES = Path(__file__).parent.parent / "examples"
OBSTACLES = (
    Sphere(center=[0.0, 0.0, 0.0], radius=0.4),
    Box(center=[1.2, 0.0, 0.0], size=[0.5, 1.0, 2.0]),
)


def _points(rng: np.random.Generator, k: int) -> np.ndarray:
    """``k`` points off every surface and edge of :data:`OBSTACLES` (where the signed
    distance is differentiable)."""
    q = rng.uniform([-0.6, -0.7, -1.2], [1.6, 0.7, 1.2], size=(4 * k, 3))
    s, _ = clearances(q, np.zeros(len(q)), OBSTACLES)
    w = np.abs(q - OBSTACLES[1].center) - OBSTACLES[1].half
    off_ridge = np.sort(np.abs(w), axis=-1)[:, 1] > 1e-3  # not near two faces at once
    return q[(np.abs(s).min(axis=-1) > 1e-3) & off_ridge][:k]


def test_box_and_sphere_distances_by_hand() -> None:
    """Worked values: a unit cube's face, edge, corner and inside; a sphere as a circle."""
    cube = Box(center=[0.0, 0.0, 0.0], size=[2.0, 2.0, 2.0])
    q = np.array([[2.0, 0.0, 0.0], [2.0, 2.0, 0.0], [2.0, 2.0, 2.0], [0.5, 0.0, 0.0], [0, 0, -0.9]])
    delta, grad = cube.signed_distance(q)
    np.testing.assert_allclose(delta, [1.0, np.sqrt(2), np.sqrt(3), -0.5, -0.1], rtol=1e-15)
    np.testing.assert_allclose(grad[1], [2**-0.5, 2**-0.5, 0.0], rtol=1e-15)
    np.testing.assert_array_equal(grad[3:], [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    # a sphere cut by the plane z = 0 is the circle: one formula in d dimensions
    sphere, circle = (
        Sphere(center=[0.3, -0.2, 0.0], radius=0.5),
        Circle(center=[0.3, -0.2], radius=0.5),
    )
    p = np.random.default_rng(0).normal(size=(20, 2))
    d3, g3 = sphere.signed_distance(np.column_stack([p, np.zeros(20)]))
    d2, g2 = circle.signed_distance(p)
    np.testing.assert_array_equal(d3, d2)
    np.testing.assert_array_equal(g3[:, :2], g2)


def test_clearance_gradient_matches_finite_differences() -> None:
    rng = np.random.default_rng(1)
    q = _points(rng, 40)
    radii = np.full(len(q), 0.1)
    s, grad = clearances(q, radii, OBSTACLES)
    assert (s < 0).any() and (s > 0).any()  # points inside and outside
    eps = 1e-6
    for c in range(3):
        step = np.zeros(3)
        step[c] = eps
        fd = clearances(q + step, radii, OBSTACLES)[0] - clearances(q - step, radii, OBSTACLES)[0]
        np.testing.assert_allclose(fd / (2 * eps), grad[..., c], atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(grad, axis=-1), 1.0, rtol=1e-12)
    # Khatib's repulsion is the gradient of the obstacle potential (its descent direction)
    out = _points(rng, 80)
    out = out[clearances(out, np.zeros(len(out)), OBSTACLES)[0].min(axis=-1) > 0.05][:10]
    v = fl.safety.obstacle_potential(out, np.zeros(len(out)), OBSTACLES, eta=1.0, influence=1.0)
    g = fl.safety.grad_obstacle_potential(
        out, np.zeros(len(out)), OBSTACLES, eta=1.0, influence=1.0
    )
    i, c = 0, 2
    bump = np.zeros_like(out)
    bump[i, c] = eps

    def pot(x: np.ndarray) -> float:
        return fl.safety.obstacle_potential(x, np.zeros(len(x)), OBSTACLES, eta=1.0, influence=1.0)

    assert v > 0
    np.testing.assert_allclose((pot(out + bump) - pot(out - bump)) / (2 * eps), g[i, c], rtol=1e-6)


def test_barrier_rows_of_spheres_and_boxes_are_the_squared_distance() -> None:
    """h = |q - p*|^2 - rho^2 with grad h = -a = 2 (q - p*), by finite differences."""
    q = _points(np.random.default_rng(2), 30)
    q = q[clearances(q, np.zeros(len(q)), OBSTACLES)[0].min(axis=-1) > 0]
    rows = obstacle_barrier_rows(q, OBSTACLES, distance=0.1, gamma=1.0)
    delta = clearances(q, np.zeros(len(q)), OBSTACLES)[0]
    # the sphere's piece is its centre (rho = R + D_o), the box's its nearest point (rho = D_o)
    np.testing.assert_allclose(rows.h[:, 0], (delta[:, 0] + 0.4) ** 2 - 0.5**2, atol=1e-12)
    np.testing.assert_allclose(rows.h[:, 1], delta[:, 1] ** 2 - 0.1**2, atol=1e-12)
    eps = 1e-6
    for c in range(3):
        step = np.zeros(3)
        step[c] = eps
        up = obstacle_barrier_rows(q + step, OBSTACLES, distance=0.1, gamma=1.0).h
        down = obstacle_barrier_rows(q - step, OBSTACLES, distance=0.1, gamma=1.0).h
        np.testing.assert_allclose((up - down) / (2 * eps), -rows.a[..., c], atol=1e-6)


def test_swept_clearance_is_exact() -> None:
    """The least distance of a straight step to a box: no sample of the step is closer,
    and a fine sampling comes within its spacing; a step through the box touches it."""
    rng = np.random.default_rng(3)
    box = OBSTACLES[1]
    q0 = rng.uniform(-1.0, 3.0, size=(200, 3))
    q1 = rng.uniform(-1.0, 3.0, size=(200, 3))
    exact = segment_box_distance(q0, q1, *box.corners)
    s = np.linspace(0.0, 1.0, 4001)[:, None, None]
    sampled = np.maximum(box.signed_distance(q0 + s * (q1 - q0))[0], 0.0).min(axis=0)
    assert np.all(exact <= sampled + 1e-12)
    np.testing.assert_allclose(exact, sampled, atol=2e-3)
    assert (exact == 0).any() and (exact > 0).any()
    through = swept_clearances([[0.8, 0.1, 0.2]], [[1.7, 0.1, 0.2]], [0.1], [box])
    assert through[0, 0] == pytest.approx(-0.1)  # ends clear, passes through: contact
    ball = swept_clearances([[-1.0, 0.5, 0.0]], [[1.0, 0.5, 0.0]], [0.05], [OBSTACLES[0]])
    assert ball[0, 0] == pytest.approx(0.5 - 0.4 - 0.05)


def _problem(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Six robots among the obstacles, clear of them and of each other, commanded inward."""
    rng = np.random.default_rng(seed)
    while True:
        q = rng.uniform(-1.5, 1.5, size=(6, 3))
        gaps = np.linalg.norm(q[:, None] - q[None], axis=-1) + 9 * np.eye(6)
        if clearances(q, np.full(6, 0.2), OBSTACLES)[0].min() > 0.05 and gaps.min() > 0.35:
            return q, -3.0 * q + 2.0 * rng.normal(size=q.shape)


def test_centralized_dual_active_set_matches_clarabel_in_space() -> None:
    """The compiled dual active set (Goldfarb-Idnani) and Clarabel solve the same 3-D QP;
    the filter's command is feasible for every row and is the QP's solution."""
    rows_active = []
    for seed in range(12):
        q, uh = _problem(seed)
        sf = SafetyFilter(filter="barrier", distance=0.3, gamma=50.0).at_step(0.01)
        c = barrier_constraints(sf, q, OBSTACLES)
        ref = solve_barrier_qp(c, uh)
        ri = np.ascontiguousarray(c.index[:, 0])
        rj = np.where(c.kind == PAIR, c.index[:, 1], -1).astype(np.int64)
        mats, vecs, lam, act, rb2 = workspace(6, len(c.bound), 3)
        out = np.empty_like(uh)
        code = centralized_command(ri, rj, np.ascontiguousarray(c.coef), c.bound, c.barrier, uh,
                                   out, lam, mats, vecs, act, rb2)  # fmt: skip
        assert code == int(ref.status)
        np.testing.assert_allclose(out, ref.u, atol=1e-7 * (1 + np.abs(uh).max()))
        assert np.all(c.G @ out.ravel() <= c.bound + 1e-9 * (1 + np.abs(c.bound)))
        np.testing.assert_allclose(sf.apply(q, uh, obstacles=OBSTACLES).u, ref.u, atol=1e-7 * 10)
        rows_active.append(int(np.count_nonzero(lam)))
    assert max(rows_active) >= 3  # the cases beyond the closed form of two rows


def test_decentralized_filter_in_space_matches_clarabel() -> None:
    """Each robot's 3-D QP by the dual active set = Clarabel's (where Clarabel solves it)."""
    dec = SafetyFilter(filter="barrier-decentralized", distance=0.3, gamma=50.0).at_step(0.01)
    changed = 0
    for seed in range(12):
        q, uh = _problem(seed)
        got = dec.apply(q, uh, obstacles=OBSTACLES)
        ref, codes = decentralized_reference(dec, q, uh, OBSTACLES)
        ok = codes != 4  # Clarabel fails on a few badly scaled rows (docs/safety.md)
        np.testing.assert_allclose(got.u[ok], ref[ok], atol=1e-6 * (1 + np.abs(uh).max()))
        np.testing.assert_array_equal(got.u[codes == 0], uh[codes == 0])
        np.testing.assert_array_equal(dec.command(q, uh, obstacles=OBSTACLES), got.u)
        changed += int(np.count_nonzero(codes == 1))
    assert changed >= 10


def _filtered_run(kind: str, dt: float) -> tuple[fl.SimulationResult, SafetyFilter]:
    """A tetrahedron marching head-on through spheres and a box, D_s near its sides."""
    tet = np.array(
        [[0, 0, 0], [1, 0, 0], [0.5, 0.8660254038, 0], [0.5, 0.2886751346, 0.8164965809]]
    )
    formation = fl.Formation.from_template(tet, edges="complete", diameters=0.2)
    obstacles = (
        Sphere(center=[0.3, 0.4, 0.3], radius=0.3),
        Sphere(center=[1.5, 0.3, 0.6], radius=0.35),
        Box(center=[2.6, 0.4, 0.2], size=[0.4, 0.4, 0.4]),
    )
    sf = SafetyFilter(filter=kind, distance=0.9, obstacle_distance=0.2, gamma=1e4)
    q0 = tet + np.array([-2.0, 0.0, 0.0])
    res = fl.simulate(
        formation, fl.get_law("distance", k_c=4.0), q0, duration=4.0,
        integrator=fl.get_integrator("euler", dt=dt),
        marching=Marching(velocity=[1.5, 0.0, 0.0]), obstacles=obstacles, safety=sf,
    )  # fmt: skip
    return res, sf


@pytest.mark.parametrize("kind", ["barrier", "barrier-decentralized"])
def test_a_filtered_run_in_space_keeps_every_pair_and_obstacle_clear(kind: str) -> None:
    """The discrete condition at a step long enough that the continuous one jumps past
    (``dt gamma h^2 > 1``): no saved state has a pair within D_s or a centre within D_o."""
    res, sf = _filtered_run(kind, dt=0.02)
    q = res.q
    iu, ju = np.triu_indices(4, k=1)
    pair = np.linalg.norm(q[:, iu] - q[:, ju], axis=-1)
    centre = clearances(q, np.zeros(4), res.safety.obstacles)[0]
    assert res.status == "success", res.message
    assert pair.min() >= sf.distance * (1 - 1e-9), pair.min()
    assert centre.min() >= sf.d_obstacle - 1e-9, centre.min()
    assert res.safety.active.any()  # the filter did the work
    assert pair.min() < sf.distance + 0.02 or centre.min() < sf.d_obstacle + 0.02


def test_marching_in_space_moves_the_centroid_at_v_ref() -> None:
    tet = np.array(
        [[0, 0, 0], [1, 0, 0], [0.5, 0.8660254038, 0], [0.5, 0.2886751346, 0.8164965809]]
    )
    formation = fl.Formation.from_template(tet, edges="complete", diameters=0.2)
    v = np.array([0.2, -0.1, 0.3])
    res = fl.simulate(formation, fl.get_law("distance"), tet * 1.3, duration=2.0,
                      marching=Marching(velocity=v))  # fmt: skip
    centroid = res.q.mean(axis=1)
    np.testing.assert_allclose(centroid[-1] - centroid[0], v * res.t[-1], rtol=1e-9)
    with pytest.raises(ParameterError, match=r"velocity \[vx, vy\] has 2 components") as err:
        fl.simulate(formation, fl.get_law("distance"), tet * 1.3, duration=0.1,
                    marching=Marching(velocity=[0.2, 0.0]))  # fmt: skip
    assert err.value.key == "velocity"


SPACE = """\
name = "tet"
[robots]
positions = [[0.0, 0.0, 0.0], [1.2, 0.0, 0.0], [0.5, 1.0, 0.0], [0.5, 0.3, 0.9]]
diameters = 0.2
[formation]
edges = "complete"
template = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.8660254038, 0.0],
            [0.5, 0.2886751346, 0.8164965809]]
[controller]
law = "distance"
[simulation]
dt = 1e-2
duration = 0.5
"""


@pytest.mark.parametrize(
    ("base", "extra", "key", "words"),
    [
        (SPACE, "[[obstacles]]\ncircle = { center = [3.0, 0.0], radius = 0.4 }\n", "obstacles",
         ["obstacles, item 1 (line 14)", "a circle is an obstacle in the plane",
          "sphere = { center = [x, y, z], radius = R }"]),
        (SPACE, "[[obstacles]]\nsphere = { center = [3.0, 0.0, 0.0], radius = 0.4 }\n"
                "[[obstacles]]\npolygon = [[3.0, 0.0], [4.0, 0.0], [3.0, 1.0]]\n", "obstacles",
         ["obstacles, item 2 (line 16)", "a polygon is an obstacle in the plane"]),
        (PLANE, "[[obstacles]]\nsphere = { center = [3.0, 0.0, 0.0], radius = 0.4 }\n", "obstacles",
         ["obstacles, item 1 (line 12)", "a sphere is an obstacle in space",
          "circle = { center = [x, y], radius = R }"]),
        (PLANE, "[[obstacles]]\nbox = { center = [3, 0, 0], size = [1, 1, 1] }\n", "obstacles",
         ["obstacles, item 1 (line 12)", "a box is an obstacle in space"]),
        (SPACE, "[[obstacles]]\nbox = { center = [3, 0, 0], size = [1, -1, 1] }\n", "obstacles",
         ["obstacles, item 1 (line 14)", "box size must be three lengths > 0"]),
        (SPACE, "[[obstacles]]\nsphere = { center = [0.5, 0.3, 0.8], radius = 0.2 }\n", "obstacles",
         ["overlaps robot 4's start"]),
        (SPACE, '[safety]\nfilter = "barrier"\nmax_speed = 1.0\n', "safety.max_speed",
         ["safety.max_speed (line 16)", "a formation in space (3-D) has none"]),
        (SPACE, "[marching]\nvelocity = [0.2, 0.0]\n", "marching.velocity",
         ["marching.velocity (line 15)", "give [vx, vy, vz] (space)"]),
        (PLANE, "[marching]\nvelocity = [0.2, 0.0, 0.1]\n", "marching.velocity",
         ["marching.velocity (line 13)", "give [vx, vy] (the plane)"]),
        (SPACE, '[marching]\nkind = "motion-parameters"\nvelocity = [0.2, 0.0, 0.0]\n',
         "marching.kind", ["marching.kind (line 15)", "designed on the shape in the plane"]),
    ],
)  # fmt: skip
def test_scenario_refusals_name_the_key_and_line(base, extra, key, words) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario(base + extra, source="bad.toml")
    assert err.value.key == key
    for w in words:
        assert w in str(err.value), str(err.value)


def test_scenario_in_space_takes_obstacles_filter_and_marching() -> None:
    sc = parse_scenario(
        SPACE + "[marching]\nvelocity = [0.1, 0.0, 0.2]\nleader = 4\n"
        "[[obstacles]]\nsphere = { center = [3.0, 0.0, 0.0], radius = 0.4 }\n"
        "[[obstacles]]\nbox = { center = [0.0, 3.0, 0.0], size = [1.0, 0.5, 2.0] }\n"
        '[safety]\nfilter = "barrier-decentralized"\ndistance = 0.3\n'
    )
    assert [type(o).__name__ for o in sc.obstacles] == ["Sphere", "Box"]
    assert sc.safety is not None and sc.safety.filter == "barrier-decentralized"
    assert sc.marching is not None and sc.marching.leaders == (4,)
    res = fl.scenario.run_scenario(sc)
    assert res.q.shape[-1] == 3 and res.safety is not None
    np.testing.assert_allclose(res.q[-1, 3] - res.q[0, 3], [0.1 * 0.5, 0.0, 0.2 * 0.5], rtol=1e-9)


def test_run_study_and_animate_in_space(tmp_path: Path) -> None:
    """``run`` and ``animate`` draw the spheres and the box; ``study`` of a few trials."""
    runner = CliRunner()
    text = SPACE.replace("duration = 0.5", "duration = 0.3") + (
        "[[obstacles]]\nsphere = { center = [2.5, 0.0, 0.0], radius = 0.4 }\n"
        "[[obstacles]]\nbox = { center = [0.0, 2.5, 0.0], size = [1.0, 0.5, 2.0] }\n"
        '[safety]\nfilter = "barrier"\ndistance = 0.3\n'
        '[study]\ntrials = 3\ninitial = { kind = "box", half_width = 1.0 }\nlaws = ["distance"]\n'
    )
    path = tmp_path / "tet.toml"
    path.write_text(text)
    res = runner.invoke(app, ["run", str(path), "--out", str(tmp_path / "run"), "--quiet"])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert [next(iter(o)) for o in summary["safety"]["obstacles"]] == ["sphere", "box"]
    res = runner.invoke(app, ["animate", str(tmp_path / "run"), "--format", "gif", "--frames", "4"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "run" / "animation.gif").stat().st_size > 0
    res = runner.invoke(app, ["study", str(path), "--out", str(tmp_path / "study"), "--quiet"])
    assert res.exit_code == 0, res.output
    study = json.loads((tmp_path / "study" / "summary.json").read_text())
    assert sum(study["groups"][0]["counts"].values()) == 3


def test_animation_in_space_draws_obstacles_and_active_robots() -> None:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from formationlab.plotting.animation import animate_run

    t = np.linspace(0.0, 1.0, 5)
    q = np.zeros((5, 2, 3))
    q[:, 1, 0] = 1.0 + t
    active = np.zeros((5, 2), bool)
    active[:, 0] = True
    anim = animate_run(t, q, edges=[[0, 1]], diameters=[0.2, 0.2], max_frames=5,
                       obstacles=OBSTACLES, active=active)  # fmt: skip
    anim._draw_was_started = True  # drawn by hand below (matplotlib warns if never drawn)
    ax = anim._fig.axes[0]
    faces = [c for c in ax.collections if isinstance(c, Poly3DCollection)]
    assert len(faces) == 2  # the sphere's surface and the box
    assert {t.get_text() for t in ax.texts} >= {"O1", "O2"}
    anim._draw_frame(0)
    points = [
        c for c in ax.collections if hasattr(c, "get_edgecolor") and len(c.get_offsets()) == 2
    ]
    edge = points[-1].get_edgecolor()
    np.testing.assert_allclose(edge[0][:3], (0.862745, 0.078431, 0.235294), atol=1e-5)  # crimson
