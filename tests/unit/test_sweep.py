"""Campaigns, the pure parts: keys, distributions, case generation, metrics, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from orchestrator.campaigns.campaign import key_path, set_key, si_value
from orchestrator.campaigns.campaign_file import CampaignErrors, load_campaign
from orchestrator.campaigns.dispersions import dispersion
from orchestrator.campaigns.metrics import reduce_signal
from orchestrator.config.load import validate

BASE = {
    "run": {"name": "sweepme", "epoch": "2022-09-18T12:00:00Z", "duration": "50 ms", "step": "10 ms"},
    "components": {
        "push": {"type": "test.constant", "parameters": {"value": 1.0}},
        "total": {"type": "test.integrator", "parameters": {"gain": 2.0}},
    },
    "connections": {"total.u": "push.y"},
}


def write(tmp_path, campaign: dict, name="campaign.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump({"config": BASE, **campaign}, sort_keys=False))
    return path


def errors_of(tmp_path, campaign: dict) -> str:
    with pytest.raises(CampaignErrors) as caught:
        load_campaign(write(tmp_path, campaign))
    return "\n".join(caught.value.errors)


def test_key_paths_and_indexing():
    assert key_path("components.d.parameters.bodies.t.twist[5]") == [
        "components",
        "d",
        "parameters",
        "bodies",
        "t",
        "twist",
        5,
    ]
    assert key_path("a.b[1][2].c") == ["a", "b", 1, 2, "c"]
    with pytest.raises(ValueError):
        key_path("a..b")
    raw = {"components": {"c": {"parameters": {"v": [0, 0, 0]}}}}
    set_key(raw, "components.c.parameters.v[2]", "3 m")
    set_key(raw, "components.c.parameters.new.deep", 1)
    assert raw["components"]["c"]["parameters"] == {"v": [0, 0, "3 m"], "new": {"deep": 1}}
    for bad in ("components.c.parameters.v[3]", "components.x.parameters.a", "components.c.parameters.w[0]"):
        with pytest.raises(ValueError):
            set_key(raw, bad, 0)


def test_distributions_take_units_and_depend_on_seed_draw_and_key_alone():
    d = dispersion("k", {"normal": ["0 rad/s", "0.001 rad/s"]}, "disperse.k")
    assert d.unit == "rad/s" and d.args == (0.0, 0.001)
    value = d.draw(7, 3)
    assert value == d.draw(7, 3) and value != d.draw(7, 4) and value != d.draw(8, 3)
    assert value.endswith(" rad/s")
    other = dispersion("j", {"normal": ["0 rad/s", "0.001 rad/s"]}, "disperse.j")
    assert other.draw(7, 3) != value  # independent streams per key
    mixed = dispersion("k", {"uniform": ["1 deg", "0.5 rad"]}, "w")
    assert mixed.unit == "deg" and mixed.args[0] == 1.0 and math.isclose(mixed.args[1], 0.5 / math.pi * 180)
    t = dispersion("k", {"truncated_normal": [0, 1, -0.1, 0.2]}, "w")
    draws = [t.draw(1, i) for i in range(200)]
    assert all(-0.1 <= x <= 0.2 for x in draws) and len(set(draws)) == 200
    c = dispersion("k", {"choice": ["rk4", "euler"]}, "w")
    assert {c.draw(0, i) for i in range(50)} == {"rk4", "euler"}
    for spec, message in (
        ({"gauss": [0, 1]}, "unknown distribution"),
        ({"normal": [0]}, "expected [mean, sigma]"),
        ({"normal": [0, -1]}, "sigma must be positive"),
        ({"uniform": [2, 1]}, "low must be below"),
        ({"normal": ["0 m", "1 s"]}, "share a unit"),
        ({"normal": ["0 furlong", 1]}, "unknown unit"),
        ([0, 1], "expected one distribution"),
    ):
        with pytest.raises(Exception, match=message.replace("[", r"\[")):
            dispersion("k", spec, "disperse.k")


def test_cases_come_from_the_seed_and_their_index(tmp_path):
    campaign = load_campaign(
        write(
            tmp_path,
            {
                "samples": 4,
                "seed": 11,
                "grid": {"components.total.parameters.gain": [1, 3]},
                "disperse": {"components.push.parameters.value": {"normal": [1, 0.1]}},
                "metrics": {"final": {"signal": "total.x", "reduce": "final"}},
                "keep": "none",
            },
        )
    )
    assert campaign.count == 8
    cases = [campaign.case(i) for i in range(8)]
    assert [c.params["components.total.parameters.gain"] for c in cases] == [1] * 4 + [3] * 4
    values = [c.params["components.push.parameters.value"] for c in cases]
    assert values[:4] == values[4:] and len(set(values[:4])) == 4  # common draws on every grid point
    again = load_campaign(
        write(
            tmp_path,
            {"samples": 40, "seed": 11, "disperse": {"components.push.parameters.value": {"normal": [1, 0.1]}}},
            "other.yaml",
        )
    )
    assert again.case(2).params["components.push.parameters.value"] == values[2]  # index alone, not the count
    assert cases[5].raw["components"]["total"]["parameters"]["gain"] == 3
    validate(cases[5].raw, tmp_path / "c.yaml")


def test_bad_campaigns_name_their_keys(tmp_path):
    assert "campaign.yaml: sampels: unknown key" in errors_of(tmp_path, {"sampels": 3})
    text = errors_of(tmp_path, {"seed": 1, "disperse": {"components.push.parameters.value": {"poisson": [1]}}})
    assert "disperse.components.push.parameters.value.poisson: unknown distribution" in text
    text = errors_of(
        tmp_path, {"seed": 1, "disperse": {"components.push.parameters.value": {"normal": ["1 m", "1 m"]}}}
    )
    assert "components.push.parameters.value" in text and "unit 'm' does not measure" in text
    text = errors_of(tmp_path, {"metrics": {"m": {"signal": "total.nothing", "reduce": "final"}}})
    assert "metrics.m.signal: no signal 'total.nothing'" in text and "total.x" in text
    text = errors_of(tmp_path, {"metrics": {"m": {"signal": "total.x", "reduce": "median"}}})
    assert "metrics.m.reduce: expected one of" in text
    text = errors_of(tmp_path, {"metrics": {"m": {"signal": "total.x", "reduce": "first_crossing"}}})
    assert "metrics.m.threshold: first_crossing needs a threshold" in text
    text = errors_of(
        tmp_path, {"metrics": {"m": {"signal": "total.u_time", "reduce": "first_crossing", "threshold": "3 m"}}}
    )
    assert "metrics.m.threshold: unit 'm' does not measure s" in text
    text = errors_of(tmp_path, {"grid": {"components.pull.parameters.value": [1, 2]}})
    assert "grid.components.pull.parameters.value: no component 'pull'" in text
    text = errors_of(tmp_path, {"grid": {"components.push.parameters.valeu": [1]}})
    assert "components.push.parameters.valeu" in text and "unknown" in text
    text = errors_of(tmp_path, {"disperse": {"components.push.parameters.value": {"normal": [1, 0.1]}}})
    assert "seed: missing" in text
    assert "keep: expected one of all, failed, none" in errors_of(tmp_path, {"keep": "some"})
    missing = tmp_path / "nofile.yaml"
    missing.write_text("config: nowhere.yaml\n")
    with pytest.raises(CampaignErrors, match=r"config: .*nowhere\.yaml: cannot read"):
        load_campaign(missing)


def test_reducers():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    x = np.array([1.0, -3.0, 2.0, 0.5])
    assert reduce_signal("final", t, x) == 0.5
    assert reduce_signal("min", t, x) == -3.0 and reduce_signal("max", t, x) == 2.0
    assert reduce_signal("mean", t, x) == 0.125
    assert reduce_signal("rms", t, x) == math.sqrt((1 + 9 + 4 + 0.25) / 4)
    assert reduce_signal("max_abs", t, x) == 3.0
    assert reduce_signal("first_crossing", t, x, 0.0) == 1.0  # starts above, first below at t=1
    assert reduce_signal("first_crossing", t, np.array([0, 1, 2, 3.0]), 1.5) == 2.0
    assert math.isnan(reduce_signal("first_crossing", t, x, 10.0))


def test_vector_metric_is_the_norm_and_parameters_read_in_si(tmp_path):
    campaign = load_campaign(write(tmp_path, {"metrics": {"n": {"signal": "total.x", "reduce": "max"}}}))
    m = campaign.metrics[0]
    assert m.columns == ("total.x",)
    from orchestrator.campaigns.metrics import Metric

    norm = Metric("n", "v", "final", ("v[0]", "v[1]"))
    assert norm.value(np.array([0.0, 1.0]), {"v[0]": np.array([0.0, 3.0]), "v[1]": np.array([1.0, 4.0])}) == 5.0
    assert si_value("2 km") == 2000.0 and si_value(3) == 3.0 and si_value("rk4") == "rk4"


# --------------------------------------------------------------------------- capture studies (issue 33)


def test_a_direction_is_uniform_on_the_sphere():
    """{direction: uniform}: unit 3-vectors whose mean over 4000 draws is within 3 sigma of 0
    (sigma = 1/sqrt(3 n) per axis) and whose z is uniform on [-1, 1] (Archimedes: a sphere's area
    is uniform in height): the quartiles of z within 0.04 of -0.5, 0, 0.5. A draw depends on the
    seed, the draw and the key alone."""
    d = dispersion("components.dynamics.parameters.bodies.target.twist.axis", {"direction": "uniform"}, "disperse.x")
    v = np.array([d.draw(7, i) for i in range(4000)])
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-15)
    assert np.all(np.abs(v.mean(axis=0)) < 3.0 / math.sqrt(3 * 4000))
    assert np.allclose(np.quantile(v[:, 2], [0.25, 0.5, 0.75]), [-0.5, 0.0, 0.5], atol=0.04)
    assert d.draw(7, 11) == d.draw(7, 11) and d.draw(7, 11) != d.draw(8, 11)
    with pytest.raises(Exception, match="uniform"):
        dispersion("k", {"direction": [0, 1]}, "disperse.k")


def test_slice_and_event_metrics():
    """A slice [i:j] is the norm of those elements alone (a wrench's force); an event metric reads
    a field of the first (or last, min, max) event of its name, counts them, and is NaN when there
    is none."""
    from orchestrator.campaigns.metrics import metric

    signals = {"dyn.wrench": (tuple(f"dyn.wrench[{i}]" for i in range(6)), "N, N*m")}
    force = metric("f", {"signal": "dyn.wrench[0:3]", "reduce": "max"}, signals, "metrics.f")
    torque = metric("tq", {"signal": "dyn.wrench[3:6]", "reduce": "max"}, signals, "metrics.tq")
    table = {
        f"dyn.wrench[{i}]": np.array(col)
        for i, col in enumerate([[3.0, 0.0], [4.0, 0.0], [0.0, 0.0], [0.0, 1.0], [0.0, 2.0], [0.0, 2.0]])
    }
    t = np.array([0.0, 1.0])
    assert force.value(t, table) == 5.0 and torque.value(t, table) == 3.0
    assert (force.unit, torque.unit) == ("N", "N*m")
    with pytest.raises(Exception, match=r"0 <= i < j <= 6"):
        metric("f", {"signal": "dyn.wrench[4:9]", "reduce": "max"}, signals, "metrics.f")
    events = [
        {"event": "capture", "time": 4.15},
        {"event": "grasp_overload", "torque": 31.0},
        {"event": "grasp_overload", "torque": 45.0},
        {"event": "capture_aborted", "reason": "out of reach"},
    ]
    at = metric("at", {"event": "capture", "field": "time"}, None, "metrics.at")
    peak = metric("peak", {"event": "grasp_overload", "field": "torque", "reduce": "max"}, None, "metrics.peak")
    count = metric("n", {"event": "grasp_overload", "reduce": "count"}, None, "metrics.n")
    why = metric("why", {"event": "capture_aborted", "field": "reason"}, None, "metrics.why")
    assert at.value(t, {}, events) == 4.15 and peak.value(t, {}, events) == 45.0 and count.value(t, {}, events) == 2.0
    assert why.value(t, {}, events) == "out of reach"
    assert math.isnan(at.value(t, {}, events[1:]))
    with pytest.raises(Exception, match="field"):
        metric("x", {"event": "capture"}, None, "metrics.x")


def test_outcomes_come_from_the_last_listed_event(tmp_path):
    """outcomes: {captured: capture, aborted: capture_aborted}: a run that failed is 'failed'
    whatever its events; else the outcome of the last listed event; else 'completed'. The names
    of a run's own states are refused."""
    campaign = load_campaign(write(tmp_path, {"outcomes": {"captured": "capture", "aborted": "capture_aborted"}}))
    assert campaign.outcome("completed", ["start", "capture", "end"]) == "captured"
    assert campaign.outcome("completed", ["capture", "grasp_overload", "capture_aborted"]) == "aborted"
    assert campaign.outcome("completed", ["start", "end"]) == "completed"
    assert campaign.outcome("failed", ["capture"]) == "failed"
    assert "outcomes.failed: completed, failed, interrupted are the outcomes of a run itself" in errors_of(
        tmp_path, {"outcomes": {"failed": "capture"}}
    )
    assert campaign.outcome("completed", ["start", "end"], "undecided") == "undecided"  # no listed event: the run's


def test_without_outcomes_a_case_is_what_its_run_declares(tmp_path):
    """No outcomes: key: a capture case is captured, aborted or undecided as its run's end event
    says, not 'completed'; a failed run stays failed; a run declaring none is completed."""
    campaign = load_campaign(write(tmp_path, {}))
    assert campaign.outcome("completed", ["start", "capture_closed", "end"], "captured") == "captured"
    assert campaign.outcome("completed", ["start", "end"], "undecided") == "undecided"
    assert campaign.outcome("failed", ["start"], "") == "failed"
    assert campaign.outcome("completed", ["start", "end"], "") == "completed"


def test_a_twist_from_rate_and_axis(tmp_path):
    """bodies.<b>.twist: {rate, axis, axes, linear}: rate times the normalized axis, in the body's
    own axes turned by its orientation (axes: body) or as given (axes: frame); a zero axis is
    refused naming the key."""
    from components.dynamics.specs import initial_twist
    from components.errors import ConfigError
    from components.rotations import quat_to_matrix

    q = np.array([0.1, -0.3, 0.2, 0.9]) / np.linalg.norm([0.1, -0.3, 0.2, 0.9])
    body = {
        "orientation": q.tolist(),
        "twist": {"rate": 0.07, "axis": [1.0, 2.0, 2.0], "axes": "body", "linear": [0.0, 0.01, 0.0]},
    }
    twist = np.array(initial_twist(body))
    assert np.allclose(twist[:3], [0.0, 0.01, 0.0], atol=0.0)
    assert np.allclose(twist[3:], quat_to_matrix(q) @ np.array([1.0, 2.0, 2.0]) / 3.0 * 0.07, atol=1e-16)
    body["twist"]["axes"] = "frame"
    assert np.allclose(np.array(initial_twist(body))[3:], [0.07 / 3, 0.14 / 3, 0.14 / 3], atol=1e-16)
    body["twist"]["axis"] = [0.0, 0.0, 0.0]
    with pytest.raises(ConfigError, match=r"twist\.axis"):
        initial_twist(body)


def test_check_validates_a_campaign_and_run_points_to_sweep(tmp_path, capsys):
    """`orchestrator check CAMPAIGN` validates the campaign (its cases counted; a bad key refused
    with exit 2 naming it); `orchestrator run CAMPAIGN` says it is a campaign and what runs it."""
    from orchestrator.cli import main

    path = write(
        tmp_path, {"samples": 4, "seed": 3, "disperse": {"components.push.parameters.value": {"uniform": [0.0, 1.0]}}}
    )
    assert main(["check", str(path)]) == 0
    assert "ok — a campaign of 4 cases" in capsys.readouterr().out
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}: a campaign file" in err and f"orchestrator sweep {path} --out DIR runs it" in err
    bad = write(
        tmp_path,
        {"samples": 4, "seed": 3, "disperse": {"components.push.parameters.valu": {"uniform": [0.0, 1.0]}}},
        name="bad.yaml",
    )
    assert main(["check", str(bad)]) == 2
    assert "components.push.parameters.valu" in capsys.readouterr().err
