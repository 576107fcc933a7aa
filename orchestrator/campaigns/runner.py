"""Running a campaign (``orchestrator sweep``): its cases in parallel on this machine (the local
pool), or on a dask.distributed cluster (campaigns/distributed.py), into the campaign directory
(campaigns/directory.py, which lists its files).

Every case is one ``orchestrator run`` process of its own (own run id, own bus on a free port,
own component processes), started with the case's config file, so a case's numbers are those of
a plain ``orchestrator run`` of that file, wherever it runs.
"""

from __future__ import annotations

import concurrent.futures as futures
import os
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

from orchestrator.campaigns.campaign import Campaign, case_yaml
from orchestrator.campaigns.case import STOP_GRACE_S, execute_case
from orchestrator.campaigns.directory import CampaignDir, Progress, ignore_interrupts

# ---------------------------------------------------------------- the pools


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def _slots(jobs: int, dedicated: bool) -> list:
    """CPU sets for the parallel cases: when the config asks for a ``dedicated_cpu``, disjoint ones
    (so that one case's dedicated CPU is not another's: with two or more CPUs a case pins its
    component within its own set, with one it runs unpinned there); else none (the OS shares them)."""
    cpus = sorted(os.sched_getaffinity(0))
    if jobs < 2 or not dedicated or len(cpus) < jobs:
        return [None] * jobs
    per = len(cpus) // jobs
    return [frozenset(cpus[i * per : (i + 1) * per]) for i in range(jobs)]


def _dedicated(campaign: Campaign, todo: list[int]) -> int:
    """How many components of a case ask for a CPU of their own (dedicated_cpu)."""
    if not todo:
        return 0
    components = campaign.case(todo[0]).raw.get("components") or {}
    return sum(1 for c in components.values() if isinstance(c, dict) and c.get("dedicated_cpu") in (True, "process"))


def default_jobs(campaign: Campaign, todo: list[int]) -> int:
    """Cases at once by default: one per CPU; for a config with dedicated_cpu components, as many
    as can each have those CPUs plus one to share (the demo on 2 CPUs: one at a time)."""
    cpus = len(os.sched_getaffinity(0))
    return max(1, cpus // (1 + _dedicated(campaign, todo)) if _dedicated(campaign, todo) else cpus)


def run_local(directory: CampaignDir, todo: list[int], jobs: int, progress: Progress) -> bool:
    """The cases on this machine, ``jobs`` at a time; False when interrupted (Ctrl-C)."""
    campaign = directory.campaign
    stop = threading.Event()
    slots = _slots(jobs, _dedicated(campaign, todo) > 0)
    free = list(range(jobs))
    lock = threading.Lock()

    def one(index: int) -> dict:
        with lock:
            slot = free.pop()
        try:
            if stop.is_set():
                return {"case": index, "status": "interrupted"}
            return execute_case(
                index,
                directory.config_file(index),
                directory.record_dir(index),
                campaign.metrics,
                campaign.keep,
                stop=stop,
                cpus=slots[slot],
            )
        finally:
            with lock:
                free.append(slot)

    pool = futures.ThreadPoolExecutor(max_workers=jobs, thread_name_prefix="case")
    pending = {pool.submit(one, i): i for i in todo}
    completed = True
    try:
        while pending:
            done, _ = futures.wait(pending, timeout=0.3, return_when=futures.FIRST_COMPLETED)
            progress.running = min(jobs, len(pending) - len(done))
            for future in done:
                pending.pop(future)
                result = future.result()
                if result["status"] != "interrupted":
                    directory.store(result)
                    progress.add(result["status"])
            progress.show()
    except KeyboardInterrupt:
        completed = False
        stop.set()
        for future in pending:
            future.cancel()
        ignore_interrupts(lambda: _finish(pending, directory))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return completed


def _finish(pending: dict, directory: CampaignDir) -> None:
    """After a stop: store what finished anyway (a case that completed as the stop came)."""
    for future in pending:
        if future.cancelled():
            continue
        try:
            result = future.result(timeout=STOP_GRACE_S + 10)
        except Exception:
            continue
        if result["status"] != "interrupted":
            directory.store(result)


# ---------------------------------------------------------------- the whole sweep


def summary(rows: list[dict], campaign: Campaign, wall: float, out, ran: int | None = None) -> None:
    """What the campaign gave: counts, each metric's spread over the completed cases, the failures."""
    statuses: dict[str, int] = {}
    for row in rows:
        statuses[row["status"]] = statuses.get(row["status"], 0) + 1
    counts = ", ".join(f"{n} {s}" for s, n in statuses.items())
    finished = statuses.get("completed", 0) + statuses.get("failed", 0) if ran is None else ran
    print(
        f"campaign: {len(rows)} cases: {counts}; {wall:.1f} s wall"
        + (f", {finished / wall * 60:.1f} cases/min" if wall > 0 and finished else ""),
        file=out,
    )
    if any(row["outcome"] != row["status"] for row in rows):  # declared or named outcomes: say them
        outcomes: dict[str, int] = {}
        for row in rows:
            outcomes[row["outcome"]] = outcomes.get(row["outcome"], 0) + 1
        print(
            "  outcomes: " + ", ".join(f"{n} {o} ({100.0 * n / len(rows):.0f}%)" for o, n in outcomes.items()), file=out
        )
    ok = [r for r in rows if r["status"] == "completed"]
    numeric = [m for m in campaign.metrics if not any(isinstance(r[m.name], str) for r in ok)]
    for m in campaign.metrics:
        texts = sorted({r[m.name] for r in ok if isinstance(r[m.name], str) and r[m.name]})
        if texts:  # a text metric (an event's reason): how often each
            tally = {t: sum(1 for r in ok if r[m.name] == t) for t in texts}
            print(
                f"  {m.name}: "
                + "; ".join(f"{n} x {t[:160]}" for t, n in sorted(tally.items(), key=lambda x: -x[1])[:5]),
                file=out,
            )
    if numeric and ok:
        print(f"  {'metric':<24}{'mean':>13}{'std':>13}{'min':>13}{'max':>13}", file=out)
        for m in numeric:
            values = np.array([r[m.name] for r in ok], dtype=float)
            finite = values[np.isfinite(values)]
            if not len(finite):
                print(
                    f"  {m.name:<24}" + (f"no case had a {m.event} event" if m.event else "(no finite value)"), file=out
                )
                continue
            print(
                f"  {m.name:<24}{np.mean(finite):>13.6g}{np.std(finite):>13.6g}{np.min(finite):>13.6g}"
                f"{np.max(finite):>13.6g}"
                + (f"   ({len(values) - len(finite)} NaN)" if len(finite) < len(values) else ""),
                file=out,
            )
    failed = [r for r in rows if r["status"] == "failed"]
    for r in failed[:10]:
        print(f"  case {r['case']} failed: {r['error']}", file=out)
    if len(failed) > 10:
        print(f"  ... and {len(failed) - 10} more failed cases (cases.parquet)", file=out)
    retried = [r for r in rows if r.get("attempts", 1) > 1]
    if retried:
        listed = ", ".join(f"case {r['case']} ({r['attempts']} attempts)" for r in retried[:10])
        print(f"  retried: {listed}", file=out)


def _todo(directory: CampaignDir, scope: list[int], only: bool, stream) -> list[int]:
    """The cases of ``scope`` to run: all of them for --only (their earlier results removed), else
    those not finished yet; each case's config written beside its recording first."""
    campaign = directory.campaign
    for index in scope:  # each case's config beside its recording, written before any runs
        path = directory.config_file(index)
        text = case_yaml(campaign.case(index), campaign)
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
    if only:
        todo = scope
        for index in todo:
            directory.result_file(index).unlink(missing_ok=True)
    else:
        todo = [i for i in scope if directory.done(i) is None]
    skipped = len(scope) - len(todo)
    if skipped:
        print(f"resuming: {skipped} of {len(scope)} cases already finished, {len(todo)} to run", file=stream)
    return todo


def sweep(
    campaign: Campaign,
    out: Path,
    *,
    jobs: int | None = None,
    cluster: str | None = None,
    resume: bool = False,
    only: list[int] | None = None,
    retries: int = 2,
    stream=sys.stderr,
) -> int:
    """Run a validated campaign into ``out``: 0 when every case in scope ran (completed or
    failed), 130 when interrupted."""
    directory = CampaignDir(out, campaign)
    directory.prepare(resume, only)
    scope = list(only) if only is not None else list(range(campaign.count))
    todo = _todo(directory, scope, only is not None, stream)
    jobs = jobs or default_jobs(campaign, todo)
    where = f"on {cluster}" if cluster else f"{jobs} at a time"
    print(f"campaign {campaign.path}: {len(todo)} cases {where}, into {out}", file=stream, flush=True)
    progress = Progress(len(todo), stream, stream.isatty(), "queued or running" if cluster else "running")
    start = time.perf_counter()
    completed = True
    main = threading.current_thread() is threading.main_thread()
    previous = (
        signal.signal(signal.SIGTERM, _interrupt) if main else None
    )  # a SIGTERM (a batch system's stop) is a Ctrl-C
    try:
        if todo:
            if cluster:
                from orchestrator.campaigns.distributed import run_dask

                completed = run_dask(directory, todo, cluster, retries, progress)
            else:
                completed = run_local(directory, todo, jobs, progress)
    finally:
        if main:
            signal.signal(signal.SIGTERM, previous)
        progress.end()
        rows_scope = (
            scope
            if only is None
            else sorted(set(scope) | {i for i in range(campaign.count) if directory.result_file(i).exists()})
        )
        rows = directory.table(rows_scope)
    ran = sum(1 for i in todo if directory.done(i) is not None)
    summary(rows, campaign, time.perf_counter() - start, stream, ran)
    print(
        f"results in {out / 'cases.parquet'}"
        + ("" if completed else f"; interrupted: orchestrator sweep {campaign.path} --out {out} --resume finishes it"),
        file=stream,
    )
    return 0 if completed else 130
