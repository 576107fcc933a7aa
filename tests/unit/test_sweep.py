"""Campaigns, the pure parts: keys, distributions, case generation, metrics, validation."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from orchestrator.config import validate
from orchestrator.campaign_metrics import reduce_signal
from orchestrator.dispersions import dispersion
from orchestrator.sweep import CampaignErrors, key_path, load_campaign, set_key, si_value

BASE = {
    "run": {"name": "sweepme", "epoch": "2022-09-18T12:00:00Z", "duration": "50 ms", "step": "10 ms"},
    "components": {"push": {"type": "test.constant", "parameters": {"value": 1.0}},
                   "total": {"type": "test.integrator", "parameters": {"gain": 2.0}}},
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
    assert key_path("components.d.parameters.bodies.t.twist[5]") == ["components", "d", "parameters", "bodies",
                                                                       "t", "twist", 5]
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
    assert other.draw(7, 3) != value                      # independent streams per key
    mixed = dispersion("k", {"uniform": ["1 deg", "0.5 rad"]}, "w")
    assert mixed.unit == "deg" and mixed.args[0] == 1.0 and math.isclose(mixed.args[1], 0.5 / math.pi * 180)
    t = dispersion("k", {"truncated_normal": [0, 1, -0.1, 0.2]}, "w")
    draws = [t.draw(1, i) for i in range(200)]
    assert all(-0.1 <= x <= 0.2 for x in draws) and len(set(draws)) == 200
    c = dispersion("k", {"choice": ["rk4", "euler"]}, "w")
    assert {c.draw(0, i) for i in range(50)} == {"rk4", "euler"}
    for spec, message in (({"gauss": [0, 1]}, "unknown distribution"), ({"normal": [0]}, "expected [mean, sigma]"),
                          ({"normal": [0, -1]}, "sigma must be positive"), ({"uniform": [2, 1]}, "low must be below"),
                          ({"normal": ["0 m", "1 s"]}, "share a unit"), ({"normal": ["0 furlong", 1]}, "unknown unit"),
                          ([0, 1], "expected one distribution")):
        with pytest.raises(Exception, match=message.replace("[", r"\[")):
            dispersion("k", spec, "disperse.k")


def test_cases_come_from_the_seed_and_their_index(tmp_path):
    campaign = load_campaign(write(tmp_path, {
        "samples": 4, "seed": 11, "grid": {"components.total.parameters.gain": [1, 3]},
        "disperse": {"components.push.parameters.value": {"normal": [1, 0.1]}},
        "metrics": {"final": {"signal": "total.x", "reduce": "final"}}, "keep": "none"}))
    assert campaign.count == 8
    cases = [campaign.case(i) for i in range(8)]
    assert [c.params["components.total.parameters.gain"] for c in cases] == [1] * 4 + [3] * 4
    values = [c.params["components.push.parameters.value"] for c in cases]
    assert values[:4] == values[4:] and len(set(values[:4])) == 4    # common draws on every grid point
    again = load_campaign(write(tmp_path, {
        "samples": 40, "seed": 11, "disperse": {"components.push.parameters.value": {"normal": [1, 0.1]}}},
        "other.yaml"))
    assert again.case(2).params["components.push.parameters.value"] == values[2]   # index alone, not the count
    assert cases[5].raw["components"]["total"]["parameters"]["gain"] == 3
    validate(cases[5].raw, tmp_path / "c.yaml")


def test_bad_campaigns_name_their_keys(tmp_path):
    assert "campaign.yaml: sampels: unknown key" in errors_of(tmp_path, {"sampels": 3})
    text = errors_of(tmp_path, {"seed": 1, "disperse": {"components.push.parameters.value": {"poisson": [1]}}})
    assert "disperse.components.push.parameters.value.poisson: unknown distribution" in text
    text = errors_of(tmp_path, {"seed": 1, "disperse": {"components.push.parameters.value": {"normal": ["1 m", "1 m"]}}})
    assert "components.push.parameters.value" in text and "unit 'm' does not measure" in text
    text = errors_of(tmp_path, {"metrics": {"m": {"signal": "total.nothing", "reduce": "final"}}})
    assert "metrics.m.signal: no signal 'total.nothing'" in text and "total.x" in text
    text = errors_of(tmp_path, {"metrics": {"m": {"signal": "total.x", "reduce": "median"}}})
    assert "metrics.m.reduce: expected one of" in text
    text = errors_of(tmp_path, {"metrics": {"m": {"signal": "total.x", "reduce": "first_crossing"}}})
    assert "metrics.m.threshold: first_crossing needs a threshold" in text
    text = errors_of(tmp_path, {"metrics": {"m": {"signal": "total.u_time", "reduce": "first_crossing",
                                                  "threshold": "3 m"}}})
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
    with pytest.raises(CampaignErrors, match="config: .*nowhere.yaml: cannot read"):
        load_campaign(missing)


def test_reducers():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    x = np.array([1.0, -3.0, 2.0, 0.5])
    assert reduce_signal("final", t, x) == 0.5
    assert reduce_signal("min", t, x) == -3.0 and reduce_signal("max", t, x) == 2.0
    assert reduce_signal("mean", t, x) == 0.125
    assert reduce_signal("rms", t, x) == math.sqrt((1 + 9 + 4 + 0.25) / 4)
    assert reduce_signal("max_abs", t, x) == 3.0
    assert reduce_signal("first_crossing", t, x, 0.0) == 1.0          # starts above, first below at t=1
    assert reduce_signal("first_crossing", t, np.array([0, 1, 2, 3.0]), 1.5) == 2.0
    assert math.isnan(reduce_signal("first_crossing", t, x, 10.0))


def test_vector_metric_is_the_norm_and_parameters_read_in_si(tmp_path):
    campaign = load_campaign(write(tmp_path, {"metrics": {
        "n": {"signal": "total.x", "reduce": "max"}}}))
    m = campaign.metrics[0]
    assert m.columns == ("total.x",)
    from orchestrator.campaign_metrics import Metric
    norm = Metric("n", "v", "final", ("v[0]", "v[1]"))
    assert norm.value(np.array([0.0, 1.0]), {"v[0]": np.array([0.0, 3.0]), "v[1]": np.array([1.0, 4.0])}) == 5.0
    assert si_value("2 km") == 2000.0 and si_value(3) == 3.0 and si_value("rk4") == "rk4"
