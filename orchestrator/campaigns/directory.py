"""The campaign directory ``DIR`` of ``orchestrator sweep``: its files, its cases' results as they
come, the progress line, and what ``--resume`` and ``--only`` find there:

| path | what |
|---|---|
| ``campaign.yaml`` | the campaign as given |
| ``campaign.json`` | its fingerprint (``--resume`` refuses another campaign), keys, metrics, case count |
| ``cases/NNNN.yaml`` | case NNNN's config: runs by itself with ``orchestrator run`` |
| ``cases/NNNN/`` | its recording, as ``keep`` says |
| ``cases/NNNN.json`` | its result, once it completed or failed (``--resume`` skips it) |
| ``cases.parquet`` | one row per case: case, status, error, parameters, metrics, wall_time, attempts, host, recording |
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import signal
import tarfile
import time
from pathlib import Path

from orchestrator.campaigns.campaign import Campaign, si_value

FIXED_COLUMNS = ("case", "status", "outcome", "error")
TAIL_COLUMNS = ("wall_time", "attempts", "host", "recording")


class CampaignError(Exception):
    """The campaign cannot run (DIR in use by another campaign, the cluster unreachable...)."""


# ---------------------------------------------------------------- the campaign directory


class CampaignDir:
    def __init__(self, out: Path, campaign: Campaign):
        self.out, self.campaign = out, campaign
        self.cases = out / "cases"

    def config_file(self, index: int) -> Path:
        return self.cases / f"{index:04d}.yaml"

    def record_dir(self, index: int) -> Path:
        return self.cases / f"{index:04d}"

    def result_file(self, index: int) -> Path:
        return self.cases / f"{index:04d}.json"

    def prepare(self, resume: bool, only: list[int] | None) -> None:
        """Claim DIR: new or empty; the same campaign with --resume or --only; else CampaignError."""
        meta = self.out / "campaign.json"
        fingerprint = self.campaign.fingerprint()
        if self.out.exists() and not self.out.is_dir():
            raise CampaignError(f"--out {self.out}: exists and is not a directory")
        if self.out.is_dir() and any(self.out.iterdir()):
            if not meta.exists():
                raise CampaignError(
                    f"--out {self.out}: the directory is in use and holds no campaign; give a new or empty directory"
                )
            stored = json.loads(meta.read_text())
            if stored.get("fingerprint") != fingerprint:
                raise CampaignError(
                    f"--out {self.out}: holds another campaign (or this one changed since); give a new directory"
                )
            if not resume and only is None:
                raise CampaignError(
                    f"--out {self.out}: holds this campaign already: --resume finishes it, --only N reruns a case"
                )
        elif resume:
            raise CampaignError(f"--resume: {self.out} holds no campaign to resume")
        self.cases.mkdir(parents=True, exist_ok=True)
        if self.campaign.path.exists():
            shutil.copyfile(self.campaign.path, self.out / "campaign.yaml")
        c = self.campaign
        meta.write_text(
            json.dumps(
                {
                    "fingerprint": fingerprint,
                    "campaign": str(c.path.resolve()),
                    "cases": c.count,
                    "grid": list(c.grid),
                    "dispersed": [d.key for d in c.dispersions],
                    "metrics": {
                        m.name: {
                            "signal": m.signal,
                            "event": m.event,
                            "field": m.field,
                            "reduce": m.reduce,
                            "unit": m.unit,
                        }
                        for m in c.metrics
                    },
                    "units": {d.key: d.unit for d in c.dispersions if d.unit},
                    "grid_values": c.grid,
                    "outcomes": c.outcomes,
                    "keep": c.keep,
                },
                indent=2,
            )
        )

    def done(self, index: int) -> dict | None:
        path = self.result_file(index)
        try:
            return json.loads(path.read_text()) if path.exists() else None
        except ValueError:
            return None

    def store(self, result: dict) -> None:
        """A finished case's result, written atomically (a resume trusts it)."""
        files = result.pop("files", None)
        index = result["case"]
        if files is not None:
            target = self.record_dir(index)
            shutil.rmtree(target, ignore_errors=True)
            target.mkdir(parents=True)
            with tarfile.open(fileobj=io.BytesIO(files), mode="r:gz") as tar:
                tar.extractall(target, filter="data")
        record = f"cases/{index:04d}" if result.get("kept") and self.record_dir(index).exists() else ""
        result["recording"] = record
        if result["status"] == "interrupted":
            return
        path = self.result_file(index)
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(result, default=float))
        os.replace(tmp, path)

    def table(self, indexes: list[int], pending_status: str = "interrupted"):
        """cases.parquet's rows for these cases: results on disk; the others ``pending_status``."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        c = self.campaign
        rows = []
        for index in indexes:
            params = c.case(index).params
            result = self.done(index) or {
                "case": index,
                "status": pending_status,
                "error": "",
                "metrics": {},
                "wall_time": math.nan,
                "attempts": 0,
                "host": "",
                "recording": "",
            }
            row = {
                "case": index,
                "status": result["status"],
                "outcome": c.outcome(result["status"], result.get("events", []), result.get("outcome", "")),
                "error": result.get("error", ""),
            }
            row.update({k: params[k] for k in c.keys})
            row.update({m.name: _metric_value(result["metrics"].get(m.name, math.nan)) for m in c.metrics})
            row.update(
                {
                    "wall_time": float(result["wall_time"]),
                    "attempts": int(result.get("attempts", 1)),
                    "host": result.get("host", ""),
                    "recording": result.get("recording", ""),
                }
            )
            rows.append(row)
        columns = {}
        for name in [*FIXED_COLUMNS, *c.keys, *(m.name for m in c.metrics), *TAIL_COLUMNS]:
            values = [r[name] for r in rows]
            if name in c.keys:
                converted = [si_value(v) for v in values]
                values = (
                    converted
                    if all(isinstance(v, float) for v in converted)
                    else [v if isinstance(v, str) else json.dumps(v) for v in values]
                )
            elif any(isinstance(v, str) for v in values) and name not in FIXED_COLUMNS + TAIL_COLUMNS:
                values = [v if isinstance(v, str) else "" for v in values]  # a text metric: '' for none
            columns[name] = values
        schema_types = {"case": pa.int64(), "attempts": pa.int64(), "wall_time": pa.float64()}
        arrays = {n: pa.array(v, type=schema_types.get(n)) for n, v in columns.items()}
        table = pa.table(arrays)
        tmp = self.out / ".cases.parquet.tmp"
        pq.write_table(table, tmp)
        os.replace(tmp, self.out / "cases.parquet")
        return rows


def _metric_value(value):
    """A metric as cases.parquet holds it: a number (NaN for none) or a text (an event's reason)."""
    return value if isinstance(value, str) else float(value)


class Progress:
    """The progress line on a terminal: cases done, completed and failed, running, rate, time left."""

    def __init__(self, total: int, out, tty: bool, running: str = "running"):
        self.total, self.out, self.tty, self.label = total, out, tty, running
        self.counts = {"completed": 0, "failed": 0, "interrupted": 0}
        self.start = time.perf_counter()
        self.last = 0.0
        self.running = 0

    def add(self, status: str) -> None:
        self.counts[status] = self.counts.get(status, 0) + 1
        self.show()

    def show(self, force: bool = False) -> None:
        if not self.tty:
            return
        now = time.perf_counter()
        if not force and now - self.last < 0.3:
            return
        self.last = now
        done = self.counts["completed"] + self.counts["failed"]
        elapsed = now - self.start
        rate = done / elapsed * 60 if elapsed > 0 else 0.0
        eta = (self.total - done) / (done / elapsed) if done else math.nan
        print(
            f"\r  {done}/{self.total} cases ({self.counts['completed']} completed, {self.counts['failed']} failed)"
            f", {self.running} {self.label}, {rate:.1f} cases/min"
            + (f", about {eta:.0f} s left" if done else "")
            + "   ",
            end="",
            file=self.out,
            flush=True,
        )

    def end(self) -> None:
        if self.tty:
            print(file=self.out, flush=True)


def ignore_interrupts(action) -> None:
    """Run ``action`` with a second Ctrl-C ignored: the clean-up has bounded waits of its own."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        action()
    finally:
        signal.signal(signal.SIGINT, previous)
