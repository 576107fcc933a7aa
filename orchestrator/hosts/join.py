"""Components joining from other hosts, the orchestrator's side: the join files and the desk that
answers joins (docs/design.md §7).

For each ``launch: external`` component the orchestrator writes a join file (mode 0600): the
endpoints to reach the run, the run id, the secret, the component's name and generation, the bus
settings (with TLS, the component's certificate and key and the run's CA). ``orchestrator join
FILE`` (:mod:`orchestrator.hosts.joiner`) opens a session with them and asks the desk, on
``join/<component>``, which generation to serve: the desk grants a generation it waits for, and
refuses a second join while the first one's process serves.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

from components import protocol, queries
from components.message_codec import Malformed
from orchestrator.hosts.tls import write_private

FORMAT = "zenorbit join 1"  # the file's first key, so that a wrong file is told apart


def join_key(run_id: str, name: str) -> str:
    return protocol.JOIN.key(run_id, name=name)


def write_join_file(
    path: Path,
    *,
    role: str,
    run_id: str,
    run_name: str,
    connect: list[str],
    secret: str,
    settings: dict,
    join_timeout_s: float,
    component: str | None = None,
    generation: int | None = None,
) -> Path:
    """A join file (mode 0600) for a component (``role`` component) or the run's router."""
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    body = {
        "format": FORMAT,
        "role": role,
        "run_id": run_id,
        "run": run_name,
        "component": component,
        "generation": generation,
        "connect": connect,
        "join_timeout_s": join_timeout_s,
        "secret": secret,
        "settings": settings,
    }
    return write_private(path, json.dumps(body, indent=1).encode())


class JoinDesk:
    """Answers joins on ``join/*`` (from Zenoh's threads, under a lock): a component the run waits
    for (:meth:`invite`) is granted its generation; one whose process serves is refused a second
    join; one between generations (a restart under way) is told to wait; once the run ends
    (:meth:`close`), every join is told it is over."""

    def __init__(self, session, run_id: str, out):
        self.run_id, self.out = run_id, out
        self.lock = threading.Lock()
        self.entries: dict[str, dict] = {}  # name -> {generation, member, joined, host}
        self.zid = str(session.zid())
        self.over = False
        self.queryable = session.declare_queryable(protocol.JOIN.pattern(run_id), self._answer)

    def invite(self, member) -> None:
        """Wait for a join of this generation of an external member."""
        with self.lock:
            self.entries[member.name] = {"generation": member.generation, "member": member, "joined": False}

    def close(self) -> None:
        with self.lock:
            self.over = True

    def _decide(self, name: str, request: queries.Join | None) -> queries.Message:
        if self.over:
            return queries.Over()
        entry = self.entries.get(name)
        if entry is None:
            return queries.JoinRefused(f"no component {name!r} of this run joins from another host")
        member = entry["member"]
        if entry["joined"] and not member.ended:
            return queries.JoinRefused(
                f"component {name!r} has joined already (generation "
                f"{entry['generation']}, {entry['host']}): a second join is refused"
            )
        if entry["joined"]:
            return queries.Wait()  # terminated: a restart will invite the next generation
        entry["joined"], entry["host"] = True, request_host(request)
        member.host, member.zid = entry["host"], request.zid if request is not None else ""
        return queries.Granted(entry["generation"], self.zid)

    def _answer(self, query) -> None:
        name = str(query.key_expr).rpartition("/")[2]
        try:
            request = queries.Join.decode(query.payload.to_bytes() if query.payload is not None else b"")
        except Malformed:
            request = None
        with self.lock:
            answer = self._decide(name, request)
        if type(answer) is queries.JoinRefused:
            print(
                f"warning: refused a join for {name!r} from {request_host(request)}: {answer.error}",
                file=self.out,
                flush=True,
            )
        query.reply(query.key_expr, answer.encode())


def request_host(request: queries.Join | None) -> str:
    """How a join names where it comes from: 'host ADDRESS (NAME), pid PID'."""
    if request is None:
        return "host ? (?), pid ?"
    address, name, pid = (str(v)[:80] for v in (request.address, request.hostname, request.pid))
    return f"host {address} ({name}), pid {pid}"
