"""``orchestrator ps``, ``stop`` and ``swap``: requests to the runs alive on this machine."""

from __future__ import annotations

from typing import TypeVar

from components import queries
from components.message_codec import Malformed, Message
from orchestrator.commands.exits import USAGE_ERROR, fail

M = TypeVar("M", bound=Message)


def _query(entry: dict, request: Message, expected: type[M], timeout: float = 30.0) -> M | queries.Refused:
    """The run's answer to ``request``: one of type ``expected``, or Refused saying why not."""
    from components import bus

    session = bus.open_session(connect=[entry["endpoint"]], secret=entry["secret"], settings=entry.get("settings"))
    try:
        for reply in session.get(bus.control_key(entry["run_id"]), payload=request.encode(), timeout=timeout):
            if reply.ok is not None:
                try:
                    answer = queries.decode_control_answer(reply.ok.payload.to_bytes())
                except Malformed as e:
                    return queries.Refused(f"run {entry['run_id']} answered something malformed: {e}", usage=False)
                if isinstance(answer, (expected, queries.Refused)):
                    return answer
                return queries.Refused(
                    f"run {entry['run_id']} answered {type(answer).__name__}, expected {expected.__name__}", usage=False
                )
        return queries.Refused(f"run {entry['run_id']} did not answer within {timeout:g} s", usage=True)
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
        status = _query(entry, queries.Status(), queries.RunStatus, timeout=3.0)
        if isinstance(status, queries.RunStatus):
            when = f"{status.time:.3f} s"
            comps = ", ".join(f"{n}:{c.type}" for n, c in status.components.items())
        else:
            when, comps = "?", status.error
        print(f"{entry['run_id']:<32}{entry['pid']:>8}  {when:>12}  {entry['endpoint']:<24}{comps}")
    return 0


def cmd_stop(args) -> int:
    entry, error = _one_run(args.run)
    if error:
        return fail(error)
    answer = _query(entry, queries.Stop(), queries.Stopping)
    if type(answer) is queries.Refused:
        return fail(answer.error, 1)
    print(f"stopping {entry['run_id']}")
    return 0


def cmd_swap(args) -> int:
    entry, error = _one_run(args.run)
    if error:
        return fail(error)
    answer = _query(entry, queries.Swap(args.component, args.type, args.set), queries.Swapped, timeout=120.0)
    if isinstance(answer, queries.Refused):  # bad parameters or type: 2; a replacement that failed to start: 1
        return fail(answer.error, USAGE_ERROR if answer.usage else 1)
    print(f"swapped {args.component} at step {answer.step} (generation {answer.generation})")
    return 0
