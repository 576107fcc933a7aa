"""The registry of live runs (`orchestrator ps`, `stop`, `swap` find runs through it): a reader
never removes the entry of a live run, whatever moment it reads it at."""

import json
import os
import subprocess
import sys

from orchestrator.run import runs


def test_an_entry_read_while_written_is_left_alone_and_a_dead_runs_is_removed():
    runs.register("r-1", "live", "tcp/127.0.0.1:1", "c.yaml", "secret")
    assert [e["name"] for e in runs.find("live")] == ["live"]
    assert sorted(p.name for p in runs.directory().iterdir()) == ["r-1.json"]  # no partial file left
    half = runs.directory() / "r-2.json"
    half.write_text('{"run_id": "r-2", "name": "half", "pid": ')  # as a reader may find a file being written
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    gone = runs.directory() / "r-3.json"
    gone.write_text(json.dumps({"run_id": "r-3", "name": "gone", "pid": int(dead.stdout)}))
    assert [e["name"] for e in runs.alive()] == ["live"]
    assert half.exists() and not gone.exists()
    assert runs.find("live")[0]["pid"] == os.getpid()
