"""Campaigns for real: each case is the plain run of its config, locally and on Dask, bit for bit;
a failing case, --only, --resume after Ctrl-C, a worker killed mid-campaign."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml

from tests.conftest import ROOT, wait_until

pytestmark = pytest.mark.integration

CONFIG = {
    "run": {"name": "sweepcase", "epoch": "2022-09-18T12:00:00Z", "duration": "200 ms", "step": "10 ms"},
    "components": {
        "push": {"type": "test.constant", "parameters": {"value": 1.0}},
        "total": {"type": "test.integrator", "parameters": {"gain": 2.0}},
        "bad": {"type": "test.faulty", "parameters": {"fault": "raise", "at_step": 100000}},
    },
    "connections": {"total.u": "push.y"},
}
METRICS = {
    "final": {"signal": "total.x", "reduce": "final"},
    "peak": {"signal": "total.x", "reduce": "max_abs"},
    "cross": {"signal": "total.x", "reduce": "first_crossing", "threshold": 0.1},
}


def campaign_file(tmp_path, name="campaign.yaml", config=CONFIG, **extra):
    path = tmp_path / name
    body = {
        "config": config,
        "samples": 3,
        "seed": 5,
        "disperse": {
            "components.push.parameters.value": {"normal": [1.0, 0.2]},
            "components.total.parameters.gain": {"uniform": [1, 3]},
        },
        "metrics": METRICS,
        "keep": "all",
        **extra,
    }
    path.write_text(yaml.safe_dump(body, sort_keys=False))
    return path


def sweep(*args, timeout=300):
    return subprocess.run(
        [sys.executable, "-m", "orchestrator.cli", "sweep", *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def cases(out):
    return pq.read_table(out / "cases.parquet").to_pandas()


def same_results(a, b):
    """cases.parquet equal but for wall times, hosts and attempts."""
    drop = ["wall_time", "host", "attempts"]
    left, right = a.drop(columns=drop), b.drop(columns=drop)
    assert list(left.columns) == list(right.columns)
    assert left.equals(right), (left, right)


def test_each_case_is_the_plain_run_of_its_config(tmp_path):
    out = tmp_path / "out"
    result = sweep(campaign_file(tmp_path), "--out", out, "--jobs", 2)
    assert result.returncode == 0, result.stderr
    assert "3 completed" in result.stderr and "final" in result.stderr
    table = cases(out)
    assert list(table["case"]) == [0, 1, 2] and set(table["status"]) == {"completed"}
    assert list(table.columns[:6]) == [
        "case",
        "status",
        "outcome",
        "error",
        "components.push.parameters.value",
        "components.total.parameters.gain",
    ]
    for index in range(3):
        plain = tmp_path / f"plain{index}"
        run = subprocess.run(
            [sys.executable, "-m", "orchestrator.cli", "run", out / "cases" / f"{index:04d}.yaml", "--record", plain],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert run.returncode == 0, run.stderr
        mine = pq.read_table(out / "cases" / f"{index:04d}" / "signals.parquet")
        theirs = pq.read_table(plain / "signals.parquet")
        assert mine.equals(theirs)
        x = theirs.column("total.x").to_numpy()
        row = table.iloc[index]
        assert row["final"] == x[-1] and row["peak"] == abs(x).max()
        assert row["recording"] == f"cases/{index:04d}"
    # --only reproduces one case by itself, in a directory of its own
    alone = tmp_path / "alone"
    result = sweep(campaign_file(tmp_path), "--out", alone, "--only", 2)
    assert result.returncode == 0, result.stderr
    one = cases(alone)
    assert list(one["case"]) == [2]
    same_results(one.reset_index(drop=True), table.iloc[[2]].reset_index(drop=True))
    # the same directory again without --resume is refused; plot draws the campaign
    again = sweep(campaign_file(tmp_path), "--out", out)
    assert again.returncode == 2 and "--resume" in again.stderr
    plot = subprocess.run(
        [sys.executable, "-m", "orchestrator.cli", "plot", out], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert plot.returncode == 0, plot.stderr
    assert (out / "plots" / "metrics_histograms.png").exists() and (out / "plots" / "final_vs_parameters.png").exists()


def test_a_failing_case_is_recorded_and_the_campaign_goes_on(tmp_path):
    out = tmp_path / "out"
    path = campaign_file(
        tmp_path, grid={"components.bad.parameters.at_step": [100000, 4]}, samples=1, keep="failed", disperse={}
    )
    result = sweep(path, "--out", out)
    assert result.returncode == 0, result.stderr
    table = cases(out)
    assert list(table["status"]) == ["completed", "failed"]
    assert "deliberate failure at step 4" in table["error"][1]
    assert table["recording"][0] == "" and table["recording"][1] == "cases/0001"  # keep: failed
    assert not (out / "cases" / "0000").exists() and (out / "cases" / "0001" / "signals.parquet").exists()
    # a failed case's metrics come from its recording too (its rows up to the failure)
    kept = pq.read_table(out / "cases" / "0001" / "signals.parquet")
    column = "total.x"  # the metric "final" of campaign_file
    assert table["final"][1] == kept.column(column).to_numpy()[-1] and not table["final"].isna()[0]
    assert list(table["outcome"]) == ["completed", "failed"]
    assert "case 1 failed: " in result.stderr


def test_bad_campaign_files_stop_before_anything_runs(tmp_path):
    out = tmp_path / "out"
    path = campaign_file(tmp_path, metrics={"m": {"signal": "total.y", "reduce": "final"}}, sampels=3)
    result = sweep(path, "--out", out)
    assert result.returncode == 2
    assert "sampels: unknown key" in result.stderr and "metrics.m.signal: no signal 'total.y'" in result.stderr
    assert not out.exists()


def started_cases(out) -> list[Path]:
    """The cases whose run has begun (its recording has its start event) and not yet finished (no result file)."""
    return [
        record
        for record in (out / "cases").glob("[0-9][0-9][0-9][0-9]")
        if (record / "events.jsonl").exists() and not record.with_suffix(".json").exists()
    ]


def started_runs_under(pid: int) -> list[Path]:
    """The recordings of the `orchestrator run` processes below ``pid`` whose run has begun (a start event)."""
    import psutil

    records = []
    for child in psutil.Process(pid).children(recursive=True):
        try:
            args = child.cmdline()
        except psutil.Error:  # ended meanwhile
            continue
        if "--record" in args and (Path(args[args.index("--record") + 1]) / "events.jsonl").exists():
            records.append(Path(args[args.index("--record") + 1]))
    return records


def test_resume_after_ctrl_c_runs_only_what_is_left(tmp_path):
    """The sweep is started with SIGINT ignored, as `&` from a script leaves it (issue 34): a
    Ctrl-C (SIGINT) still stops it cleanly, exit 130 with the --resume hint, what finished kept."""
    out = tmp_path / "out"
    slow = {**CONFIG, "run": {**CONFIG["run"], "realtime": 1.0, "duration": "1 s"}}
    path = tmp_path / "slow.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "config": slow,
                "samples": 6,
                "seed": 3,
                "metrics": METRICS,
                "keep": "none",
                "disperse": {"components.push.parameters.value": {"uniform": [0, 1]}},
            }
        )
    )
    process = subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "sweep", str(path), "--out", str(out), "--jobs", "1"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
    )
    try:
        wait_until(lambda: len(list((out / "cases").glob("*.json"))) >= 2, "two cases finished", run=process)
        wait_until(lambda: started_cases(out), "the third case's run started", run=process)
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, err
    assert "--resume" in err
    first = cases(out)
    finished = set(first["case"][first["status"] == "completed"])
    assert 2 <= len(finished) < 6 and set(first["status"]) == {"completed", "interrupted"}
    stamps = {i: (out / "cases" / f"{i:04d}.json").stat().st_mtime_ns for i in finished}
    leftovers = subprocess.run(["ps", "-eo", "args="], capture_output=True, text=True).stdout
    assert str(out / "cases") not in leftovers  # no case's run left behind
    result = sweep(path, "--out", out, "--resume")
    assert result.returncode == 0, result.stderr
    assert f"{len(finished)} of 6 cases already finished" in result.stderr
    assert set(cases(out)["status"]) == {"completed"}
    assert all((out / "cases" / f"{i:04d}.json").stat().st_mtime_ns == s for i, s in stamps.items())
    fresh = tmp_path / "fresh"
    assert sweep(path, "--out", fresh, "--jobs", 2).returncode == 0
    same_results(cases(out), cases(fresh))


@pytest.fixture
def dask_cluster():
    import distributed

    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, scheduler_port=0
    )
    client = distributed.Client(cluster)
    try:
        yield cluster, client
    finally:
        client.close()
        cluster.close()


def test_dask_gives_the_local_results_and_survives_a_dead_worker(tmp_path, dask_cluster):
    cluster, client = dask_cluster
    paced = {**CONFIG, "run": {**CONFIG["run"], "realtime": 1.0, "duration": "1 s"}}  # a case lasts > 1 s
    path = campaign_file(tmp_path, samples=6, config=paced)
    local, remote = tmp_path / "local", tmp_path / "remote"
    assert sweep(path, "--out", local).returncode == 0
    # a worker killed while it runs a case: the case runs again elsewhere, none is lost
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "orchestrator.cli",
            "sweep",
            str(path),
            "--out",
            str(remote),
            "--cluster",
            cluster.scheduler_address,
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    killed = None
    try:
        busy = wait_until(
            lambda: [w for w, keys in client.processing().items() if any("zenorbit-case" in str(k) for k in keys)],
            "a worker given a case",
            60,
            process,
        )
        pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
        wait_until(lambda: started_runs_under(pid), "the worker's case run started", 60, process)  # mid-case
        os.kill(pid, signal.SIGKILL)
        killed = busy[0]
        _, err = process.communicate(timeout=240)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, err
    assert killed is not None
    table = cases(remote)
    assert set(table["status"]) == {"completed"}
    same_results(table, cases(local))
    assert (table["attempts"] > 1).any(), table[["case", "attempts", "host"]]
    for index in range(6):
        mine = pq.read_table(remote / "cases" / f"{index:04d}" / "signals.parquet")
        assert mine.equals(pq.read_table(local / "cases" / f"{index:04d}" / "signals.parquet"))
    # the same again, no worker killed: the same cases.parquet
    again = tmp_path / "again"
    assert sweep(path, "--out", again, "--cluster", cluster.scheduler_address).returncode == 0
    same_results(cases(again), cases(local))
    assert json.loads((again / "campaign.json").read_text())["cases"] == 6
