"""The viewer with formations in space (``Formation.dim == 3``): session, protocol, replay."""

from __future__ import annotations

import dataclasses
import json

import httpx
import numpy as np
import pytest
from _viewer import ROOT, serving

import formationlab as fl
from formationlab.io.netcdf import write_trajectory
from formationlab.io.scenario import load_scenario
from formationlab.scenario import parse_scenario, run_scenario
from formationlab.viewer import Controller, LiveSession, SessionError
from formationlab.viewer.assets import THREE_FILES, three_module
from formationlab.viewer.messages import decode_binary, encode_binary
from formationlab.viewer.sources import open_session
from formationlab.viewer.widget import Viewer

SPACE = ROOT / "examples" / "space"
TETRA = SPACE / "tetrahedron-mirror.toml"
QUAD = SPACE / "drones-quadrotor.toml"


def tetra_session() -> LiveSession:
    return LiveSession(load_scenario(TETRA), seed=1)


def frame_of(reply):
    """The header and the positions ``(n, d)`` of a frame reply, through the wire format."""
    header, buffers = decode_binary(encode_binary(reply.header, reply.buffers))
    return header, np.frombuffer(buffers[0], dtype="<f4")


def test_steps_in_space_equal_the_simulator():
    s = tetra_session()
    assert s.step(150) == 150
    sc = s.scenario
    ref = fl.simulate(
        sc.formation, sc.law, sc.q0, duration=0.3, integrator=sc.integrator, backend="numpy"
    )
    assert ref.q.shape[-1] == 3
    np.testing.assert_allclose(s.q, ref.q[-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(s.trajectory().positions, ref.q, rtol=0, atol=1e-12)


def test_quadrotor_steps_equal_the_simulator():
    s = LiveSession(load_scenario(QUAD), seed=1)
    s.step(40)
    sc = s.scenario
    ref = fl.simulate(
        sc.formation, sc.law, sc.q0, duration=0.2, integrator=sc.integrator, model=sc.model,
        backend="numpy",
    )  # fmt: skip
    np.testing.assert_allclose(s.state, ref.x[-1], rtol=0, atol=1e-12)


def test_info_and_frames_carry_the_third_coordinate():
    s = tetra_session()
    c = Controller(s)
    info, frame = c.hello()
    assert info.header["dim"] == 3
    assert info.header["surfaces"] == {"tetrahedra": [[1, 2, 3, 4]], "beta": [-1.0]}
    assert "chirality-restricted" in info.header["laws"]
    assert "angle-restricted" not in info.header["laws"]  # a law of the plane
    header, pos = frame_of(frame)
    np.testing.assert_allclose(pos.reshape(4, 3), s.scenario.q0, atol=1e-6)
    assert header["heading"] is False
    assert header["active"] == [1]  # started near the mirror: the restriction is on


def test_a_drag_moves_the_robot_in_space_and_holds_it():
    s = tetra_session()
    c = Controller(s)
    c.hello()
    replies = c.handle(json.dumps({"type": "drag", "robot": 2, "x": -2.5, "y": 0.4, "z": 1.7}))
    header, pos = frame_of(replies[-1])
    np.testing.assert_allclose(pos.reshape(4, 3)[1], [-2.5, 0.4, 1.7], atol=1e-6)
    assert header["pinned"] == 2
    others = s.q[[0, 2, 3]].copy()
    s.step(100)
    np.testing.assert_array_equal(s.q[1], [-2.5, 0.4, 1.7])  # held where the pointer is
    assert np.linalg.norm(s.q[[0, 2, 3]] - others) > 1e-3  # the others respond
    c.handle(json.dumps({"type": "release"}))
    s.step(100)
    assert np.linalg.norm(s.q[1] - [-2.5, 0.4, 1.7]) > 1e-4
    # without z the robot keeps its height
    z = s.q[2, 2]
    s.drag(3, 1.0, 3.0)
    np.testing.assert_array_equal(s.q[2], [1.0, 3.0, z])
    with pytest.raises(SessionError, match=r"robot 1 at \(1, 3, [-0-9.]+\) would overlap robot 3"):
        s.drag(1, *s.q[2])


def test_a_drag_in_space_stops_a_quadrotor_and_a_z_in_the_plane_is_refused():
    s = LiveSession(load_scenario(QUAD), seed=1)
    s.step(40)
    assert np.abs(s.state[:, 3:]).max() > 1e-3  # moving
    s.drag(4, -1.0, 0.6, 4.0)
    np.testing.assert_array_equal(s.state[3], [-1.0, 0.6, 4.0, 0.0, 0.0, 0.0])
    plane = LiveSession(load_scenario(ROOT / "examples" / "paper-simulation-2.toml"), seed=1)
    reply = Controller(plane).handle(
        json.dumps({"type": "drag", "robot": 1, "x": 0.0, "y": 0.0, "z": 1.0})
    )
    assert reply[0].header["code"] == "refused"
    assert "in the plane; send x and y only" in reply[0].header["message"]


def test_perturb_moves_every_robot_in_all_three_axes():
    s = tetra_session()
    s.set_paused(True)
    q = s.q.copy()
    s.perturb(0.05)
    dq = s.q - q
    assert np.all(np.abs(dq) > 0)  # every coordinate, z included
    assert 0.005 < np.std(dq) < 0.2


def test_export_in_space_runs_from_the_state_shown():
    s = LiveSession(load_scenario(QUAD), seed=1)
    s.step(30)
    _, text = s.export_scenario()
    sc = parse_scenario(text, source="<test>")
    np.testing.assert_allclose(sc.x0, s.state, rtol=0, atol=1e-12)  # positions and velocities
    assert sc.formation.dim == 3


def test_replay_of_a_run_in_space(tmp_path):
    sc = load_scenario(TETRA)  # what `formationlab run` writes (without its figures)
    res = run_scenario(dataclasses.replace(sc, duration=0.2), backend="numpy")
    out = tmp_path / "run"
    out.mkdir()
    write_trajectory(
        res, out / "trajectory.nc", attrs={"scenario": sc.text, "scenario_name": sc.name}
    )
    s = open_session(out)
    info = s.info()
    assert info["dim"] == 3 and info["n"] == 4
    assert info["surfaces"]["tetrahedra"] == [[1, 2, 3, 4]]
    s.seek(info["frames"] - 1)
    ref = tetra_session()
    ref.step(100)
    np.testing.assert_allclose(s.frame().positions, ref.q, atol=1e-6)  # float32 on the wire
    assert s.frame().heading is None  # three numbers per robot are a position, not x, y, theta
    with pytest.raises(SessionError, match="a replay cannot move robots"):
        s.drag(1, 0.0, 0.0, 1.0)


def test_three_js_is_served_from_the_package_and_given_to_the_widget():
    controls = three_module("OrbitControls.js")
    assert "from './three.module.min.js';" in controls and "from 'three';" not in controls
    assert 'from"./three.core.min.js"' in three_module("three.module.min.js")
    with serving(tetra_session()) as srv:
        base = f"http://{srv.host}:{srv.port}"
        js = httpx.get(f"{base}/three/three.core.min.js")  # no token: it carries no data
        assert js.status_code == 200 and js.headers["content-type"].startswith("text/javascript")
        assert "Copyright 2010-2025 Three.js Authors" in js.text
        assert httpx.get(f"{base}/three/../server.py").status_code == 404
        assert httpx.get(f"{base}/three/three.webgpu.js").status_code == 404
    assert set(Viewer(load_scenario(TETRA))._three) == set(THREE_FILES)
    assert Viewer(ROOT / "examples" / "paper-simulation-2.toml")._three == {}  # the plane


def test_spheres_and_boxes_reach_the_page():
    """The obstacles in space as the page draws them: a sphere's centre has three
    coordinates, a box has its centre and size (the scenario's numbers)."""
    sc = load_scenario(ROOT / "examples" / "space" / "tetrahedron-spheres.toml")
    shapes = LiveSession(sc, seed=1).info()["obstacles"]
    assert len(shapes) == len(sc.obstacles)
    for shape, ob in zip(shapes, sc.obstacles, strict=True):
        np.testing.assert_array_equal(shape["center"], ob.center)
        assert len(shape["center"]) == 3
        if shape["kind"] == "circle":
            assert shape["radius"] == ob.radius
        else:
            assert shape["kind"] == "box"
            np.testing.assert_array_equal(shape["size"], ob.size)
    assert {s["kind"] for s in shapes} == {"circle", "box"}
