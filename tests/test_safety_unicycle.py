"""Unicycles in the filtered closed loop, through their near-identity points.

The filter acts on the points ``p_i = q_i + l (cos theta_i, sin theta_i)`` with the
distance ``D_s + 2 l`` (``point_safety_distance``; docs/safety.md, Unicycles): then
``|q_i - q_j| >= |p_i - p_j| - 2 l >= D_s``. From starts where the unfiltered unicycles
collide, under either filter the points keep ``D_s + 2 l`` at every step, and the centres
``D_s`` at every step and along every step (the straight segment an Euler step moves a
centre, the contact rule's swept test).
"""

import warnings

import numpy as np
import pytest

from formationlab.controllers import SquaredDistanceLaw
from formationlab.dynamics import System
from formationlab.formation.spec import Formation
from formationlab.models import Unicycle
from formationlab.safety import SafetyFilter, point_safety_distance, unicycle_points
from formationlab.studies.batch import run_batch

SQUARE = Formation.from_template([[0, 0], [1, 0], [1, 1], [0, 1]], orientation="free")
D_S, ELL, DT, STEPS = 0.25, 0.05, 1e-3, 1500
IU, JU = np.triu_indices(4, 1)


def _swept_centres(x0, x1):
    """Least centre distance over each straight Euler step; (B,)."""
    r0 = x0[:, JU, :2] - x0[:, IU, :2]
    dr = (x1[:, JU, :2] - x1[:, IU, :2]) - r0
    dd = np.sum(dr * dr, -1)
    s = np.clip(-np.sum(r0 * dr, -1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    m = r0 + s[..., None] * dr
    return np.sqrt(np.sum(m * m, -1)).min(-1)


@pytest.fixture(scope="module")
def colliding_unicycles():
    """Unicycle states (x, y, theta) from which the unfiltered squared-distance law collides."""
    rng = np.random.default_rng(7)
    p0 = []
    while len(p0) < 80:
        p = rng.uniform(-1.0, 1.0, (4, 2))
        d = np.linalg.norm(p[:, None] - p[None], axis=-1) + 9 * np.eye(4)
        if d.min() > D_S + 2 * ELL + 0.02:  # the points start outside D_s + 2 l
            p0.append(p)
    theta = rng.uniform(-np.pi, np.pi, (80, 4))
    heading = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    x0 = np.concatenate([np.stack(p0) - ELL * heading, theta[..., None]], axis=-1)
    plain = System(formation=SQUARE, law=SquaredDistanceLaw(), model=Unicycle(offset=ELL))
    x, hit = x0.copy(), np.zeros(len(x0), bool)
    for _ in range(STEPS):
        x1 = x + DT * plain.rhs(x)
        hit |= _swept_centres(x, x1) <= SQUARE.contact_matrix[0, 1]
        x = x1
    assert hit.sum() >= 20, "the unfiltered unicycles should collide from many of these starts"
    return x0[hit][:20]


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["barrier-decentralized", "barrier"])
def test_unicycle_points_keep_the_enlarged_distance(kind, colliding_unicycles):
    cfg = SafetyFilter(filter=kind, distance=point_safety_distance(D_S, ELL), gamma=100.0)
    model = Unicycle(offset=ELL)
    system = System(formation=SQUARE, law=SquaredDistanceLaw(), model=model, safety=cfg)
    x = colliding_unicycles.copy()
    least_points = least_centres = least_swept = np.inf
    for _ in range(STEPS):
        x1 = x + DT * system.rhs(x)  # explicit Euler, as the driver
        p = unicycle_points(x1[..., :2], x1[..., 2], ELL)
        least_points = min(least_points, np.linalg.norm(p[:, JU] - p[:, IU], axis=-1).min())
        q = x1[..., :2]
        least_centres = min(least_centres, np.linalg.norm(q[:, JU] - q[:, IU], axis=-1).min())
        least_swept = min(least_swept, _swept_centres(x, x1).min())
        x = x1
    assert least_points >= D_S + 2 * ELL  # at every step
    assert least_centres >= D_S and least_swept >= D_S  # at every step and along the steps
    assert least_points < D_S + 2 * ELL + 0.1  # the filter did act (the law drives them in)
    # the compiled batch path steps the same closed loop: no trial collides
    res = run_batch(SQUARE, SquaredDistanceLaw(), colliding_unicycles, dt=DT,
                    duration=STEPS * DT, model=model, safety=cfg)  # fmt: skip
    assert "collision" not in set(res.outcome)
    assert np.all(res.min_clearance >= D_S - SQUARE.contact_matrix[0, 1])


def _heading_starts(n_starts: int) -> np.ndarray:
    """Heading-mapped unicycle states (x, y, theta) on the square, clear of D_s."""
    rng = np.random.default_rng(11)
    out = []
    while len(out) < n_starts:
        p = rng.uniform(-3.0, 3.0, (4, 2))
        d = np.linalg.norm(p[:, None] - p[None], axis=-1) + 9 * np.eye(4)
        if d.min() > 0.32:
            out.append(np.column_stack([p, rng.uniform(-np.pi, np.pi, 4)]))
    return np.stack(out)


def test_heading_unicycles_get_a_warning_because_the_filter_does_not_hold_them():
    """Under "heading" a unicycle turns towards its command before following it, so the
    certificate (the command is the centres' velocity) does not hold: a warning, and a
    run where filtered robots still touch shows why it is one."""
    from formationlab.errors import FormationlabWarning

    cfg = SafetyFilter(filter="barrier-decentralized", distance=0.3)
    model = Unicycle(mapping="heading")
    with pytest.warns(FormationlabWarning, match="does not follow"):
        System(formation=SQUARE, law=SquaredDistanceLaw(), model=model, safety=cfg)
    with warnings.catch_warnings():
        warnings.simplefilter("error", FormationlabWarning)  # near-identity: no warning
        System(formation=SQUARE, law=SquaredDistanceLaw(), model=Unicycle(), safety=cfg)
    with pytest.warns(FormationlabWarning):
        res = run_batch(SQUARE, SquaredDistanceLaw(), _heading_starts(100), dt=1e-2,
                        duration=15.0, model=model, safety=cfg)  # fmt: skip
    assert "collision" in set(res.outcome)  # 9 of 100 when written (44 without the filter)


def test_double_integrators_refuse_a_filter_whose_certificate_they_cannot_follow(tmp_path):
    """A double integrator's command is a force: the filter would report its commands
    unchanged while robots meet (seen before this check). Refused, in Python and files."""
    from typer.testing import CliRunner

    from formationlab.cli import _load_commands, app
    from formationlab.errors import ParameterError
    from formationlab.models import DoubleIntegrator

    cfg = SafetyFilter(filter="barrier", distance=D_S)
    with pytest.raises(ParameterError, match="command is a force") as err:
        System(formation=SQUARE, law=SquaredDistanceLaw(), model=DoubleIntegrator(), safety=cfg)
    assert err.value.key == "filter"
    System(formation=SQUARE, law=SquaredDistanceLaw(), model=DoubleIntegrator(),
           safety=SafetyFilter(filter="none"))  # fmt: skip
    text = (
        "[robots]\npositions = [[0, 0], [2, 0], [2, 2], [0, 2]]\n"
        'model = "double-integrator"\n[formation]\nedges = "complete"\n'
        "template = [[0, 0], [1, 0], [1, 1], [0, 1]]\n"
        '[controller]\nlaw = "squared-distance"\n[simulation]\nduration = 1.0\n'
        "[study]\ntrials = 4\n"
    )
    plain, filtered = tmp_path / "plain.toml", tmp_path / "filtered.toml"
    plain.write_text(text)
    filtered.write_text(text + '[safety]\nfilter = "barrier-decentralized"\n')
    _load_commands()
    cli = CliRunner()
    for args in (
        ["validate", str(filtered)],
        ["run", str(filtered), "-o", str(tmp_path / "run")],
        ["study", str(filtered), "-o", str(tmp_path / "study")],
        ["study", str(plain), "--filter", "barrier", "-o", str(tmp_path / "study2")],
    ):
        res = cli.invoke(app, args)
        assert res.exit_code == 2, res.output
        assert "Traceback" not in res.output and "command is a force" in res.output
    assert "safety.filter (line 14)" in cli.invoke(app, ["validate", str(filtered)]).output
    assert not any((tmp_path / d).exists() for d in ("run", "study", "study2"))
