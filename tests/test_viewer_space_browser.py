"""The view of a formation in space in headless chromium (three.js on WebGL, SwiftShader):
the scene renders every robot, the camera orbits, and a robot dragged with the mouse moves
on the server in the plane facing the camera."""

from __future__ import annotations

from io import BytesIO

import numpy as np
import pytest
from _viewer import ROOT, ROOT_SEL, attr, launch_chromium, pause, viewer_page, wait_for
from PIL import Image
from playwright.sync_api import sync_playwright

from formationlab.io.scenario import load_scenario
from formationlab.viewer import LiveSession

TETRA = ROOT / "examples" / "space" / "tetrahedron-mirror.toml"


@pytest.fixture(scope="module")
def space():
    session = LiveSession(load_scenario(TETRA), seed=1)
    with sync_playwright() as p:
        browser = launch_chromium(p, webgl=True)
        with viewer_page(browser, session) as page:
            yield page, session
        browser.close()


def hook(page, call):
    return page.evaluate(f"document.querySelector('{ROOT_SEL}').flv.{call}")


def test_the_scene_renders_every_robot_in_space(space):
    page, session = space
    wait_for(lambda: int(attr(page, "frames")) > 3, what="frames drawn")
    assert attr(page, "dim") == "3"
    assert int(attr(page, "robots")) == session.formation.n == 4
    assert page.is_visible("canvas[data-role=scene3d]")
    assert not page.is_visible("canvas[data-role=scene]")  # the plane's canvas is not used
    assert {"robots", "edges", "trails"} <= set(hook(page, "legend()"))
    t = session.t
    wait_for(lambda: float(attr(page, "t")) > t, what="the run to stream")
    pause(page, session)
    # the pixels: a robot's colour (#1f6fb5, shaded) where robot 1's centre is drawn, and
    # the background's white around the formation
    # (the camera eases towards the formation for a few frames after it moves: the shot is
    # taken when robot 1's pixel is the same before and after it, on a loaded machine too)
    box = page.locator("canvas[data-role=scene3d]").bounding_box()
    for _ in range(50):
        before = hook(page, "robotPx(1)")
        shot = page.screenshot(clip=box)
        if hook(page, "robotPx(1)") == before:
            break
    else:
        raise AssertionError("the camera did not come to rest")
    img = np.asarray(Image.open(BytesIO(shot)).convert("RGB"), dtype=int)
    x, y = before
    r, g, b = img[round(y - box["y"]), round(x - box["x"])]
    assert b > r + 40 and b > 90, (r, g, b)
    # the background's white: most of the picture (a corner may hold a trail or an edge,
    # as the camera frames the formation)
    white = (img == 255).all(axis=-1).mean()
    assert white > 0.5, white


def test_drag_a_robot_in_the_plane_facing_the_camera_then_orbit(space):
    page, session = space
    pause(page, session)
    q0 = session.q.copy()
    # a robot whose drawing overlaps no other's
    px = np.array([hook(page, f"robotPx({i})") for i in range(1, 5)])
    gaps = [min(np.linalg.norm(px[i] - px[j]) for j in range(4) if j != i) for i in range(4)]
    i = int(np.argmax(gaps))
    assert gaps[i] > 30
    camera = hook(page, "camera()")
    x0, y0 = px[i]
    page.mouse.move(x0, y0)
    page.mouse.down()
    for k in range(1, 11):
        page.mouse.move(x0 + 7 * k, y0 - 3 * k)
    wait_for(lambda: session.pinned == i and np.linalg.norm(session.q[i] - q0[i]) > 0.05,
             what="the robot dragged on the server")  # fmt: skip
    wait_for(lambda: np.allclose(hook(page, f"robotPx({i + 1})"), [x0 + 70, y0 - 30], atol=2),
             what="the robot drawn under the pointer")  # fmt: skip
    dq = session.q[i] - q0[i]
    # in the plane facing the camera through the robot's centre: no motion along the view
    assert abs(np.dot(dq, camera["direction"])) < 1e-3 * np.linalg.norm(dq)
    assert abs(dq[2]) > 1e-3  # a drag in space moves z as well (this camera looks down)
    others = [j for j in range(4) if j != i]
    np.testing.assert_allclose(session.q[others], q0[others], atol=0)  # paused: only it moved
    page.mouse.up()
    wait_for(lambda: session.pinned is None, what="the release")
    # orbit: a drag on empty space turns the camera and moves no robot
    before, q1 = hook(page, "camera()"), session.q.copy()
    box = page.locator("canvas[data-role=scene3d]").bounding_box()
    page.mouse.move(box["x"] + 20, box["y"] + box["height"] - 20)
    page.mouse.down()
    for k in range(1, 6):
        page.mouse.move(box["x"] + 20 + 12 * k, box["y"] + box["height"] - 20 - 4 * k)
    page.mouse.up()
    after = hook(page, "camera()")
    assert np.linalg.norm(np.subtract(after["direction"], before["direction"])) > 0.05
    np.testing.assert_array_equal(session.q, q1)
    assert session.pinned is None
    assert attr(page, "errors") == "0"
