"""Config validation: every error names its key and file, all errors at once, before any process."""

import textwrap
from pathlib import Path

import pytest

from orchestrator.config.load import load, validate
from orchestrator.config.yaml_file import ConfigErrors

GOOD = """
run: {name: chain, epoch: 2022-09-18T12:00:00Z, duration: 2 s, step: 1 ms}
components:
  src: {type: test.constant, parameters: {value: 1.0}}
  int: {type: test.integrator, step: 10 ms, parameters: {gain: 2}}
connections:
  int.u: src.y
"""


def errors_of(write_config, text, overrides=()):
    with pytest.raises(ConfigErrors) as e:
        load(write_config(textwrap.dedent(text)), overrides)
    return e.value.errors


def test_good_config_resolves_units_defaults_and_routes(write_config):
    config = load(write_config(GOOD))
    assert config.step_ns == 1_000_000 and config.steps == 2000
    assert config.algorithm == "jacobi"  # documented default, written to config.yaml
    assert config.components["int"].step_ns == 10_000_000
    assert config.components["int"].resolved["x0"] == 0.0  # default filled
    assert config.connections == [("int", "u", "src", "y")]
    assert config.resolved["components"]["int"]["parameters"] == {"gain": 2.0, "x0": 0.0}
    assert config.epoch == "2022-09-18T12:00:00Z"


def test_overrides_reach_any_key(write_config):
    config = load(
        write_config(GOOD), ["run.duration=0.02", "components.int.parameters.gain=50", "run.algorithm=gauss-seidel"]
    )
    assert config.steps == 20 and config.algorithm == "gauss-seidel"
    assert config.components["int"].resolved["gain"] == 50.0


@pytest.mark.parametrize(
    "text, key",
    [
        (GOOD + "not_a_key: 1\n", "not_a_key: unknown key"),
        (GOOD.replace("step: 1 ms}", "step: 1 ms, colour: red}"), "run.colour: unknown key"),
        (GOOD.replace("name: chain, ", ""), "run.name: missing required key"),
        (GOOD.replace("duration: 2 s", "duration: 2 parsecs"), "run.duration: unknown time unit"),
        (GOOD.replace("step: 10 ms", "step: 1.5 ms"), "components.int.step: must be a positive integer multiple"),
        (GOOD.replace("{gain: 2}", "{gain: 2, gian: 3}"), "components.int.parameters.gian: unknown parameter"),
        (GOOD.replace("{value: 1.0}", "{}"), "components.src.parameters.value: missing required parameter"),
        (GOOD.replace("{gain: 2}", "{gain: '2 km'}"), "components.int.parameters.gain: unit 'km' does not measure 1"),
        (GOOD.replace("int.u: src.y", "int.u: src.z"), "connections.int.u: src (test.constant) has no output 'z'"),
        (GOOD.replace("int.u: src.y", "int.v: src.y"), "connections.int.v: int (test.integrator) has no input 'v'"),
        (GOOD.replace("int.u: src.y", "int.u: nowhere.y"), "connections.int.u: no component named 'nowhere'"),
        (GOOD.replace("test.constant", "orbit.warp_drive"), "components.src.type: unknown component type"),
        (GOOD.replace("step: 1 ms}", "step: 1 ms, algorithm: newton}"), "run.algorithm: expected one of jacobi"),
        (GOOD.replace("duration: 2 s", "duration: 2.0005 s"), "run.duration: must be a whole number of steps"),
        (GOOD.replace("epoch: 2022-09-18T12:00:00Z", "epoch: yesterday"), "run.epoch"),
        (GOOD + "events: [{at: 1 s, swap: ghost}]\n", "events[0].swap: no component named 'ghost'"),
        (GOOD + "events: [{at: 3 s, swap: int}]\n", "events[0].at: must be within the run"),
        (GOOD + "events: [{at: 5 ms, swap: int}]\n", "events[0].at: must fall on a step boundary of int"),
        (
            GOOD + "events: [{at: 1 s, swap: src, type: test.counter}]\n",
            "events[0]: test.counter has no output 'y', which the connection int.u: src.y uses",
        ),
        (GOOD.replace("duration: 2 s", "duration: .inf"), "run.duration: expected a finite duration"),
        (GOOD.replace("step: 10 ms", "step: .nan"), "components.int.step: expected a finite duration"),
        (GOOD.replace("{gain: 2}", "{gain: .nan}"), "components.int.parameters.gain: expected a finite quantity"),
        (GOOD.replace("step: 1 ms}", "step: 1 ms, step_timeout: 0 s}"), "run.step_timeout: expected a duration > 0"),
        (GOOD.replace("step: 1 ms}", "step: 1 ms, realtime: .nan}"), "run.realtime: expected a finite quantity"),
        (GOOD + "bus: {listen: [foo/bar]}\n", "bus.listen[0]: expected a Zenoh endpoint like tcp/127.0.0.1:0"),
        (GOOD.replace("type: test.constant", "type: 5"), "components.src.type: expected a component type name"),
        (
            GOOD.replace("{value: 1.0}}", "{value: 1.0}, dedicated_cpu: yes please}"),
            "components.src.dedicated_cpu: expected one of process, got 'yes please'",
        ),
        (
            GOOD.replace("{value: 1.0}}", "{value: 1.0}, dedicated_cpu: 1}"),
            "components.src.dedicated_cpu: expected bool or process, got 1",
        ),
        (
            GOOD.replace("{value: 1.0}}", "{value: 1.0}, launch: external, dedicated_cpu: true}"),
            "components.src.dedicated_cpu: only for components the orchestrator starts",
        ),
        (
            GOOD.replace("{value: 1.0}}", "{value: 1.0}, launch: external, dedicated_cpu: process}"),
            "components.src.dedicated_cpu: only for components the orchestrator starts",
        ),
    ],
)
def test_each_error_names_its_key_and_file(write_config, text, key):
    errors = errors_of(write_config, text)
    assert any(key in e for e in errors), errors
    assert all("config.yaml" in e for e in errors)


def test_all_errors_are_reported_at_once(write_config):
    text = GOOD.replace("{gain: 2}", "{gian: 3}").replace("int.u: src.y", "int.u: src.z") + "extra: 1\n"
    errors = errors_of(write_config, text)
    assert len(errors) == 3, errors


def test_shape_mismatch_is_an_error(write_config):
    text = """
    run: {name: s, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 1 ms}
    components:
      a: {type: test.noop, parameters: {size: 3}}
      b: {type: test.noop, parameters: {size: 2}}
    connections: {b.u: a.y}
    """
    assert any("shape mismatch" in e and "connections.b.u" in e for e in errors_of(write_config, text))


def test_duplicate_yaml_keys_are_errors(write_config):
    text = GOOD + "connections:\n  int.u: src.y\n"
    assert any("duplicate key 'connections'" in e for e in errors_of(write_config, text))


def test_bad_override_syntax(write_config):
    with pytest.raises(ConfigErrors, match="expected KEY=VALUE"):
        load(write_config(GOOD), ["run.duration"])


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigErrors, match="cannot read config"):
        load(tmp_path / "absent.yaml")


def test_a_user_component_file_that_fails_to_load_is_one_config_error(write_config, tmp_path):
    (tmp_path / "broken.py").write_text("raise RuntimeError('half-written component')\n")
    errors = errors_of(write_config, GOOD.replace("type: test.constant", "type: broken.py:Thing"))
    assert any("components.src.type: loading 'broken.py'" in e and "half-written component" in e for e in errors)


def test_restart_needs_the_state_of_every_component(tmp_path):
    from components.testing.blocks import Counter
    from orchestrator.config.load import load
    from orchestrator.config.yaml_file import ConfigErrors

    (tmp_path / "stateless.py").write_text(
        "from components.testing.blocks import Counter\n\n"
        "class Stateless(Counter):\n    get_state = set_state = Counter.__mro__[1].get_state\n"
    )
    config = tmp_path / "c.yaml"
    config.write_text(
        "run: {name: r, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 1 ms, checkpoint_every: 3 ms}\n"
        "components:\n  a: {type: test.counter, on_failure: restart, step: 2 ms}\n"
        "  b: {type: stateless.py:Stateless}\n"
        "faults: [{at: 2 s, component: a, kind: crash}, {at: 0 s, component: z, kind: nan},\n"
        "         {at: 0 s, component: a, kind: delay}, {at: 0 s, component: a, kind: hang, duration: 1 s}]\n"
    )
    with pytest.raises(ConfigErrors) as raised:
        load(config)
    errors = "\n".join(raised.value.errors)
    assert (
        "components.a.on_failure: restart needs the state of every component, and b (stateless.py:Stateless)" in errors
    )
    assert "run.checkpoint_every: must be a multiple of every component's step" in errors
    assert "faults[0].at: must be within the run" in errors
    assert "faults[1].component: no component named 'z'" in errors
    assert "faults[2].duration: a delay needs one" in errors
    assert "faults[3].duration: only a delay has one, not a hang" in errors
    assert Counter.restorable()


SHADOWS = """
run: {name: s, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 1 ms}
components:
  src: {type: test.noop, parameters: {size: 3}}
  b: {type: test.noop, parameters: {size: 3}, shadow: {type: orbit.warp_drive}}
  c: {type: test.noop, parameters: {size: 3}, shadow: {type: test.noop, parameters: {size: 2}}}
  d: {type: test.noop, parameters: {size: 3}, shadow: {type: test.integrator}}
  e: {type: test.noop, parameters: {size: 3}, shadow: {type: test.noop, parameters: {size: 3}}}
  e_shadow: {type: test.constant, parameters: {value: 1}}
  f: {type: test.integrator, shadow: {type: milli.py:Milli}}
  g: {type: test.integrator, shadow: {type: test.integrator, parameters: {gain: 3}}}
connections: {b.u: src.y, c.u: src.y, d.u: src.y, e.u: src.y}
"""


def test_a_shadow_is_checked_like_a_component_and_against_its_main(write_config, tmp_path, capsys):
    from orchestrator.cli import main

    # u_time in ms where test.integrator has it in s
    (tmp_path / "milli.py").write_text(
        "from components.sdk import Variable\nfrom components.testing.blocks import Integrator\n\n"
        "class Milli(Integrator):\n    @classmethod\n    def declare(cls, params, run):\n"
        "        return [Variable('u', 'input', (), '1', 0.0, 'rate'), Variable('x', 'output', (), '1', 0.0, 'x'),\n"
        "                Variable('u_time', 'output', (), 'ms', 0.0, 'when')]\n"
    )
    unknown = SHADOWS.replace("{type: orbit.warp_drive}", "{type: test.noop, colour: red}")
    assert main(["check", str(write_config(unknown))]) == 2  # the schema first, as for a component
    assert "components.b.shadow.colour: unknown key (known: type, parameters)" in capsys.readouterr().err
    assert main(["check", str(write_config(SHADOWS))]) == 2
    errors = capsys.readouterr().err.splitlines()
    expected = {
        "components.b.shadow.type: unknown component type 'orbit.warp_drive'": 1,
        "components.c.shadow: input 'u': expected shape (3,) in 1 (as c, test.noop), got shape (2,) in 1": 1,
        "components.c.shadow: output 'y': expected shape (3,) in 1 (as c, test.noop), got shape (2,)": 1,
        "components.d.shadow: input 'u': expected shape (3,) in 1 (as d, test.noop), got shape () in 1": 1,
        "components.d.shadow: output 'y': expected shape (3,) in 1 (as d, test.noop), test.integrator has no such output": 1,
        "components.e.shadow: its outputs are recorded as e_shadow.<output>, and a component is named 'e_shadow'": 1,
        "components.f.shadow: output 'u_time': expected shape () in s (as f, test.integrator), got shape () in ms": 1,
    }
    assert {k: sum(k in e for e in errors) for k in expected} == expected, errors
    assert len(errors) == len(expected) and not any("components.g" in e for e in errors), errors


def test_a_shadow_takes_its_mains_inputs_right_after_it_and_stays_nested_in_the_resolved_config(write_config):
    text = (
        SHADOWS.split("  b:")[0]
        + "  g: {type: test.integrator, shadow: {type: test.integrator, parameters: {gain: 3}}}\n"
        "  h: {type: test.integrator}\nconnections: {g.u: h.x, h.u: g.x}\n"
    )
    config = load(write_config(text))
    assert list(config.components) == ["src", "g", "g_shadow", "h"]
    assert config.components["g_shadow"].shadow_of == "g" and config.components["g_shadow"].resolved["gain"] == 3.0
    assert config.connections == [("g", "u", "h", "x"), ("h", "u", "g", "x"), ("g_shadow", "u", "h", "x")]
    assert config.resolved["components"]["g"]["shadow"] == {
        "type": "test.integrator",
        "parameters": {"gain": 3.0, "x0": 0.0},
    }
    assert "g_shadow" not in config.resolved["components"] and "g_shadow.u" not in config.resolved["connections"]
    from orchestrator.config.shadows import connections_of

    # a main fed by itself: its shadow is fed by itself (its own loop is part of what is shadowed)
    assert connections_of("a", [("a", "u", "a", "x"), ("a", "v", "b", "y"), ("b", "u", "a", "x")]) == [
        ("a_shadow", "u", "a_shadow", "x"),
        ("a_shadow", "v", "b", "y"),
    ]


def test_a_swap_to_a_type_that_takes_the_state_keeps_the_parameters_and_the_outputs():
    """dynamics.dart -> dynamics.pinocchio hands the state over (Component.takes_state_of): the
    event's parameters default to the old ones, as for the same type; new parameters that change
    the outputs are refused at check, naming the event; to a type that does not take the state
    (test.*) nothing is handed over and nothing is refused for it."""
    from pathlib import Path

    from components import registry
    from orchestrator.config.connections import hands_over

    demo = Path(__file__).resolve().parents[2] / "configs" / "humanoid_tracking.yaml"
    config = load(demo, ["events=[{at: 5 s, swap: dynamics, type: dynamics.pinocchio}]"])
    old, event = config.components["dynamics"], config.events[0]
    assert event.parameters == old.parameters and hands_over(old, event.type, event.spec.cls)
    assert not hands_over(old, "test.noop", registry.load("test.noop"))
    with pytest.raises(ConfigErrors) as e:
        load(
            demo,
            [
                "events=[{at: 5 s, swap: dynamics, type: dynamics.pinocchio, parameters: "
                "{link_outputs: true, bodies: {humanoid: {urdf: ../models/humanoid_torso.urdf}}}}]"
            ],
        )
    assert (
        len(e.value.errors) == 1
        and "events[0]: a swap from dynamics.dart to dynamics.pinocchio hands the state "
        "over, so the new outputs must be the old ones"
        in e.value.errors[0]
    )


def test_messages_show_numbers_not_numpy_reprs():
    """A zero quaternion (checked after the values became numpy floats) is refused showing the
    numbers as written, not np.float64(...) (issue 34); the same for a component's runtime error."""
    from components.errors import ComponentError

    raw = {
        "run": {"name": "q", "epoch": "2022-09-18T12:00:00Z", "duration": "1 s", "step": "10 ms"},
        "components": {
            "dynamics": {
                "type": "dynamics.dart",
                "parameters": {
                    "bodies": {
                        "target": {
                            "urdf": str(Path(__file__).resolve().parents[2] / "models" / "capture" / "target.urdf"),
                            "orientation": [0, 0, 0, 0],
                        }
                    }
                },
            }
        },
    }
    with pytest.raises(ConfigErrors) as caught:
        validate(raw, Path("q.yaml"), full=True)
    text = "\n".join(caught.value.errors)
    assert "orientation: expected a unit quaternion [x, y, z, w], got [0.0, 0.0, 0.0, 0.0]" in text, text
    assert "np." not in text
    import numpy as np

    assert str(ComponentError(f"got {[np.float64(1.5), np.int64(2)]}")) == "got [1.5, 2]"


def test_a_latency_that_is_not_a_whole_number_of_steps_is_refused_before_the_run():
    """sensor.relative_pose with latency 70 ms and step 50 ms: refused by check (and run) naming
    the key, not at the run's first step (issue 34)."""
    root = Path(__file__).resolve().parents[2]
    with pytest.raises(ConfigErrors) as caught:
        load(
            root / "configs" / "capture_tumbling_target.yaml",
            ["components.pose_sensor.parameters.latency=70 ms"],
            full=True,
        )
    text = "\n".join(caught.value.errors)
    assert (
        "components.pose_sensor.parameters.latency: must be a non-negative integer multiple of the component's "
        "step (50 ms"
    ) in text, text


def test_bodies_that_overlap_at_the_start_are_warned_at_check():
    """The capture target's CoM 0.3 m from the servicer's bus centre (inside it): check warns,
    naming both bodies and links and the depth (Bullet's narrow phase on the URDFs' collision
    geometry: the 1.2 m bus and the 1.67 m target box overlap by 0.6 + 0.835 - 0.3 = 1.135 m along
    x, less along the deepest contact's normal); the shipped placement, 2.4 m apart, gets no word."""
    root = Path(__file__).resolve().parents[2]
    config = root / "configs" / "capture_tumbling_target.yaml"
    inside = load(config, ["components.dynamics.parameters.bodies.target.position=[0.3, 0, 0]"], full=True)
    found = [n for n in inside.notes if "overlap at the start" in n]
    assert len(found) == 1, inside.notes
    assert (
        "bodies.servicer and bodies.target overlap at the start: servicer's link 'bus' and target's link 'target' by "
    ) in found[0] and "they pass through each other" in found[0]
    depth = float(found[0].split(" by ")[1].split(" mm")[0]) / 1e3
    assert 0.0 < depth <= 1.135 + 1e-6
    assert not [n for n in load(config, full=True).notes if "overlap" in n]


def test_a_process_group_is_one_line_per_component_and_kept_in_the_resolved_config(write_config):
    config = load(
        write_config(
            GOOD.replace("{value: 1.0}}", "{value: 1.0}, process: loop}").replace(
                "{gain: 2}}", "{gain: 2}, process: loop, shadow: {type: test.integrator}}"
            )
            + "events: [{at: 1 s, swap: int}]\n"
        )
    )
    assert [config.components[n].process for n in ("src", "int", "int_shadow")] == ["loop", "loop", None]
    assert config.events[0].spec.process is None  # a swap's new generation: a process of its own
    assert config.resolved["components"]["int"]["process"] == "loop"
    assert "process" not in load(write_config(GOOD, "plain.yaml")).resolved["components"]["int"]  # the default


@pytest.mark.parametrize(
    "entries, expected",
    [
        (
            "launch: external, process: loop}",
            "components.src.process: group 'loop' is one process, started by the "
            "orchestrator or by you: expected its members all launch: local, got launch: external (src) beside "
            "launch: local (int)",
        ),
        (
            "dedicated_cpu: true, process: loop}",
            "components.src.dedicated_cpu: the members of group 'loop' share one "
            "process and its CPU: expected those that ask for one to agree (true or process), got src: true, int: process",
        ),
        ("process: 7up}", "components.src.process: expected a group name: a letter, then letters, digits or '_'"),
    ],
)
def test_a_group_whose_members_disagree_is_refused_saying_what_was_expected(write_config, entries, expected):
    text = GOOD.replace("{value: 1.0}}", "{value: 1.0}, " + entries).replace(
        "{gain: 2}}", "{gain: 2}, process: loop, dedicated_cpu: process}"
    )
    errors = errors_of(write_config, text)
    assert any(expected in e for e in errors), errors


def test_an_external_group_is_refused_with_the_reason(write_config):
    text = GOOD.replace("{value: 1.0}}", "{value: 1.0}, launch: external, process: far}").replace(
        "{gain: 2}}", "{gain: 2}, launch: external, process: far}"
    )
    errors = errors_of(write_config, text)
    assert any(
        "components.src.process: group 'far' (src, int) is launch: external; orchestrator join serves one "
        "component" in e
        for e in errors
    ), errors


def test_a_type_that_cannot_share_a_process_is_refused_with_its_reason(write_config, monkeypatch):
    from components.testing.blocks import Constant

    monkeypatch.setattr(
        Constant, "group_problem", classmethod(lambda cls, params, run: "it owns the process's signals")
    )
    errors = errors_of(write_config, GOOD.replace("{value: 1.0}}", "{value: 1.0}, process: loop}"))
    assert any(
        "components.src.process: src (test.constant) cannot join group 'loop': it owns the process's "
        "signals; run it in a process of its own (no process: key)" in e
        for e in errors
    ), errors


def test_view_foxglove_port():
    from orchestrator.config.views import viewer_spec

    errors: list[str] = []
    assert viewer_spec("foxglove", "--view", errors, Path(".")).port == 8765
    assert viewer_spec("foxglove:9000", "--view", errors, Path(".")).port == 9000
    assert viewer_spec({"mode": "foxglove", "port": 9001}, "viewer", errors, Path(".")).port == 9001
    assert errors == []
    assert viewer_spec("foxglove:70000", "--view", errors, Path(".")) is None
    assert viewer_spec("foxglove:x", "--view", errors, Path(".")) is None
    assert "65535" in errors[0] and "port number" in errors[1]


def test_ros2_section_domain_from_environment_and_endpoint_override(monkeypatch):
    from orchestrator.config.views import ros2_spec

    monkeypatch.setenv("ROS_DOMAIN_ID", "5")
    errors: list[str] = []
    spec = ros2_spec({"topics": ["/clock"]}, "ros2", errors, endpoint="tcp/192.0.2.7:7447")
    assert errors == [] and (spec.endpoint, spec.domain_id, spec.distro, spec.topics, spec.rate_hz) == (
        "tcp/192.0.2.7:7447",
        5,
        "jazzy",
        ["/clock"],
        30.0,
    )
    assert ros2_spec({"domain_id": 3}, "ros2", errors).domain_id == 3  # the section wins over the environment
    monkeypatch.setenv("ROS_DOMAIN_ID", "five")
    assert ros2_spec(None, "--ros2", errors) is None and "ROS_DOMAIN_ID" in errors[-1] and "'five'" in errors[-1]
    monkeypatch.delenv("ROS_DOMAIN_ID")
    errors = []
    assert ros2_spec(None, "--ros2", errors).domain_id == 0
    assert ros2_spec({"topics": ["/ok", "/2d/pose"]}, "ros2", errors) is None
    assert errors == ["ros2.topics[1]: ROS 2 rejects the topic name '/2d/pose': a part of it starts with a digit"]


def test_a_camera_without_bodies_takes_the_dynamics_and_one_with_them_keeps_its_own():
    """The config's fill (orchestrator/config/scene.py): the camera's scene is the dynamics' bodies
    as name -> urdf when left out or null, its own when given; a swap event's camera likewise; two
    components naming bodies leave no scene to take."""
    from orchestrator.config.scene import fill_scenes

    bodies = {"a": {"urdf": "a.urdf", "frame": "lvlh"}, "b": {"urdf": "b.urdf"}}
    config = {
        "components": {
            "dynamics": {"type": "dynamics.dart", "parameters": {"bodies": bodies}},
            "left_out": {"type": "sensor.camera", "parameters": {"body": "a"}},
            "null": {"type": "sensor.camera", "parameters": {"body": "a", "bodies": None}},
            "own": {"type": "sensor.camera", "parameters": {"bodies": {"a": "other.urdf"}}},
        },
        "events": [{"swap": "own", "type": None, "parameters": {"body": "b"}}],
    }
    errors = []
    fill_scenes(config, Path("."), Path("c.yaml"), errors)
    cameras = {
        name: entry["parameters"]["bodies"] for name, entry in config["components"].items() if name != "dynamics"
    }
    assert not errors and cameras == {
        "left_out": {"a": "a.urdf", "b": "b.urdf"},
        "null": {"a": "a.urdf", "b": "b.urdf"},
        "own": {"a": "other.urdf"},
    }
    assert config["events"][0]["parameters"] == {"body": "b", "bodies": {"a": "a.urdf", "b": "b.urdf"}}
    assert config["components"]["dynamics"]["parameters"]["bodies"] is bodies  # the dynamics' untouched

    config["components"]["second"] = {"type": "dynamics.pinocchio", "parameters": {"bodies": bodies}}
    config["components"]["left_out"]["parameters"] = {"body": "a"}
    fill_scenes(config, Path("."), Path("c.yaml"), errors)
    assert errors == [
        "c.yaml: components.left_out.parameters.bodies: the run's bodies are in dynamics and second: give this one's "
        "(body name -> URDF)"
    ]
