"""The cases of a campaign on a dask.distributed cluster (``orchestrator sweep --cluster``)."""

from __future__ import annotations

import io
import math
import shutil
import tarfile
import tempfile
import time
import uuid
from pathlib import Path

from orchestrator.campaigns.case import STOP_GRACE_S, execute_case
from orchestrator.campaigns.directory import CampaignDir, CampaignError, Progress, ignore_interrupts


def remote_case(payload: dict) -> dict:
    """A case on a Dask worker: its config written to a temporary directory, run there, the
    recording shipped back (a tar.gz in ``files``) when ``keep`` wants it."""
    stop_event = None
    try:
        from distributed import Event, get_worker

        worker = get_worker().address
        stop_event = Event(payload["stop_event"])
    except Exception:  # run outside a worker (tests): no stop event
        worker = "local"
    work = Path(tempfile.mkdtemp(prefix=f"zenorbit-case{payload['case']}-"))
    last_check = [0.0, False]

    def stopped() -> bool:
        if stop_event is None:
            return False
        now = time.monotonic()
        if now - last_check[0] > 1.0:
            last_check[0] = now
            try:
                last_check[1] = bool(stop_event.is_set())
            except Exception:
                pass
        return bool(last_check[1])

    try:
        config_file = work / f"{payload['case']:04d}.yaml"
        config_file.write_text(payload["config"])
        record = work / f"{payload['case']:04d}"
        result = execute_case(
            payload["case"], config_file, record, payload["metrics"], payload["keep"], stopped=stopped
        )
        if result["kept"] and record.exists():
            buffer = io.BytesIO()
            with tarfile.open(fileobj=buffer, mode="w:gz") as tar:
                tar.add(record, arcname=".")
            result["files"] = buffer.getvalue()
        result["host"] = f"{result['host']} ({worker})"
        return result
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run_dask(directory: CampaignDir, todo: list[int], address: str, retries: int, progress: Progress) -> bool:
    """The cases on a dask.distributed scheduler at ``address``; False when interrupted."""
    from distributed import Client, Event, as_completed

    campaign = directory.campaign
    try:
        client = Client(address, timeout="15s")
    except (OSError, TimeoutError) as e:
        raise CampaignError(f"--cluster {address}: cannot reach the scheduler ({e})") from None
    token = uuid.uuid4().hex[:8]
    stop_name = f"zenorbit-stop-{token}"
    stop = Event(stop_name, client=client)
    try:
        submitted, keys = _submit(client, directory, todo, retries, stop_name, token)
        pending = set(submitted)
        try:
            for future in as_completed(submitted):
                pending.discard(future)
                index = keys[future.key]
                try:
                    result = future.result()
                except Exception as e:  # the task raised on every try, or its workers kept dying
                    result = _failed(index, f"dask: {type(e).__name__}: {e}", campaign, retries)
                result["attempts"] = max(result.get("attempts", 1), _attempts(client, future.key))
                if result["status"] != "interrupted":
                    directory.store(result)
                    progress.add(result["status"])
                progress.running = sum(1 for f in pending if f.status == "pending")
                progress.show()
        except KeyboardInterrupt:
            ignore_interrupts(lambda: _wind_down(client, directory, pending, keys, stop))
            return False
        return True
    finally:
        client.close()


def _submit(client, directory: CampaignDir, todo: list[int], retries: int, stop_name: str, token: str):
    """Each case submitted as a task: the futures, and the case of each future's key."""
    campaign = directory.campaign
    keys = {}
    submitted = []
    for index in todo:
        payload = {
            "case": index,
            "config": directory.config_file(index).read_text(),
            "metrics": campaign.metrics,
            "keep": campaign.keep,
            "stop_event": stop_name,
        }
        key = f"zenorbit-case-{campaign.fingerprint()}-{index:04d}-{token}"
        future = client.submit(remote_case, payload, key=key, retries=retries, pure=False)
        keys[future.key] = index
        submitted.append(future)
    return submitted, keys


def _failed(index: int, error: str, campaign, retries: int) -> dict:
    """The result of a case whose task raised on every try."""
    return {
        "case": index,
        "status": "failed",
        "error": error,
        "metrics": {m.name: math.nan for m in campaign.metrics},
        "wall_time": math.nan,
        "host": "",
        "kept": False,
        "attempts": retries + 1,
    }


def _wind_down(client, directory: CampaignDir, pending: set, keys: dict, stop) -> None:
    """After Ctrl-C: the running cases stopped cleanly (their results kept), the queued ones cancelled."""
    stop.set()
    queued = [f for f in pending if keys[f.key] not in _processing(client)]
    client.cancel(queued)
    deadline = time.monotonic() + STOP_GRACE_S + 10
    for future in pending:
        if future in queued:
            continue
        try:
            result = future.result(timeout=max(deadline - time.monotonic(), 0.1))
        except Exception:
            continue
        if result["status"] != "interrupted":
            directory.store(result)
    client.cancel(list(pending))


def _processing(client) -> set[int]:
    try:
        keys = {k for ks in client.processing().values() for k in ks}
    except Exception:
        return set()
    return {int(str(k).rsplit("-", 2)[-2]) for k in keys if str(k).startswith("zenorbit-case-")}


def _attempts(client, key: str) -> int:
    """How many times the scheduler started the task (a worker that died while running it: one more)."""
    try:
        story = client.story(key)
    except Exception:
        return 1
    starts = 0
    for entry in story:  # the scheduler's transitions: (origin, key, start, finish, ...)
        fields = entry if isinstance(entry, (tuple, list)) else ()
        if len(fields) >= 4 and fields[0] == "scheduler" and fields[1] == key and fields[3] == "processing":
            starts += 1
    return max(starts, 1)
