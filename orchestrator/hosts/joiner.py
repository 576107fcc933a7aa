"""Joining a run from another host: ``orchestrator join FILE`` serves a component of the run, and
``orchestrator router --listen ... --join FILE`` is the run's router (docs/design.md §7).

A joined component serves one generation after another: when the run restarts from a checkpoint
it asks to join again, and when its link to the orchestrator is lost (cut, or the orchestrator's
host gone) it tries to reach the run again, for up to run.join_timeout. It exits 0 when the run
ends, 1 when the run refuses it or is gone, 2 for a file that is not a join file.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

from components import bus, queries
from components.message_codec import Malformed
from orchestrator.hosts.join import FORMAT, join_key
from orchestrator.hosts.tls import write_pem_files

ASK_TIMEOUT_S = 5.0
PROBE_TIMEOUT_S = 2.0
CONNECT_TIMEOUT_S = 4.0  # a reachable run that does not take the link by then refused it (Zenoh retries meanwhile)
DEAD_AFTER_S = 10.0  # every endpoint refusing TCP this long: nothing listens, the run has ended


class JoinError(Exception):
    """The join cannot go on; ``code`` the exit code."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message)
        self.code = code


def read_join_file(path: Path, role: str) -> dict:
    try:
        mode = Path(path).stat().st_mode
    except OSError as e:
        raise JoinError(f"{path}: cannot read it ({e.strerror})", 2) from None
    if mode & 0o077:  # it holds the run's secret and key: as ssh refuses such a key file
        raise JoinError(
            f"{path}: readable or writable by others (mode {mode & 0o777:o}), and it holds the run's "
            f"secret: chmod 600 {path}",
            2,
        )
    try:
        body = json.loads(Path(path).read_text())
    except OSError as e:
        raise JoinError(f"{path}: cannot read it ({e.strerror})", 2) from None
    except ValueError:
        body = None
    if not isinstance(body, dict) or body.get("format") != FORMAT:
        raise JoinError(f"{path}: not a join file (the orchestrator writes them: DIR/join/<component>.join)", 2)
    if body.get("role") != role:
        other = "orchestrator router --join" if body.get("role") == "router" else "orchestrator join"
        raise JoinError(f"{path}: a join file for {body.get('role')!r}, not {role!r}: use it with `{other}`", 2)
    return body


def local_settings(body: dict, directory: Path) -> dict:
    """The file's bus settings with its certificates written to files in ``directory``."""
    settings = dict(body["settings"])
    if settings.get("tls"):
        settings["tls"] = write_pem_files(directory, settings["tls"])
    return settings


def split(endpoint: str) -> tuple[str, int]:
    address = endpoint.partition("/")[2]
    host, _, port = address.rpartition(":")
    return host.strip("[]"), int(port)


def reachable(endpoints: list[str]) -> tuple[str | None, bool]:
    """The first endpoint a TCP connection reaches (the run's TLS and secret not yet asked), and
    whether every endpoint refused the connection outright (nothing listens there)."""
    refused = True
    for endpoint in endpoints:
        try:
            with socket.create_connection(split(endpoint), timeout=PROBE_TIMEOUT_S):
                return endpoint, False
        except ConnectionRefusedError:
            continue
        except OSError:
            refused = False  # a timeout or no route: something may be there, out of reach
    return None, refused


def own_address(endpoint: str) -> str:
    """This host's address on the route to ``endpoint`` (no packet sent)."""
    host, port = split(endpoint)
    try:
        with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect((host, port))
            return probe.getsockname()[0]
    except OSError:
        return "?"


def _ask(session, body: dict, endpoint: str) -> queries.Message | None:
    """The run's answer to a join (Granted, Wait, JoinRefused, Over); None: none, or a malformed one."""
    request = queries.Join(own_address(endpoint), socket.gethostname(), os.getpid(), str(session.zid()))
    for reply in session.get(
        join_key(body["run_id"], body["component"]), payload=request.encode(), timeout=ASK_TIMEOUT_S
    ):
        if reply.ok is not None:
            try:
                return queries.decode_join_answer(reply.ok.payload.to_bytes())
            except Malformed:
                return None
    return None


def _connect(body: dict, endpoints: list[str], listen: str | None, settings: dict, deadline: float):
    """A session with the run (retried until ``deadline``), and the endpoint it went to."""
    import zenoh

    from components.serving import open_component_session

    refused_since = None
    while True:
        endpoint, refused = reachable(endpoints)
        if endpoint is not None:
            try:
                session = open_component_session(
                    endpoint, listen, body["secret"], settings, connect_timeout_s=CONNECT_TIMEOUT_S
                )
                return session, endpoint
            except zenoh.ZError:
                raise JoinError(
                    f"the run at {endpoint} refused the link: wrong secret or certificate (is {body['run']!r} "
                    f"still the run this join file is from?)"
                ) from None
        now = time.monotonic()
        refused_since = (refused_since or now) if refused else None
        if refused_since is not None and now - refused_since >= DEAD_AFTER_S:
            raise JoinError(
                f"the run {body['run']!r} at {', '.join(endpoints)} is not alive: nothing has listened "
                f"there for {DEAD_AFTER_S:g} s (it has ended, or the join file is from an earlier run)"
            )
        if now > deadline:
            raise JoinError(
                f"cannot reach the run {body['run']!r} at {', '.join(endpoints)} "
                f"(run.join_timeout, {body['join_timeout_s']:g} s)"
                + (
                    ""
                    if refused
                    else ": something answers slowly or not at all there (alive but out of reach: a firewall, a route?)"
                )
            )
        time.sleep(1.0)


def join(
    path: Path, connect: list[str] | None = None, listen: str | None = None, cpu: int | None = None, out=sys.stderr
) -> int:
    """Serve the component of a join file for as long as the run wants it; the exit code."""
    from components.group import ORPHANED, RELEASED

    body = read_join_file(path, "component")
    name, endpoints = body["component"], connect or body["connect"]
    timeout = float(body["join_timeout_s"])
    with tempfile.TemporaryDirectory(prefix="zenorbit-join-") as directory:
        settings = local_settings(body, Path(directory))
        served = False
        deadline = time.monotonic() + timeout
        while True:
            session, endpoint = _connect(body, endpoints, listen, settings, deadline)
            try:
                while True:
                    answer = _ask(session, body, endpoint)
                    if type(answer) is queries.Granted:
                        ended = _serve(session, body, endpoint, answer, cpu, settings, out)
                        served = True
                        deadline = time.monotonic() + timeout
                        if ended == ORPHANED:
                            print(
                                f"lost the run {body['run']!r}: trying to join again for "
                                f"{timeout:g} s (run.join_timeout)",
                                file=out,
                                flush=True,
                            )
                            break
                        if ended != RELEASED:
                            return 0
                        continue
                    if type(answer) is queries.Over or (
                        answer is None and served and not _orchestrator_alive(session, body)
                    ):
                        return 0
                    if type(answer) is queries.JoinRefused and not served:
                        raise JoinError(f"the run refused the join: {answer.error}")
                    if answer is None and not served:
                        raise JoinError(
                            f"the run {body['run']!r} at {endpoint} did not answer the join "
                            f"(it ended, or this file is from another run)"
                        )
                    if time.monotonic() > deadline:
                        raise JoinError(
                            f"the run {body['run']!r} did not take {name!r} back within "
                            f"{timeout:g} s (run.join_timeout)"
                        )
                    time.sleep(0.2)
            finally:
                bus.close_session(session)


def _serve(session, body: dict, endpoint: str, granted: queries.Granted, cpu: int | None, settings: dict, out):
    """Serve the generation the run granted until the run releases it, ends or is lost: how it ended."""
    from components.serving import beat_interval, serve_session

    name = body["component"]
    print(
        f"joined run {body['run']!r} ({body['run_id']}) at {endpoint} as {name!r}, generation {granted.generation}",
        file=out,
        flush=True,
    )
    return serve_session(
        session, body["run_id"], [(name, granted.generation)], cpu, granted.orchestrator, beat_interval(settings)
    )


def _orchestrator_alive(session, body: dict) -> bool:
    return any(True for _ in session.liveliness().get(bus.orchestrator_alive_key(body["run_id"]), timeout=2.0))


def route(path: Path, listen: list[str]) -> int:
    """The run's router until the run ends (its orchestrator's liveliness token goes) or a signal."""
    import zenoh

    body = read_join_file(path, "router")
    # a router forwards every link's traffic: Zenoh's own runtime (a thread per task kind), not the
    # one thread a component's session runs on (bus.RUNTIME), on which one TLS link blocked sending
    # holds up every other
    bus.prefer_runtime(bus.DEFAULT_RUNTIME)
    with tempfile.TemporaryDirectory(prefix="zenorbit-router-") as directory:
        settings = {**local_settings(body, Path(directory)), "mode": "router"}
        try:
            session = bus.open_session(listen, [], secret=body["secret"], settings=settings)
        except zenoh.ZError as e:
            raise JoinError(f"cannot listen on {', '.join(listen)}: {e}") from None
        done = threading.Event()
        seen = threading.Event()

        def orchestrator(sample) -> None:
            if sample.kind == zenoh.SampleKind.PUT:
                seen.set()
            elif seen.is_set():
                done.set()

        previous = {sig: signal.signal(sig, lambda *_: done.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
        watch = session.liveliness().declare_subscriber(
            bus.orchestrator_alive_key(body["run_id"]), orchestrator, history=True
        )
        print(
            f"router of run {body['run']!r} ({body['run_id']}) listening on {', '.join(listen)}"
            f"{' (TLS)' if settings.get('tls') else ''}",
            file=sys.stderr,
            flush=True,
        )
        try:
            while not done.wait(0.2):
                pass
        finally:
            watch.undeclare()
            bus.close_session(session)
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    return 0
