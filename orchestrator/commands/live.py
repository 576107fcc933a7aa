"""``orchestrator ps``, ``stop`` and ``swap``: requests to the runs alive on this machine."""

from __future__ import annotations

import json

from orchestrator.commands.exits import USAGE_ERROR, fail


def _query(entry: dict, request: dict, timeout: float = 30.0) -> dict:
    from components import bus

    session = bus.open_session(connect=[entry["endpoint"]], secret=entry["secret"], settings=entry.get("settings"))
    try:
        for reply in session.get(bus.control_key(entry["run_id"]), payload=json.dumps(request), timeout=timeout):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
        return {"ok": False, "error": f"run {entry['run_id']} did not answer within {timeout:g} s"}
    finally:
        session.close()


def _one_run(name: str):
    from orchestrator.run import runs

    found = runs.find(name)
    if not found:
        names = ", ".join(r["name"] for r in runs.alive()) or "none"
        return None, f"no run named {name!r} is alive (alive: {names}; see `orchestrator ps`)"
    if len(found) > 1:
        return None, f"several runs are named {name!r}: give a run id ({', '.join(r['run_id'] for r in found)})"
    return found[0], None


def cmd_ps(args) -> int:
    from orchestrator.run import runs

    entries = runs.alive()
    if not entries:
        print("no runs alive")
        return 0
    print(f"{'RUN ID':<32}{'PID':>8}  {'TIME':>12}  {'ENDPOINT':<24}COMPONENTS")
    for entry in entries:
        status = _query(entry, {"op": "status"}, timeout=3.0)
        if status.get("ok"):
            when = f"{status['time']:.3f} s"
            comps = ", ".join(f"{n}:{c['type']}" for n, c in status["components"].items())
        else:
            when, comps = "?", status.get("error", "")
        print(f"{entry['run_id']:<32}{entry['pid']:>8}  {when:>12}  {entry['endpoint']:<24}{comps}")
    return 0


def cmd_stop(args) -> int:
    entry, error = _one_run(args.run)
    if error:
        return fail(error)
    answer = _query(entry, {"op": "stop"})
    if not answer.get("ok"):
        return fail(answer.get("error", "stop refused"), 1)
    print(f"stopping {entry['run_id']}")
    return 0


def cmd_swap(args) -> int:
    entry, error = _one_run(args.run)
    if error:
        return fail(error)
    answer = _query(
        entry, {"op": "swap", "component": args.component, "type": args.type, "set": args.set}, timeout=120.0
    )
    if not answer.get("ok"):  # bad parameters or type: 2; a replacement that failed to start: 1
        return fail(answer.get("error", "swap refused"), USAGE_ERROR if answer.get("usage", True) else 1)
    print(f"swapped {args.component} at step {answer['step']} (generation {answer['generation']})")
    return 0
