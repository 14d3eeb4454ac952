"""MCAP recordings of runs (docs/robots.md), read back by readers nobody here wrote.

``rosbags`` (its ``AnyReader`` and type system) decodes every message from the schemas in
the file, the way ``ros2 bag`` and Foxglove do, and each value is compared with what
``trajectory.nc`` holds or with the package's own functions computed here (distance errors,
the law's potential); ``mcap``'s reader checks the container: profile, channels, schemas,
encodings and message counts. The message definitions are compared with the ones rosbags
ships for ROS 2 Humble and Jazzy. The recordings come from the paper's triangle (section 4,
simulation 2's alpha table: restrictions active at the start), a unicycle run and a run in
space, each a short cut of a scenario of examples/.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest
from _scenarios import triangle
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from typer.testing import CliRunner, Result

from formationlab.cli import _load_commands, app
from formationlab.controllers.angle_restricted import switching_lines
from formationlab.errors import MissingExtraError
from formationlab.io.mcap import ROBOT_TOPIC, TOPICS, write_mcap
from formationlab.io.netcdf import load_trajectory
from formationlab.io.ros2_messages import definition
from formationlab.outcomes.analysis import distance_errors
from formationlab.scenario import run_scenario
from formationlab.scenario.parse import parse_scenario

_load_commands()
runner = CliRunner()
EXAMPLES = Path(__file__).parents[1] / "examples"
TOL = 1e-9


def invoke(*args: object) -> Result:
    return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)


def error_line(res: Result) -> str:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, res.stderr
    return lines[0]


def example(path: str, duration: float) -> str:
    """The text of an example scenario, cut to ``duration`` seconds."""
    text = (EXAMPLES / path).read_text()
    return re.sub(r"(?m)^duration = .*$", f"duration = {duration}", text)


def read_bag(path: Path) -> dict[str, list[tuple[int, object]]]:
    """Every message of the recording decoded by rosbags: topic -> [(log time, message)]."""
    out: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([path]) as reader:
        for conn, stamp, raw in reader.messages():
            out.setdefault(conn.topic, []).append((stamp, reader.deserialize(raw, conn.msgtype)))
    return out


def stamp_ns(header: object) -> int:
    return int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)  # type: ignore[attr-defined]


def positions(poses: list[object]) -> np.ndarray:
    """``(n, 3)`` positions of decoded ``geometry_msgs/Pose`` messages."""
    return np.array([[p.position.x, p.position.y, p.position.z] for p in poses])  # type: ignore[attr-defined]


def coordinates(points: list[object]) -> np.ndarray:
    """``(k, 3)`` coordinates of decoded ``geometry_msgs/Point`` messages."""
    return np.array([[p.x, p.y, p.z] for p in points]).reshape(-1, 3)  # type: ignore[attr-defined]


def quaternions(poses: list[object]) -> np.ndarray:
    """``(n, 4)`` orientations ``(x, y, z, w)`` of decoded poses."""
    o = [p.orientation for p in poses]  # type: ignore[attr-defined]
    return np.array([[a.x, a.y, a.z, a.w] for a in o])


# ------------------------------------------------------------------ the paper's triangle


@pytest.fixture(scope="module")
def triangle_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``formationlab run ... --record rec.mcap`` of the paper's triangle over 2 s."""
    folder = tmp_path_factory.mktemp("mcap")
    scenario = folder / "triangle.toml"
    scenario.write_text(triangle("mcap-triangle", "2.0"))
    out = folder / "run"
    res = invoke("run", scenario, "--out", out, "--save-every", 20, "--record", "rec.mcap", "-q")
    assert res.exit_code in (0, 1), res.output  # (1: stopped early; the files are written)
    return out


def test_run_record_export_and_api_write_the_same_file(triangle_run: Path) -> None:
    rec = triangle_run / "rec.mcap"
    assert rec.is_file()
    res = invoke("export", "mcap", triangle_run, "--out", triangle_run / "exported.mcap")
    assert res.exit_code == 0, res.output
    assert res.stdout.startswith(f"wrote {triangle_run / 'exported.mcap'} (")
    api = write_mcap(load_trajectory(triangle_run / "trajectory.nc"), triangle_run / "api.mcap")
    # from the run's result, from trajectory.nc by the command and by the API: the same bytes
    assert rec.read_bytes() == (triangle_run / "exported.mcap").read_bytes() == api.read_bytes()
    manifest = (triangle_run / "summary.json").read_text()
    assert '"rec.mcap"' in manifest and '"exported.mcap"' in manifest


def test_every_kth_state(triangle_run: Path, tmp_path: Path) -> None:
    ds = load_trajectory(triangle_run / "trajectory.nc")
    res = invoke("export", "mcap", triangle_run, "--every", 3, "--out", tmp_path / "3.mcap")
    assert res.exit_code == 0, res.output
    bag = read_bag(tmp_path / "3.mcap")
    rows = np.arange(0, ds.sizes["time"], 3)
    assert [log for log, _ in bag["/formation/lyapunov"]] == np.rint(
        ds["time"].values[rows] * 1e9
    ).astype(np.int64).tolist()
    V = [m.data for _, m in bag["/formation/lyapunov"]]  # type: ignore[attr-defined]
    np.testing.assert_allclose(V, ds["V"].values[rows], rtol=0, atol=TOL)
    poses = [positions(m.poses)[:, :2] for _, m in bag["/formation/poses"]]  # type: ignore[attr-defined]
    np.testing.assert_allclose(poses, ds["q"].values[rows], rtol=0, atol=TOL)


def test_the_container_has_the_ros2_profile_channels_and_counts(triangle_run: Path) -> None:
    ds = load_trajectory(triangle_run / "trajectory.nc")
    T = ds.sizes["time"]
    with open(triangle_run / "rec.mcap", "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert summary is not None and summary.statistics is not None
    topics = {c.topic: c for c in summary.channels.values()}
    expected = {**TOPICS, **{ROBOT_TOPIC[0].format(k=k): ROBOT_TOPIC[1] for k in (1, 2, 3)}}
    assert {t: summary.schemas[c.schema_id].name for t, c in topics.items()} == expected
    for c in topics.values():
        schema = summary.schemas[c.schema_id]
        assert (schema.encoding, c.message_encoding) == ("ros2msg", "cdr")
        assert schema.data.decode() == definition(schema.name)
        assert summary.statistics.channel_message_counts[c.id] == T
    assert summary.statistics.message_count == 7 * T
    assert summary.statistics.message_start_time == 0
    assert summary.statistics.message_end_time == round(float(ds["time"][-1]) * 1e9)
    assert metadata["formationlab"]["scenario_name"] == "mcap-triangle"
    assert metadata["formationlab"]["frame"] == "world"


def test_rosbags_reads_the_poses_of_trajectory_nc(triangle_run: Path) -> None:
    ds = load_trajectory(triangle_run / "trajectory.nc")
    t, q = ds["time"].values, ds["q"].values
    bag = read_bag(triangle_run / "rec.mcap")
    stamps = np.rint(t * 1e9).astype(np.int64)
    arrays = bag["/formation/poses"]
    assert len(arrays) == len(t)
    for k, (log, msg) in enumerate(arrays):
        assert log == stamps[k] == stamp_ns(msg.header)  # type: ignore[attr-defined]
        assert msg.header.frame_id == "world"  # type: ignore[attr-defined]
        got = positions(msg.poses)  # type: ignore[attr-defined]
        np.testing.assert_allclose(got[:, :2], q[k], rtol=0, atol=TOL)
        assert np.all(got[:, 2] == 0.0)
        assert np.all(quaternions(msg.poses) == [0.0, 0.0, 0.0, 1.0])  # type: ignore[attr-defined]
    for i in range(3):
        own = bag[f"/robot_{i + 1}/pose"]
        got = np.array([positions([m.pose])[0] for _, m in own])  # type: ignore[attr-defined]
        np.testing.assert_allclose(got[:, :2], q[:, i], rtol=0, atol=TOL)
        assert [stamp_ns(m.header) for _, m in own] == stamps.tolist()  # type: ignore[attr-defined]


def test_rosbags_reads_v_and_the_distance_errors(triangle_run: Path) -> None:
    ds = load_trajectory(triangle_run / "trajectory.nc")
    sc = parse_scenario(str(ds.attrs["scenario"]), source="<test>")
    q = ds["q"].values
    bag = read_bag(triangle_run / "rec.mcap")
    V = np.array([m.data for _, m in bag["/formation/lyapunov"]])  # type: ignore[attr-defined]
    np.testing.assert_allclose(V, ds["V"].values, rtol=0, atol=TOL)
    # the package's own functions on the saved positions: the law's V_n (eq. 15), r_ij - d_ij
    np.testing.assert_allclose(V, sc.law.potential(sc.formation, q), rtol=1e-12, atol=TOL)
    errors = [m for _, m in bag["/formation/distance_errors"]]
    err = np.array([m.data for m in errors])  # type: ignore[attr-defined]
    np.testing.assert_allclose(err, distance_errors(sc.formation, q), rtol=0, atol=TOL)
    dims = {(d.label, d.size, d.stride) for m in errors for d in m.layout.dim}  # type: ignore[attr-defined]
    assert dims == {("1-2,1-3,2-3", 3, 3)}
    assert err.shape == (len(q), 3) and np.abs(err[0]).max() > 1.0  # (the run starts far away)


def test_the_markers_hold_the_edges_restrictions_and_switching_lines(triangle_run: Path) -> None:
    ds = load_trajectory(triangle_run / "trajectory.nc")
    sc = parse_scenario(str(ds.attrs["scenario"]), source="<test>")
    f, theta = sc.formation, sc.law.theta
    q, sigma = ds["q"].values, ds["sigma"].values
    tris, beta, _ = f.surfaces
    bag = read_bag(triangle_run / "rec.mcap")
    on_steps = 0
    for k, (_, msg) in enumerate(bag["/formation/graph"]):
        marks = {m.ns: m for m in msg.markers}  # type: ignore[attr-defined]
        assert set(marks) == {"edges", "restrictions", "switching lines"}
        edges = marks["edges"]
        assert (edges.type, edges.action, edges.header.frame_id) == (5, 0, "world")
        ends = coordinates(edges.points)[:, :2].reshape(-1, 2, 2)
        # each segment joins two robots: which ones, read back from the positions
        who = np.argmin(np.linalg.norm(ends[:, :, None] - q[k][None, None], axis=-1), axis=-1)
        np.testing.assert_allclose(ends, q[k][who], rtol=0, atol=TOL)
        assert who.tolist() == f.edges.tolist()
        active = np.flatnonzero(sigma[k] >= 0)
        tri, lines = marks["restrictions"], marks["switching lines"]
        if not len(active):  # (the unicycle test sees these: DELETE)
            assert tri.action == lines.action == 2
            continue
        on_steps += 1
        assert (tri.type, tri.action, lines.type, lines.action) == (11, 0, 5, 0)
        corners = coordinates(tri.points)[:, :2].reshape(-1, 3, 2)
        np.testing.assert_allclose(corners, q[k][tris[active]], rtol=0, atol=TOL)
        segs = coordinates(lines.points)[:, :2].reshape(len(active), 3, 2, 2)
        for s, surface in enumerate(active):
            a, b, c = (q[k][v] for v in tris[surface])
            for m, (w, u) in enumerate(((b, c), (c, a), (a, b))):
                for p in segs[s, m]:  # the vertex moved there meets the surface (eq. 26)
                    area = (w[0] - p[0]) * (u[1] - p[1]) - (w[1] - p[1]) * (u[0] - p[0])
                    assert abs(beta[surface] * area + theta) < 1e-9
                d = segs[s, m, 1] - segs[s, m, 0]  # parallel to the opposite side
                assert abs(d[0] * (u - w)[1] - d[1] * (u - w)[0]) < 1e-9
    assert on_steps > 0  # (simulation 2's table: the restriction is on from the start)


def test_the_definitions_are_those_of_ros2(triangle_run: Path) -> None:
    humble, jazzy = get_typestore(Stores.ROS2_HUMBLE), get_typestore(Stores.ROS2_JAZZY)
    for name in [*TOPICS.values(), ROBOT_TOPIC[1]]:
        assert definition(name) == humble.generate_msgdef(name, ros_version=2)[0]
        for kind, (_, fields) in get_types_from_msg(definition(name), name).items():
            assert fields == jazzy.fielddefs[kind][1], kind  # (Jazzy adds a constant only)


# ------------------------------------------------------------------ unicycles, space


def test_unicycle_headings_are_rotations_about_z(tmp_path: Path) -> None:
    sc = parse_scenario(example("paper-simulation-1-unicycle-heading.toml", 0.4), source="<t>")
    result = run_scenario(sc, save_every=40)
    path = write_mcap(result, tmp_path / "unicycles.mcap", name=sc.name)
    bag = read_bag(path)
    h = result.headings
    assert h is not None and np.ptp(h) > 1.0
    for k, (_, msg) in enumerate(bag["/formation/poses"]):
        np.testing.assert_allclose(positions(msg.poses)[:, :2], result.q[k], rtol=0, atol=TOL)  # type: ignore[attr-defined]
        x, y, z, w = quaternions(msg.poses).T  # type: ignore[attr-defined]
        np.testing.assert_allclose(x * x + y * y + z * z + w * w, 1.0, rtol=0, atol=TOL)
        assert np.all(x == 0) and np.all(y == 0)
        # the body's x axis turned by the quaternion is the heading's direction
        turned = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + z * w)], axis=-1)
        np.testing.assert_allclose(turned, np.stack([np.cos(h[k]), np.sin(h[k])], -1), atol=TOL)
    # simulation 1's table: no restriction is on, so its markers are deleted at every step
    assert np.all(result.sigma < 0)
    for _, msg in bag["/formation/graph"]:
        actions = {m.ns: m.action for m in msg.markers}  # type: ignore[attr-defined]
        assert actions == {"edges": 0, "restrictions": 2, "switching lines": 2}


def test_space_runs_have_z_and_no_switching_lines(tmp_path: Path) -> None:
    sc = parse_scenario(example("space/tetrahedron-mirror.toml", 0.2), source="<t>")
    result = run_scenario(sc, save_every=25)
    assert result.q.shape[-1] == 3
    bag = read_bag(write_mcap(result, tmp_path / "space.mcap"))
    assert len(bag["/formation/poses"]) == len(result.t)
    for k, (_, msg) in enumerate(bag["/formation/poses"]):
        np.testing.assert_allclose(positions(msg.poses), result.q[k], rtol=0, atol=TOL)  # type: ignore[attr-defined]
        assert np.all(quaternions(msg.poses) == [0.0, 0.0, 0.0, 1.0])  # type: ignore[attr-defined]
    for k, (_, msg) in enumerate(bag["/formation/graph"]):
        (edges,) = msg.markers  # type: ignore[attr-defined]  # (switching planes: not drawn)
        ends = coordinates(edges.points).reshape(-1, 2, 3)
        np.testing.assert_allclose(ends, result.q[k][sc.formation.edges], rtol=0, atol=TOL)
    err = np.array([m.data for _, m in bag["/formation/distance_errors"]])  # type: ignore[attr-defined]
    np.testing.assert_allclose(err, distance_errors(sc.formation, result.q), rtol=0, atol=TOL)


def test_switching_lines_lie_on_the_switching_surface(rng: np.random.Generator) -> None:
    q = rng.normal(size=(4, 5, 2))
    tris, beta, theta = np.array([[0, 1, 2], [1, 3, 4]]), np.array([1.0, -2.0]), 0.5
    seg = switching_lines(q, tris, beta, theta)
    assert seg.shape == (4, 2, 3, 2, 2)
    for s, tri in enumerate(tris):
        for m in range(3):
            w, u = q[:, tri[(m + 1) % 3]], q[:, tri[(m + 2) % 3]]
            for e in range(2):
                p = seg[:, s, m, e]
                area = (w[:, 0] - p[:, 0]) * (u[:, 1] - p[:, 1]) - (w[:, 1] - p[:, 1]) * (
                    u[:, 0] - p[:, 0]
                )
                np.testing.assert_allclose(beta[s] * area + theta, 0.0, atol=1e-12)
            length = np.linalg.norm(seg[:, s, m, 1] - seg[:, s, m, 0], axis=-1)
            np.testing.assert_allclose(length, 2.2 * np.linalg.norm(u - w, axis=-1))
    flat = q.copy()
    flat[:, 1] = flat[:, 2]  # b = c: no line
    assert np.all(np.isnan(switching_lines(flat, tris[:1], beta[:1], theta)[:, 0, 0]))


# ------------------------------------------------------------------ refusals


def test_export_refuses_a_folder_without_a_trajectory(tmp_path: Path) -> None:
    (tmp_path / "summary.json").write_text("{}")
    line = error_line(invoke("export", "mcap", tmp_path))
    assert line == (
        f"error: {tmp_path} holds no trajectory.nc; run `formationlab run SCENARIO --out "
        f"{tmp_path}` first"
    )
    assert not list(tmp_path.glob("*.mcap"))


def test_export_refuses_an_existing_file_unless_forced(triangle_run: Path) -> None:
    target = triangle_run / "recording.mcap"
    target.write_bytes(b"an earlier file")
    line = error_line(invoke("export", "mcap", triangle_run))
    assert line == f"error: {target} already exists; pass --force to replace it"
    assert target.read_bytes() == b"an earlier file"
    assert invoke("export", "mcap", triangle_run, "--force").exit_code == 0
    assert target.read_bytes() == (triangle_run / "rec.mcap").read_bytes()
    bad = error_line(invoke("export", "mcap", triangle_run, "--out", triangle_run / "r.bag"))
    assert bad == "error: an MCAP recording's file name ends in .mcap, not 'r.bag'"


def test_run_refuses_an_existing_recording_before_running(tmp_path: Path) -> None:
    scenario = tmp_path / "s.toml"
    scenario.write_text(triangle("t", "0.1"))
    earlier = tmp_path / "earlier.mcap"
    earlier.write_bytes(b"x")
    line = error_line(invoke("run", scenario, "--out", tmp_path / "o", "--record", earlier))
    assert line == f"error: {earlier} already exists; pass --force to replace it"
    assert not (tmp_path / "o").exists() and earlier.read_bytes() == b"x"


def test_without_the_robots_extra_the_commands_say_what_to_install(
    triangle_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "mcap_ros2.writer", None)  # not installed
    expected = (
        "error: MCAP recordings need the optional part 'robots', which is not installed (no "
        "module 'mcap_ros2.writer'): pip install \"formationlab[robots]\""
    )
    assert error_line(invoke("export", "mcap", triangle_run, "-o", tmp_path / "r.mcap")) == expected
    scenario = tmp_path / "s.toml"
    scenario.write_text(triangle("t", "0.1"))
    out = tmp_path / "o"
    assert error_line(invoke("run", scenario, "--out", out, "--record", "r.mcap")) == expected
    assert not out.exists() and not (tmp_path / "r.mcap").exists()
    with pytest.raises(MissingExtraError) as info:
        write_mcap(load_trajectory(triangle_run / "trajectory.nc"), tmp_path / "api.mcap")
    assert info.value.extra == "robots" and not (tmp_path / "api.mcap").exists()
