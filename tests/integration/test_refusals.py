"""Every command of the `orchestrator` CLI that takes an output path or an input path refuses a bad
one cleanly, run as a user would (a process of its own, from a directory outside the repository):
exit 2, a message naming the path as given, no traceback, and nothing written or started.

The unwritable output is a path under a regular file (``file.txt/out``): it fails for root too,
where a read-only directory would not (the tests may run as root)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from components.camera.frames import frame_path, write_frame
from orchestrator.cli import build_parser
from tests.conftest import ROOT, needs, orchestrator

pytestmark = pytest.mark.integration

CONFIG = ROOT / "configs" / "orbit_iss_kepler.yaml"
CAMPAIGN = ROOT / "configs" / "campaigns" / "capture_envelope.yaml"
UNWRITABLE = "file.txt/out"  # under a regular file, relative to the test's directory

# command -> the arguments with an unwritable output ({rec}: a recording; {out}: UNWRITABLE)
OUTPUTS = {
    "run --record": ["run", CONFIG, "--record", "{out}"],
    "run --view save:": ["run", CONFIG, "--view", "save:{out}/run.rrd"],
    "plot --out": ["plot", "{rec}", "--out", "{out}"],
    "export --rosbag2": ["export", "{rec}", "--rosbag2", "{out}"],
    "sweep --out": ["sweep", CAMPAIGN, "--out", "{out}"],
    "export-fmu -o": ["export-fmu", "orbit.kepler", "-o", "{out}/orbit.fmu"],
    "view --view save:": ["view", "{rec}", "--view", "save:{out}/replay.rrd"],
    "figure --out": ["figure", "{rec}", "--component", "camera", "--time", "0", "--out", "{out}/frame.png"],
}
# command -> the arguments with a missing input (named "missing...", in the test's directory)
INPUTS = {
    "run": ["run", "missing.yaml"],
    "check": ["check", "missing.yaml"],
    "plot": ["plot", "missing"],
    "export": ["export", "missing", "--rosbag2", "bag"],
    "sweep": ["sweep", "missing.yaml", "--out", "campaign"],
    "join": ["join", "missing.join"],
    "router": ["router", "--listen", "tcp/127.0.0.1:7999", "--join", "missing.join"],
    "describe": ["describe", "missing.py:Component"],
    "export-fmu": ["export-fmu", "missing.py:Component", "-o", "model.fmu"],
    "view": ["view", "missing", "--view", "save:replay.rrd"],
    "figure": ["figure", "missing", "--component", "camera", "--time", "0", "--out", "frame.png"],
    "markers": ["markers", "missing.yaml"],
}
NO_PATHS = {"ps", "stop", "swap", "types"}  # they take no path
# command -> the extra it needs (without it, it is refused for that: tests/unit/test_extras.py)
EXTRAS = {
    "run --view save:": "view",
    "view --view save:": "view",
    "view": "view",
    "export-fmu -o": "fmi",
    "export-fmu": "fmi",
    "markers": "vision",
}


def cases(commands: dict) -> list:
    return [pytest.param(case, marks=needs(EXTRAS[case]) if case in EXTRAS else ()) for case in commands]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A real recording (1 s of the ISS orbit) with a camera's frame added beside it."""
    record = tmp_path_factory.mktemp("refusals") / "rec"
    done = orchestrator("run", CONFIG, "--record", record, "--set", "run.duration=1s", timeout=120)
    assert done.returncode == 0, done.stderr
    rng = np.random.default_rng(0)
    (record / "frames" / "camera").mkdir(parents=True)
    write_frame(
        frame_path(record / "frames" / "camera", 0),
        {
            "rgb": rng.integers(0, 256, (48, 64, 3), dtype=np.uint8),
            "depth": np.ones((48, 64), np.float32),
            "t": np.float64(0.0),
        },
    )
    return record


def _files(directory) -> set[str]:
    return {os.path.join(d, f) for d, _, files in os.walk(directory) for f in files + ["."]}


def _refused(done, named: str) -> None:
    assert done.returncode == 2, f"expected exit 2, got {done.returncode}: {done.stderr}"
    assert named in done.stderr, f"expected the message to name {named!r}, got {done.stderr!r}"
    assert "Traceback" not in done.stderr, done.stderr
    assert done.stderr.startswith("error: "), done.stderr


def test_every_command_with_a_path_is_walked():
    """A command added to the CLI is covered here, or declared to take no path."""
    parser = build_parser()
    commands = set(next(a for a in parser._actions if a.dest == "command").choices)
    covered = {key.split()[0] for key in OUTPUTS} | set(INPUTS) | NO_PATHS
    assert commands == covered, f"expected {sorted(commands)} covered, got {sorted(covered)}"


@pytest.mark.parametrize("case", cases(OUTPUTS))
def test_an_unwritable_output_is_refused_naming_it_before_anything_starts(case, recording, tmp_path):
    (tmp_path / "file.txt").write_text("a file, not a directory\n")
    args = [str(a).format(rec=recording, out=UNWRITABLE) for a in OUTPUTS[case]]
    before, recorded = _files(tmp_path), _files(recording)
    done = orchestrator(*args, cwd=tmp_path, timeout=120)
    _refused(done, UNWRITABLE)
    assert _files(tmp_path) == before and _files(recording) == recorded  # nothing written
    assert "started" not in done.stdout + done.stderr and not done.stdout, done.stdout


@pytest.mark.parametrize("case", cases(INPUTS))
def test_a_missing_input_is_refused_naming_it(case, tmp_path):
    done = orchestrator(*INPUTS[case], cwd=tmp_path, timeout=120)
    named = next(a for a in INPUTS[case] if a.startswith("missing")).split(":")[0]
    _refused(done, named)
    assert _files(tmp_path) == {os.path.join(str(tmp_path), ".")}, "expected nothing written"
