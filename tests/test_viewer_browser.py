"""End to end in headless chromium (Debian's, through Playwright): draw, drag, switch, export."""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import pytest
from _scenarios import lattice
from _viewer import (
    ROOT_SEL,
    attr,
    launch_chromium,
    pause,
    serving,
    sim2_session,
    viewer_page,
    wait_for,
)
from playwright.sync_api import sync_playwright

import formationlab as fl
from formationlab.cli import main
from formationlab.io.scenario import load_scenario


@pytest.fixture(scope="module")
def browser():
    with sync_playwright() as p:
        b = launch_chromium(p)
        yield b
        b.close()


@pytest.fixture
def live(browser):
    session = sim2_session()
    with viewer_page(browser, session, accept_downloads=True) as page:
        yield page, session


def flv(page, what):
    """What the page's test hooks say (``axes``, ``view``, ``plots``, ``legend``)."""
    return page.evaluate(f"document.querySelector('{ROOT_SEL}').flv.{what}()")


def test_page_draws_every_robot_and_streams(live):
    page, session = live
    wait_for(lambda: int(attr(page, "frames")) > 20, what="20 frames drawn")
    assert int(attr(page, "robots")) == session.formation.n == 3
    t0 = session.t
    wait_for(lambda: session.t > t0 + 0.1, what="the run to advance")
    assert attr(page, "errors") == "0"


def test_drag_robot_1_moves_it_on_the_server_and_the_run_continues(live):
    page, session = live
    pause(page, session)
    start = session.q[0].copy()
    x0, y0 = page.evaluate(f"document.querySelector('{ROOT_SEL}').flv.robotPx(1)")
    # a drop inside the view (which follows the formation): near its top left corner
    left, top, right, bottom = flv(page, "view")["world"]
    drop = [left + 0.15 * (right - left), top - 0.15 * (top - bottom)]
    tx, ty = page.evaluate(
        f"document.querySelector('{ROOT_SEL}').flv.worldToPage({drop[0]}, {drop[1]})"
    )
    page.mouse.move(x0, y0)
    page.mouse.down()
    for k in range(1, 11):
        page.mouse.move(x0 + (tx - x0) * k / 10, y0 + (ty - y0) * k / 10)
        page.wait_for_timeout(20)
    # robot 1 follows the pointer: the server's state, drawn by the page, puts it under the
    # pointer (the page's own mapping at that moment: the view may have followed the
    # formation's extent during the drag, on a loaded machine more than otherwise)

    def under_pointer() -> bool:
        px = page.evaluate(f"document.querySelector('{ROOT_SEL}').flv.robotPx(1)")
        return bool(np.hypot(px[0] - tx, px[1] - ty) < 4.0)

    wait_for(under_pointer, what="robot 1 under the pointer")
    moved = np.linalg.norm(session.q[0] - start)
    assert moved > 0.5 * np.linalg.norm(np.asarray(drop) - start), (moved, drop, start)
    page.mouse.up()
    wait_for(lambda: session.pinned is None, what="the release")
    dropped, t_drop = session.q[0].copy(), session.t
    page.click("button[data-role=pause]")  # run on
    wait_for(lambda: session.t > t_drop + 0.2, what="the run to continue")
    assert np.linalg.norm(session.q[0] - dropped) > 1e-3  # robot 1 moves on from the drop


def test_switching_the_law_changes_the_motion(live):
    page, session = live
    pause(page, session)
    q0 = session.q.copy()
    page.select_option("select[data-role=law]", "distance")
    wait_for(lambda: session.law.name == "distance", what="the law switch")
    steps = session.steps
    page.fill("input[data-role=step-count]", "50")
    page.click("button[data-role=step]")
    wait_for(lambda: session.steps == steps + 50, what="50 steps")
    f, euler = session.formation, fl.Euler(dt=1e-3)
    ref = {}
    for law in (fl.DistanceLaw(k_c=2.0), session.scenario.law):
        system, q = fl.System(formation=f, law=law), q0.copy()
        for _ in range(50):
            q = euler.step(system, q, 1e-3)
        ref[law.name] = q
    np.testing.assert_allclose(session.q, ref["distance"], rtol=0, atol=1e-12)
    assert np.linalg.norm(ref["distance"] - ref["angle-restricted"]) > 1e-2


def test_export_downloads_a_scenario_that_validates(live, tmp_path, capsys):
    page, session = live
    pause(page, session)
    with page.expect_download() as dl:
        page.click("button[data-role=export]")
    path = tmp_path / dl.value.suggested_filename
    dl.value.save_as(path)
    with pytest.raises(SystemExit) as exc:
        main(["validate", str(path)])
    assert exc.value.code in (0, None)
    assert capsys.readouterr().out.startswith("ok:")
    np.testing.assert_array_equal(load_scenario(path).q0, session.q)


def test_switching_lines_lie_where_sigma_vanishes(live):
    page, session = live
    pause(page, session)
    f, law, q = session.formation, session.law, session.q.copy()
    (tri,), (beta,) = f.surfaces[0], f.surfaces[1]
    flat = [float(v) for v in q.ravel()]
    for a, b, c in ((tri[0], tri[1], tri[2]), (tri[1], tri[2], tri[0]), (tri[2], tri[0], tri[1])):
        seg = page.evaluate(
            f"([p, a, b, c, beta, th]) => document.querySelector('{ROOT_SEL}')"
            ".flv.switchingLine(new Float32Array(p), a, b, c, beta, th)",
            [flat, int(a), int(b), int(c), float(beta), law.theta],
        )
        for end in (seg[:2], seg[2:]):  # both ends of line s of robot a: sigma = 0 there
            moved = q.copy()
            moved[a] = end
            assert law.switching(f, moved)[0] == pytest.approx(0.0, abs=1e-5)  # float32 input


def test_screenshot_is_kept(live, tmp_path):
    page, _ = live
    wait_for(lambda: int(attr(page, "frames")) > 5, what="frames")
    shot = tmp_path / "viewer.png"
    page.screenshot(path=str(shot))
    data = shot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_png_snapshot_download(live, tmp_path):
    page, _ = live
    with page.expect_download() as dl:
        page.click("button[data-role=png]")
    path = tmp_path / dl.value.suggested_filename
    dl.value.save_as(path)
    assert path.suffix == ".png" and path.read_bytes()[:4] == b"\x89PNG"


def test_bad_gain_is_refused_on_the_page(live):
    page, session = live
    page.fill("input[data-role=param-k_c]", "0")
    page.dispatch_event("input[data-role=param-k_c]", "change")
    wait_for(lambda: int(attr(page, "errors")) >= 1, what="the error on the page")
    assert "k_c" in attr(page, "last-error") and session.law.k_c == 2.0
    wait_for(lambda: page.input_value("input[data-role=param-k_c]") == "2", what="value back")


def test_replay_with_the_time_slider(browser, tmp_path):
    import tomli_w
    from _viewer import SIM2

    from formationlab.scenario import parse_scenario
    from formationlab.viewer.sources import open_session

    raw = dict(parse_scenario(SIM2.read_text()).raw)
    raw["simulation"] = {**raw["simulation"], "duration": 0.5}
    sc = tmp_path / "short.toml"
    sc.write_text(tomli_w.dumps(raw))
    with pytest.raises(SystemExit):
        main(["run", str(sc), "--out", str(tmp_path / "run"), "--save-every", "10", "-q"])
    session = open_session(tmp_path / "run")
    with serving(session) as srv:
        page = browser.new_page(viewport={"width": 1100, "height": 720})
        page.goto(srv.url)
        page.wait_for_selector(f"{ROOT_SEL}[data-state=ready]", timeout=15_000)
        assert page.get_attribute("input[data-role=slider]", "max") == "50"
        page.click("button[data-role=pause]")
        wait_for(lambda: session.paused, what="pause")
        page.fill("input[data-role=slider]", "25")
        wait_for(lambda: session.index == 25, what="the seek")
        wait_for(lambda: abs(float(attr(page, "t")) - 0.25) < 1e-9, what="frame 25 drawn")
        assert int(attr(page, "robots")) == 3
        # the switching events the plots mark: the saved sigma's, all within the run
        switches = session.info()["series"]["switches"]
        assert attr(page, "switches") == str(len(switches))
        assert all(0 < t <= 0.5 for t in switches)
        page.close()


def test_page_shows_headings_obstacles_filter_activity_and_reference(browser):
    """A scenario with unicycles, an obstacle, a safety filter and marching: the page
    draws the headings, the obstacle, rings around the robots whose commands the filter
    changed, and the reference arrow, and says so in its status line."""
    from pathlib import Path

    from formationlab.viewer import LiveSession

    path = Path(__file__).with_name("data") / "viewer-everything.toml"
    session = LiveSession(load_scenario(path), seed=1)
    session.set_paused(True)
    session.step(20)
    with drawn_page(browser, session, robots=3) as page:
        assert attr(page, "obstacles") == "1"
        assert attr(page, "headings") == "3"
        assert attr(page, "filtered") == "1,2,3"
        assert attr(page, "reference") == "0.2,0"
        status = page.text_content(f"{ROOT_SEL} [data-role=status]")
        assert "filter barrier-decentralized: changed robots 1, 2, 3" in status
        assert "v_ref = (0.2" in status


def test_page_draws_an_arrow_from_each_leader_with_its_own_velocity(browser):
    """The scaling maneuver (a velocity per leader): an arrow from each leader, and the
    leaders' velocities in the status line."""
    from pathlib import Path

    from formationlab.viewer import LiveSession

    path = Path(__file__).parents[1] / "examples" / "bearing-hexagon-scaling.toml"
    session = LiveSession(load_scenario(path), seed=1)
    session.set_paused(True)
    session.step(5)
    assert session.info()["marching"] == {"kind": "reference", "leader": (1, 4)}
    with drawn_page(browser, session, robots=6) as page:
        assert attr(page, "reference") == "0.02,0,-0.02,0"
        status = page.text_content(f"{ROOT_SEL} [data-role=status]")
        assert "leaders' v_ref = (0.02, 0) (-0.02, 0)" in status, status


@contextmanager
def drawn_page(browser, session, *, robots: int):
    """The page of ``session`` once its first frame of ``robots`` robots is drawn; no error
    of the page's script is allowed."""
    with serving(session) as srv:
        page = browser.new_page(viewport={"width": 1100, "height": 720})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(srv.url)
        page.wait_for_selector(f"{ROOT_SEL}[data-state=ready]", timeout=15_000)
        wait_for(lambda: attr(page, "robots") == str(robots), what="the first frame drawn")
        yield page
        page.close()
        assert not errors, errors


def test_the_page_reads_like_a_plot(browser):
    """One page, several checks (a page costs seconds): the drawing takes the window, its
    grid is in metres with tick labels and a scale bar that match the drawing's scale, the
    legend names the layers drawn, the view follows the formation's extent now and a key
    fits the start, and the plots have a log V, the edge legend and the speed reached."""
    session = sim2_session()
    session.set_paused(True)
    with drawn_page(browser, session, robots=3) as page:
        # the drawing uses the window: at most the status lines and padding below it
        box = page.locator("[data-role=scene]").bounding_box()
        assert box["height"] >= 720 - 80 and box["width"] >= 1100 - 330 - 60
        # axes: ticks every `step` metres, `scale` pixels per metre apart, labelled in metres
        axes, view = flv(page, "axes"), flv(page, "view")
        step, scale = axes["step"], view["scale"]
        assert step * scale == pytest.approx(np.diff([p for _, p in axes["x"]]).mean(), rel=1e-6)
        mantissa = step / 10 ** np.floor(np.log10(step))
        assert min(abs(mantissa - m) for m in (1, 2, 5, 10)) < 1e-9
        for value, px in axes["x"][:3]:  # each tick where its value in metres is drawn
            there = page.evaluate(
                f"document.querySelector('{ROOT_SEL}').flv.worldToPage({value}, 0)"
            )
            assert there[0] - box["x"] == pytest.approx(px, abs=1e-6)
        bar = axes["bar"]
        assert bar["px"] == pytest.approx(bar["metres"] * scale, rel=1e-9)
        assert 0.1 * view["w"] <= bar["px"] <= 0.25 * view["w"] + 1e-9
        # the legend: the layers drawn at the start of simulation 2
        assert flv(page, "legend") == ["robots", "edges", "active", "lines"]
        legend_text = page.text_content(f"{ROOT_SEL} [data-role=legend]")
        assert "switching lines s (eq. 26)" in legend_text and "active restriction" in legend_text
        # fit: the 6 m start fills the view; after 3 s the 1 m triangle still does
        start = flv(page, "view")["start"]
        x0, y0, x1, y1 = view["world"]
        assert x0 <= start[0] and x1 >= start[1] and y1 <= start[2] and y0 >= start[3]
        page.fill("input[data-role=step-count]", "3000")
        page.click("button[data-role=step]")
        wait_for(lambda: abs(float(attr(page, "t")) - 3.0) < 1e-9, what="the state at 3 s drawn")
        q = session.q
        extent = max(np.ptp(q[:, 0]), np.ptp(q[:, 1])) + max(session.formation.diameters)
        wait_for(lambda: extent * flv(page, "view")["scale"] >= 0.4 * 666, what="a refit")
        near = flv(page, "view")["scale"]
        page.click("[data-role=scene]", position={"x": 5, "y": 5})
        page.keyboard.press("s")  # the start again
        wait_for(lambda: flv(page, "view")["mode"] == "start", what="the key s")
        wait_for(lambda: flv(page, "view")["scale"] < near / 3, what="the start fitted")
        page.keyboard.press("f")
        wait_for(lambda: flv(page, "view")["scale"] == pytest.approx(near), what="fit now")
        # plots: V > 0 on a log axis; one line and legend entry per edge (three edges)
        plots = flv(page, "plots")
        assert plots["v"]["log"] and not plots["v"]["negative"]
        assert plots["e"]["lines"] == ["1-2", "1-3", "2-3"] and not plots["e"]["band"]
        # running: the speed reached next to the one asked for
        page.click("button[data-role=pause]")
        wait_for(lambda: attr(page, "reached"), timeout=15, what="the speed reached")
        label = page.text_content(f"{ROOT_SEL} .flv-speed")
        assert label.startswith("x1 (reached x") and float(attr(page, "reached")) > 0
        # a switching event marked: a perturbation (seeded) turns the restriction off
        assert attr(page, "switches") == "0"
        pause(page, session)
        page.fill("input[data-role=perturb-scale]", "1")
        page.click("button[data-role=perturb]")
        page.fill("input[data-role=step-count]", "3000")
        page.click("button[data-role=step]")
        wait_for(lambda: int(attr(page, "switches")) >= 1, what="a switching event marked")
        assert flv(page, "plots")["v"]["switches"] >= 1


def test_many_edges_plot_the_worst_and_a_band(browser):
    """More edges than colours: the five worst edges as lines with a legend row that
    stays within the plot (no overprinted title), and every edge as a band."""
    from formationlab.scenario import parse_scenario
    from formationlab.viewer import LiveSession

    session = LiveSession(parse_scenario(lattice(30)), seed=1)
    session.set_paused(True)
    assert len(session.formation.edges) > 24
    session.step(5)
    with drawn_page(browser, session, robots=session.formation.n) as page:
        wait_for(lambda: flv(page, "plots")["e"], what="the error plot")
        e = flv(page, "plots")["e"]
        worst = session.frame().header["worst"]["edges"]
        edges = session.formation.edges + 1
        assert e["band"] and e["lines"] == [f"{edges[k - 1][0]}-{edges[k - 1][1]}" for k in worst]
        assert e["legend"] == [f"all {len(edges)} edges (band); worst 5:", *e["lines"]]
