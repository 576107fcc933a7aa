"""SceneLogger (rows -> Rerun): what ends up in an .rrd, read back with Rerun's own reader (rerun.chunk)."""

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from components.constants import NS_PER_S
from components.extras import missing
from components.sdk import RunSettings
from components.viewer.robot import Kinematics, read_geometry
from components.viewer.scene import SceneLogger, parse_columns

rr = pytest.importorskip("rerun", reason=missing("view", "testing the viewer"))
RrdReader = pytest.importorskip("rerun.chunk").RrdReader

ROOT = Path(__file__).resolve().parents[2]
URDF = ROOT / "models" / "humanoid_torso.urdf"


def columns_of(spec):
    """[(component.name, size)] -> recorded column names (docs/design.md §6)."""
    out = []
    for name, size in spec:
        out += [name] if size == 0 else [f"{name}[{i}]" for i in range(size)]
    return out


SPEC = [
    ("orbit.r_eci", 3),
    ("orbit.q_eci_lvlh", 4),
    ("dyn.humanoid.position", 3),
    ("dyn.humanoid.orientation", 4),
    ("dyn.humanoid.q", 14),
    ("dyn.humanoid.com", 3),
    ("dyn.humanoid.momentum", 6),
    ("dyn.humanoid.gg_torque", 51),
    ("dyn.humanoid.link_position", 51),
    ("ctrl.tau", 14),
    ("ctrl.ee_position", 3),
    ("ctrl.ee_position_desired", 3),
    ("ctrl.ee_error", 6),
    ("extra.n", 0),
]
CONFIG = {
    "run": {"name": "scene_test", "step": "10000000 ns"},
    "components": {
        "orbit": {"type": "orbit.kepler", "parameters": {}},
        "dyn": {"type": "dynamics.dart", "parameters": {"bodies": {"humanoid": {"urdf": str(URDF)}}}},
        "ctrl": {"type": "controller.computed_torque", "parameters": {}},
        "extra": {"type": "test.counter", "parameters": {}},
    },
    "connections": {"dyn.humanoid.tau": "ctrl.tau", "ctrl.q": "dyn.humanoid.q", "dyn.q_eci_lvlh": "orbit.q_eci_lvlh"},
}


def synthetic_rows(columns, n, seed=1):
    rng = np.random.default_rng(seed)
    rows = rng.normal(scale=0.3, size=(n, len(columns)))
    index = parse_columns(columns)
    rows[:, index["orbit", "r_eci"]] = (
        6.778e6 * np.c_[np.cos(np.arange(n) / 50), np.sin(np.arange(n) / 50), 0 * np.arange(n)]
    )
    rows[:, index["extra", "n"][0]] = np.arange(n)
    return rows


def read_rrd(path):
    """{entity: {"static": {component: value}, "rows": n temporal rows, "timelines": set, "data": {component: [...]}}}."""
    entities = {}
    for chunk in RrdReader(path).stream():
        entry = entities.setdefault(chunk.entity_path, {"static": {}, "rows": 0, "timelines": set(), "data": {}})
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n != "rerun.controls.RowId"]
        if chunk.is_static:
            for name in names:
                entry["static"][name] = batch.column(name).to_pylist()[-1]
            continue
        entry["rows"] += chunk.num_rows
        entry["timelines"] |= set(chunk.timeline_names)
        for name in names:
            column = batch.column(name)
            if pa.types.is_duration(column.type):  # sim_time: integer nanoseconds
                column = column.cast(pa.int64())
            entry["data"].setdefault(name, []).extend(column.to_pylist())
    return entities


def save(tmp_path, columns, config, batches, name="scene.rrd", warnings=None):
    path = tmp_path / name
    stream = rr.RecordingStream("zenorbit_test", recording_id=name)
    scene = SceneLogger(
        columns, config, None, recording=stream, warn=(warnings.append if warnings is not None else None)
    )
    stream.save(str(path), default_blueprint=scene.blueprint())
    scene.log_static()
    for steps, times, rows in batches:
        scene.log_rows(steps, times, rows)
    stream.flush()
    stream.disconnect()
    return scene, read_rrd(path)


def test_parse_columns_groups_vector_elements_in_order():
    index = parse_columns(["a.x[1]", "a.x[0]", "a.y", "b.body.q[0]", "b.body.q[1]", "junk"])
    assert list(index["a", "x"]) == [1, 0] and list(index["a", "y"]) == [2]
    assert list(index["b", "body.q"]) == [3, 4] and len(index) == 3


def test_rows_become_entities_on_sim_time_and_step(tmp_path):
    columns = columns_of(SPEC)
    n = 20
    rows = synthetic_rows(columns, n)
    steps = np.arange(n) * 3
    times = steps * 0.01
    scene, rrd = save(
        tmp_path, columns, CONFIG, [(steps[:12], times[:12], rows[:12]), (steps[12:], times[12:], rows[12:])]
    )
    links = read_geometry(URDF).links
    for link in links:
        entry = rrd[f"/world/dyn/humanoid/links/{link}"]
        assert entry["rows"] == n and entry["timelines"] == {"sim_time", "step"}
    # the link poses are Pinocchio's forward kinematics of the recorded base pose and q
    index = parse_columns(columns)
    kin = Kinematics(read_geometry(URDF))
    translations, _ = kin.link_poses(
        rows[:, index["dyn", "humanoid.position"]],
        rows[:, index["dyn", "humanoid.orientation"]],
        rows[:, index["dyn", "humanoid.q"]],
    )
    logged = np.array(
        [r[0] for r in rrd["/world/dyn/humanoid/links/arm_left_7_link"]["data"]["Transform3D:translation"]]
    )
    assert np.allclose(logged, translations[:, links.index("arm_left_7_link")], atol=1e-6)  # float32 in Rerun
    # time columns: sim_time is a duration (ns), step the step index
    entry = rrd["/plots/ctrl/tau"]
    assert entry["data"]["step"] == list(steps)
    assert entry["data"]["sim_time"] == [int(round(t * NS_PER_S)) for t in times]
    # paper figures: ee paths (3D trails and plots), errors, torques named by joint
    assert rrd["/world/ctrl/ee_desired"]["rows"] == n and rrd["/world/ctrl/ee_actual"]["rows"] == n
    assert rrd["/plots/ctrl/ee_position/desired"]["rows"] == n
    assert rrd["/plots/ctrl/ee_error/position"]["rows"] == n and rrd["/plots/ctrl/ee_error/orientation"]["rows"] == n
    assert np.allclose(entry["data"]["Scalars:scalars"][5], rows[5, index["ctrl", "tau"]])
    assert rrd["/plots/ctrl/tau"]["static"]["SeriesLines:names"][0] == "arm_left_1_joint"
    # dynamics: momentum, per-link gravity-gradient arrows (17 per row) and their magnitudes
    assert rrd["/plots/dyn/humanoid/momentum/linear"]["rows"] == n
    arrows = rrd["/world/dyn/humanoid/gg_torque"]
    assert arrows["rows"] == n and all(len(v) == len(links) for v in arrows["data"]["Arrows3D:vectors"])
    first_batch = np.array(arrows["data"]["Arrows3D:vectors"][:12])
    assert np.isclose(np.linalg.norm(first_batch, axis=2).max(), 0.25, rtol=1e-5)  # scaled on first sight
    assert rrd["/plots/dyn/humanoid/gg_torque_norm"]["rows"] == n
    # orbit view: Earth, trail, spacecraft with LVLH axes; LVLH axes in the robot view
    assert "Ellipsoids3D:half_sizes" in rrd["/orbit/earth"]["static"]
    assert rrd["/orbit/orbit/trail"]["rows"] == n and rrd["/orbit/orbit/spacecraft"]["rows"] == n
    assert "Arrows3D:vectors" in rrd["/orbit/orbit/spacecraft/lvlh"]["static"]
    assert rrd["/world/lvlh"]["rows"] == n
    # everything else under /signals; shown variables are not repeated, bulk link arrays never plotted
    assert rrd["/signals/extra/n"]["rows"] == n
    assert [v[0] for v in rrd["/signals/extra/n"]["data"]["Scalars:scalars"]] == list(range(n))
    assert rrd["/signals/dyn/humanoid.q"]["rows"] == n
    for absent in (
        "/signals/ctrl/tau",
        "/signals/dyn/humanoid.momentum",
        "/signals/dyn/humanoid.link_position",
        "/signals/dyn/humanoid.gg_torque",
    ):
        assert absent not in rrd
    assert "TextDocument:text" in rrd["/notes"]["static"]
    assert RrdReader(tmp_path / "scene.rrd").blueprints(), "the layout (blueprint) is saved with the data"
    assert scene.rows_logged == n


def test_absent_or_inconsistent_signals_are_skipped_not_fatal(tmp_path):
    spec = [
        ("dyn.humanoid.position", 3),
        ("dyn.humanoid.orientation", 4),
        ("dyn.humanoid.q", 5),  # wrong size
        ("dyn.ghost.position", 3),
        ("ctrl.ee_error", 6),
        ("ctrl.ee_position", 2),
    ]  # wrong size
    config = {
        "components": {
            "dyn": {
                "type": "dynamics.dart",
                "parameters": {"bodies": {"humanoid": {"urdf": str(URDF)}, "ghost": {"urdf": "no/such.urdf"}}},
            },
            "ctrl": {"type": "controller.joint_pd"},
        }
    }
    columns = columns_of(spec)
    warnings = []
    n = 4
    _, rrd = save(
        tmp_path, columns, config, [(np.arange(n), np.arange(n) * 0.1, np.zeros((n, len(columns))))], warnings=warnings
    )
    assert any("ghost" in w and "not found" in w for w in warnings)
    assert any("humanoid.q has 5 values" in w for w in warnings)
    assert not any(path.startswith("/world/dyn/humanoid/links/") and entry["rows"] for path, entry in rrd.items())
    assert rrd["/plots/ctrl/ee_error/position"]["rows"] == n
    assert rrd["/signals/ctrl/ee_position"]["rows"] == n  # not a 3-vector: shown as a plain signal
    assert rrd["/signals/dyn/humanoid.q"]["rows"] == n


def test_zero_vector_fields_draw_no_arrows_until_they_are_nonzero(tmp_path):
    spec = [
        ("dyn.humanoid.position", 3),
        ("dyn.humanoid.orientation", 4),
        ("dyn.humanoid.q", 14),
        ("dyn.humanoid.tidal_force", 51),
    ]
    config = {
        "components": {"dyn": {"type": "dynamics.dart", "parameters": {"bodies": {"humanoid": {"urdf": str(URDF)}}}}}
    }
    columns = columns_of(spec)
    rows = np.zeros((6, len(columns)))
    rows[:, 6] = 1.0  # identity orientation
    rows[3:, 3 + 4 + 14 + 3 * 5 + 2] = 2.0  # link 5, z: from row 3 on
    scene, rrd = save(
        tmp_path,
        columns,
        config,
        [(np.arange(3), np.arange(3) * 0.1, rows[:3]), (np.arange(3, 6), np.arange(3, 6) * 0.1, rows[3:])],
    )
    assert rrd["/world/dyn/humanoid/tidal_force"]["rows"] == 3
    assert scene.arrow_scales == {("dyn", "humanoid", "tidal_force"): pytest.approx(0.25 / 2.0)}
    assert "tidal_force: 0.125 m per N" in rrd["/notes"]["static"]["TextDocument:text"][0]


def test_module_class_types_are_recognised_by_their_type_name(tmp_path):
    columns = columns_of([("d.humanoid.position", 3), ("d.humanoid.orientation", 4), ("d.humanoid.q", 14)])
    config = {
        "components": {
            "d": {
                "type": "components.dynamics.component:DartDynamics",
                "parameters": {"bodies": {"humanoid": {"urdf": str(URDF)}}},
            }
        }
    }
    scene = SceneLogger(columns, config)
    assert [b.name for b in scene.bodies] == ["humanoid"] and scene.bodies[0].kinematics is not None


def test_bodies_and_urdf_paths_are_read_as_the_dynamics_reads_them(tmp_path, monkeypatch):
    """The viewer draws the URDF dynamics.dart simulates: same bodies, same path resolution
    (config directory first, then the project root; not the cwd)."""
    from components.dynamics.specs import load_models

    here, there = tmp_path / "config", tmp_path / "cwd"
    for path, source in (
        (here / "models" / "robot.urdf", "servicer.urdf"),
        (there / "models" / "humanoid_torso.urdf", "target.urdf"),
    ):  # a decoy in the cwd
        path.parent.mkdir(parents=True)
        path.write_text((ROOT / "models" / source).read_text())
    monkeypatch.chdir(there)
    bodies = {"a": {"urdf": "models/robot.urdf"}, "b": {"urdf": "models/humanoid_torso.urdf"}}
    config = {"components": {"dyn": {"type": "dynamics.dart", "parameters": {"bodies": bodies}}}}
    scene = SceneLogger([], config, here)
    simulated = load_models({"bodies": bodies}, RunSettings(config_dir=here))
    assert [b.name for b in scene.bodies] == ["a", "b"]
    for body in scene.bodies:
        assert body.geometry.path == simulated[body.name].path
        assert body.geometry.links == simulated[body.name].link_names
    assert scene.bodies[0].geometry.path == (here / "models" / "robot.urdf").resolve()
    assert scene.bodies[1].geometry.path == URDF.resolve()  # project root fallback


# ---------------------------------------------------------------------------------------- capture

CAPTURE = ROOT / "models" / "capture"
CAPTURE_PARAMS = {  # configs/capture_tumbling_target.yaml's bodies and grasp, in W, no orbit, closing anywhere
    "bodies": {
        "servicer": {
            "urdf": str(CAPTURE / "servicer.urdf"),
            "q": {
                "arm_1_joint": -0.9,
                "arm_2_joint": 0.2,
                "arm_3_joint": 1.6,
                "arm_4_joint": -0.3,
                "arm_5_joint": 1.2,
                "arm_6_joint": 0.3,
            },
        },
        "target": {
            "urdf": str(CAPTURE / "target.urdf"),
            "position": [2.0558, 0.2176, 1.198],
            "orientation": [-0.544708, -0.481372, 0.620058, 0.295131],
            "twist": [0, 0, 0, -0.026038, 0.006364, -0.034429],
        },
    },
    "tidal_force": False,
    "gravity_gradient": False,
    "grasp": {
        "chaser": "servicer",
        "end_effector": "ee",
        "target": "target",
        "grasp_frame": "grapple",
        "tolerance": {
            "position": "2 m",
            "orientation": "180 deg",
            "linear_velocity": "1 m/s",
            "angular_velocity": "1 rad/s",
        },
        "force_limit": "1e6 N",
        "torque_limit": "1e6 N*m",
    },
}
CAPTURE_CONFIG = {
    "run": {"name": "capture_view", "step": "10 ms"},
    "components": {"dyn": {"type": "dynamics.dart", "parameters": CAPTURE_PARAMS}},
}
CLOSE_AT = 7  # grasp.close set for this step on


@pytest.fixture(scope="module")
def capture_rows():
    """A capture as dynamics.dart computes it (stepped in-process, 10 ms): (columns, rows, first closed row)."""
    from components.testing.harness import Harness

    h = Harness("dynamics.dart", CAPTURE_PARAMS)
    outputs = [h.initialize()]
    for k in range(1, 12):
        if k == CLOSE_AT:
            h.inputs["grasp.close"] = 1.0
        outputs.append(h.step(10_000_000))
    variables = h.output_layout.variables
    columns = [c for v in variables for c in v.columns("dyn")]
    rows = np.array([np.concatenate([np.ravel(o[v.name]) for v in variables]) for o in outputs])
    closed = rows[:, columns.index("dyn.grasp.closed")]
    assert closed[0] == 0.0 and closed[-1] == 1.0
    return columns, rows, int(np.argmax(closed))


def views(container):
    """Every view of a blueprint (or container), depth first."""
    contents = getattr(container, "contents", None)
    if contents is None or hasattr(container, "class_identifier"):
        return [container]
    return [view for item in contents for view in views(item)]


def pose(entry, i):
    """Translation and rotation matrix of row i of a logged Transform3D."""
    from components.rotations import quat_to_matrix

    return (
        np.array(entry["data"]["Transform3D:translation"][i][0]),
        quat_to_matrix(np.array(entry["data"]["Transform3D:quaternion"][i][0])),
    )


@pytest.mark.parametrize("split", ["one batch", "capture starts a batch", "row by row"])
def test_capture_view_draws_both_bodies_the_grasp_frames_and_the_capture_once(tmp_path, capture_rows, split):
    columns, rows, capture = capture_rows
    n = len(rows)
    steps = np.arange(n) * 2  # steps and times unlike the row index, as a decimated view
    times = steps * 0.01
    bounds = {"one batch": [0, n], "capture starts a batch": [0, 4, capture, n], "row by row": list(range(n + 1))}[
        split
    ]
    scene, rrd = save(
        tmp_path,
        columns,
        CAPTURE_CONFIG,
        [(steps[a:b], times[a:b], rows[a:b]) for a, b in zip(bounds[:-1], bounds[1:])],
    )
    index = parse_columns(columns)
    base = "/world/dyn"
    # both spacecraft: every link posed on every row, their URDF boxes and cylinders drawn
    for body in ("servicer", "target"):
        for link in read_geometry(CAPTURE / f"{body}.urdf").links:
            assert rrd[f"{base}/{body}/links/{link}"]["rows"] == n
        kinds = {
            name.split(":")[0]
            for path, entry in rrd.items()
            if path.startswith(f"{base}/{body}/links/")
            for name in entry["static"]
        }
        assert {"Boxes3D", "Cylinders3D"} <= kinds
    # E and G as axes, children of their links (they move with the logged link poses)
    for path, length in ((f"{base}/servicer/links/ee/grasp_E", 0.15), (f"{base}/target/links/grapple/grasp_G", 0.25)):
        vectors = np.array(rrd[path]["static"]["Arrows3D:vectors"])
        assert np.allclose(vectors, length * np.eye(3))
    # the line from E to G while open (in E's axes: it ends on G's origin as the viewer poses the grapple), none after
    strips = rrd[f"{base}/servicer/links/ee/grasp_line"]["data"]["LineStrips3D:strips"]
    assert len(strips) == n and all(len(s) == 1 for s in strips[:capture]) and not any(strips[capture:])
    ee, grapple = rrd[f"{base}/servicer/links/ee"], rrd[f"{base}/target/links/grapple"]
    for i in range(capture):
        (p_E, R_E), (p_G, _) = pose(ee, i), pose(grapple, i)
        start, end = np.array(strips[i][0])
        assert np.allclose(start, 0.0) and np.allclose(p_E + R_E @ end, p_G, atol=1e-5)  # float32 in Rerun
    # the capture: once, on the first closed row, in the text log, as G's marker and on the distance plot
    events = rrd["/events/dyn/grasp"]
    assert events["rows"] == 1 and events["data"]["step"] == [steps[capture]]
    assert events["data"]["sim_time"] == [int(round(times[capture] * NS_PER_S))]
    text = events["data"]["TextLog:text"][0][0]
    assert text.startswith(
        f"capture at t = {times[capture]:.6g} s (step {steps[capture]}): servicer.ee -> target.grapple"
    )
    marker = rrd[f"{base}/target/links/grapple/grasp_G/marker"]["data"]
    assert marker["step"] == [steps[0], steps[capture]]
    assert [label[0] for label in marker["Points3D:labels"]] == ["G", "G captured"]
    assert (
        marker["Points3D:radii"][1][0] > marker["Points3D:radii"][0][0]
        and len(set(map(tuple, marker["Points3D:colors"]))) == 2
    )
    assert rrd["/plots/dyn/grasp/distance/capture"]["data"]["step"] == [steps[capture]]

    # distance and wrench magnitudes, per row; the raw outputs still plotted under /signals
    def plotted(path):
        return np.array(rrd[path]["data"]["Scalars:scalars"])

    assert np.allclose(
        plotted("/plots/dyn/grasp/distance")[:, 0], np.linalg.norm(rows[:, index["dyn", "grasp.p_ee_grasp"]], axis=1)
    )
    wrench = rows[:, index["dyn", "grasp.wrench"]]
    force, torque = plotted("/plots/dyn/grasp/wrench").T
    assert np.allclose(force, np.linalg.norm(wrench[:, :3], axis=1)) and np.allclose(
        torque, np.linalg.norm(wrench[:, 3:], axis=1)
    )
    assert rrd["/plots/dyn/grasp/wrench"]["static"]["SeriesLines:names"] == ["|force| (N)", "|torque| (N m)"]
    assert not force[:capture].any() and force[capture:].all()
    for name in ("p_ee_grasp", "closed", "wrench"):
        assert rrd[f"/signals/dyn/grasp.{name}"]["rows"] == n
    # the layout: grasp plots next to the robots, the text log in a tab
    origins = {(view.class_identifier, str(view.origin)) for view in views(scene.blueprint().root_container)}
    assert {
        ("TimeSeries", "/plots/dyn/grasp/distance"),
        ("TimeSeries", "/plots/dyn/grasp/wrench"),
        ("TextLog", "/events"),
    } <= origins


def test_grasp_without_a_drawn_target_still_plots_and_logs_the_capture(tmp_path, capture_rows):
    columns, rows, _capture = capture_rows
    params = {**CAPTURE_PARAMS, "bodies": {**CAPTURE_PARAMS["bodies"], "target": {"urdf": "no/such.urdf"}}}
    warnings = []
    n = len(rows)
    _, rrd = save(
        tmp_path,
        columns,
        {"components": {"dyn": {"type": "dynamics.dart", "parameters": params}}},
        [(np.arange(n), np.arange(n) * 0.01, rows)],
        warnings=warnings,
    )
    assert any("target" in w and "not found" in w for w in warnings)
    assert not any(path.startswith("/world/dyn/target/links/") for path in rrd)  # no G axes floating at the origin
    assert "Arrows3D:vectors" in rrd["/world/dyn/servicer/links/ee/grasp_E"]["static"]
    assert rrd["/plots/dyn/grasp/distance"]["rows"] == n and rrd["/events/dyn/grasp"]["rows"] == 1


def test_capture_text_when_the_first_row_is_already_closed(tmp_path):
    columns = columns_of([("dyn.grasp.p_ee_grasp", 3), ("dyn.grasp.closed", 0)])
    rows = np.zeros((5, len(columns)))
    rows[:, 3] = [1, 1, 0, 1, 1]  # closed, opened again, closed again
    rows[:, 0] = 0.004
    config = {"components": {"dyn": {"type": "dynamics.dart", "parameters": CAPTURE_PARAMS}}}
    _, rrd = save(
        tmp_path,
        columns,
        config,
        [(np.arange(2), np.arange(2) * 0.5, rows[:2]), (np.arange(2, 5), np.arange(2, 5) * 0.5, rows[2:])],
    )
    events = rrd["/events/dyn/grasp"]["data"]
    assert events["step"] == [0, 2, 3]
    assert [t[0] for t in events["TextLog:text"]] == [
        "capture at t = 0 s (step 0): servicer.ee -> target.grapple closed (already at the first row shown), "
        "E-G distance 4 mm",
        "grasp open again at t = 1 s (step 2): servicer.ee -> target.grapple",
        "capture at t = 1.5 s (step 3): servicer.ee -> target.grapple closed, E-G distance 4 mm",
    ]
    assert [level[0] for level in events["TextLog:level"]] == ["INFO", "WARN", "INFO"]
    assert rrd["/plots/dyn/grasp/distance/capture"]["data"]["step"] == [0, 3]


def test_robot_camera_frames_bodies_that_start_apart():
    scene = SceneLogger([], CAPTURE_CONFIG)
    eye, target = scene._camera()
    start = np.array(CAPTURE_PARAMS["bodies"]["target"]["position"])
    assert np.allclose(target, start / 2)
    assert abs((eye - target) @ start) < 1e-9 and np.linalg.norm(eye - target) > 2 * np.linalg.norm(start)
    eye, target = SceneLogger([], CONFIG)._camera()  # one body at the origin: as before
    assert tuple(eye) == (1.9, -1.6, 1.0) and not target.any()


def test_replay_finds_a_config_named_relative_to_the_project_root(tmp_path, monkeypatch):
    """A run started in the project root records ``configs/x.yaml``; a replay from elsewhere still
    resolves the config's URDF paths (``../models/...``) from there."""
    from components.viewer.replay import read_recording

    (tmp_path / "signals.parquet").write_bytes(b"")
    (tmp_path / "config.yaml").write_text("run: {name: r}\n")
    (tmp_path / "events.jsonl").write_text(
        '{"event": "start", "run_id": "r-1", "config": "configs/capture_tumbling_target.yaml"}\n'
    )
    monkeypatch.chdir(tmp_path)
    assert read_recording(tmp_path)[1:] == ((ROOT / "configs").resolve(), "r-1")
