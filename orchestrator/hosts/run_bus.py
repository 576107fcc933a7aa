"""The run's bus as each of its processes sees it: the settings (TLS certificates, access control,
lease, mode) of the orchestrator, of the components it starts, of the CLI, of a joining component
and of the router, and the endpoints another host connects to (docs/design.md §7)."""

from __future__ import annotations

import fcntl
import json
import shutil
import socket
import struct
import time
from pathlib import Path
from typing import TYPE_CHECKING

from components import bus, bus_security
from components.constants import NS_PER_S
from orchestrator.hosts.bus_config import BusSpec, host_of, is_loopback

if TYPE_CHECKING:
    from orchestrator.hosts.join import JoinDesk
    from orchestrator.hosts.link_watch import LinkWatch
    from orchestrator.hosts.tls import RunCertificates

SIOCGIFADDR = 0x8915


def interface_addresses() -> list[str]:
    """This host's IPv4 addresses, loopback excepted."""
    found = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        for _, name in socket.if_nameindex():
            try:
                answer = fcntl.ioctl(probe.fileno(), SIOCGIFADDR, struct.pack("256s", name.encode()[:15]))
            except OSError:  # no IPv4 address on it
                continue
            address = socket.inet_ntoa(answer[20:24])
            if not address.startswith("127."):
                found.append(address)
    return found


def reachable_endpoints(listen: list[str]) -> list[str]:
    """Where another host reaches a session listening on ``listen`` (ports resolved): an
    address of each wildcard listen endpoint's host, the others as they are; loopback last (a
    component on this same host)."""
    out, local = [], []
    for endpoint in listen:
        protocol, port = endpoint.partition("/")[0], endpoint.rpartition(":")[2]
        host = host_of(endpoint)
        if host in ("0.0.0.0", "::"):
            out += [f"{protocol}/{a}:{port}" for a in interface_addresses()]
            local.append(f"{protocol}/127.0.0.1:{port}")
        elif is_loopback(endpoint):
            local.append(endpoint)
        else:
            out.append(endpoint)
    return out + local


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def resolve_endpoints(listen: list[str]) -> tuple[list[str], str]:
    """Fill port 0 with a free port; return (listen endpoints, the one local components connect to)."""
    resolved = []
    for endpoint in listen:
        proto, _, address = endpoint.partition("/")
        host, _, port = address.rpartition(":")
        if port == "0":
            port = str(free_port())
        resolved.append(f"{proto}/{host}:{port}")
    proto, _, address = resolved[0].partition("/")
    host, _, port = address.rpartition(":")
    local_host = "127.0.0.1" if host in ("0.0.0.0", "[::]") else host
    return resolved, f"{proto}/{local_host}:{port}"


class BusUnavailable(Exception):
    """The run's bus cannot be opened: the run cannot start."""


class RunBus:
    """The bus of one run: its settings for each process, the orchestrator's session, the join
    files and the desk that answers joins. With TLS, ``directory`` (0700, removed by
    :meth:`close`) holds the run's certificates for the processes of this host; ``runtime``: the
    directory of this user's runs (:func:`orchestrator.run.runs.directory`)."""

    def __init__(self, config, run_id: str, secret: str, record_dir: Path | None, runtime: Path, out):
        spec: BusSpec = config.bus
        self.config, self.spec, self.run_id, self.secret, self.out = config, spec, run_id, secret, out
        self.directory = runtime / f"{run_id}.bus"
        # join files go with the recording, else with the run's entry in the runtime directory
        self.join_dir = (record_dir / "join") if record_dir else runtime.parent / "join" / run_id
        self.certificates: RunCertificates | None = None
        self.acl: dict | None = None
        self.desk: JoinDesk | None = None  # from open_session on
        self.watch: LinkWatch | None = None
        self.base = {"mode": spec.mode, "lease_ms": spec.lease_ms}
        self.endpoints: list[str] = []  # where other hosts reach the run
        self.local: str = ""  # where processes of this host (and the CLI) connect
        self.listen: list[str] = []
        if spec.tls:
            from orchestrator.hosts.tls import RunCertificates

            components = list(config.components)
            holders = {
                "orchestrator": bus_security.ORCHESTRATOR_NAME,
                "cli": bus_security.CLI_NAME,
                "router": bus_security.ROUTER_NAME,
                **{f"component.{n}": bus_security.component_name(n) for n in components},
            }
            self.certificates = RunCertificates(self.directory, holders, spec.ca, run_id)
            self.acl = bus_security.access_control(run_id, components)

    def settings(self, holder: str, portable: bool = False) -> dict:
        """Bus settings for ``holder`` (orchestrator, cli, router or component.NAME): certificate
        files, or (``portable``, for another host) their PEM text."""
        settings = dict(self.base)
        if self.certificates is not None:
            settings["tls"] = self.certificates.pem(holder) if portable else self.certificates.files(holder)
            settings["acl"] = self.acl
        return settings

    def open(self):
        """The orchestrator's session and its join desk. Through a router in client mode, this
        waits for the router (run.join_timeout)."""
        import zenoh

        from orchestrator.hosts.join import JoinDesk

        spec = self.spec
        if spec.tls or any(c.launch == "external" for c in self.config.components.values()):
            from orchestrator.hosts.link_watch import LinkWatch

            self.watch = LinkWatch(self.out)  # says so when a link with a wrong secret or certificate is refused
        connect = ([spec.router] if spec.router else []) + spec.connect
        if spec.router:
            path = self._write("router", self.join_dir.resolve() / "router.join", [spec.router])
            print(
                f"the run goes through the router at {spec.router}: start it there with\n"
                f"    orchestrator router --listen {_any_host(spec.router)} --join {path}",
                file=self.out,
                flush=True,
            )
        listen_asked = [] if spec.mode == "client" else spec.listen
        for attempt in range(3):  # a free port picked here may be taken by another run before Zenoh binds it
            if listen_asked:
                listen, local = resolve_endpoints(listen_asked)
            else:  # a client: bus_config.check made sure it names its router
                assert spec.router is not None, "a client's bus names its router"
                listen, local = [], spec.router
            try:
                session = bus.open_session(
                    listen,
                    connect,
                    mesh=spec.mode == "peer",
                    secret=self.secret,
                    settings=self.settings("orchestrator"),
                    connect_timeout_s=self.config.join_timeout_s if spec.mode == "client" else None,
                )
                break
            except zenoh.ZError as e:
                if spec.mode == "client":
                    raise BusUnavailable(
                        f"cannot reach the router at {spec.router} (bus.router) within "
                        f"{self.config.join_timeout_s:g} s (run.join_timeout): {e}"
                    ) from None
                if attempt == 2 or not any(e.endswith(":0") for e in spec.listen):
                    raise BusUnavailable(f"cannot open the bus on {', '.join(listen)} (bus.listen): {e}") from None
        self.listen, self.local = listen, local
        self.endpoints = [local] if spec.mode == "client" else reachable_endpoints(listen)  # local: the router
        self.desk = JoinDesk(session, self.run_id, self.out)
        return session

    def _write(self, role: str, path: Path, connect: list[str], member=None) -> Path:
        from orchestrator.hosts.join import write_join_file

        holder = f"component.{member.name}" if member is not None else "router"
        return write_join_file(
            path,
            role=role,
            run_id=self.run_id,
            run_name=self.config.name,
            connect=connect,
            secret=self.secret,
            settings=self.settings(holder, portable=True),
            join_timeout_s=self.config.join_timeout_s,
            component=member.name if member is not None else None,
            generation=member.generation if member is not None else None,
        )

    def invite(self, member) -> Path:
        """Write the join file of an external member, say where it is, and wait for its join."""
        path = self._write("component", self.join_dir.resolve() / f"{member.name}.join", self.endpoints, member)
        assert self.desk is not None, "open_session comes before an invite"
        self.desk.invite(member)
        print(
            f"waiting for external component {member.name!r} (generation {member.generation}, up to "
            f"{self.config.join_timeout_s:g} s): on its host, run\n    orchestrator join {path}",
            file=self.out,
            flush=True,
        )
        return path

    def child_env(self, name: str | None) -> dict[str, str]:
        """The bus settings in the environment of a process the orchestrator starts: component
        ``name``, or (None) another process of the run (the viewer), with the CLI's identity."""
        holder = f"component.{name}" if name else "cli"
        return {bus_security.BUS_ENV: json.dumps(self.settings(holder))}

    def component_listen(self) -> str | None:
        """Where a component the orchestrator starts listens for its peers: beside the
        orchestrator's first listen endpoint, so that components on other hosts reach it too; None
        in client mode."""
        if self.spec.mode == "client":
            return None
        endpoint = self.listen[0]
        return f"{endpoint.partition('/')[0]}/{endpoint.partition('/')[2].rpartition(':')[0]}:0"

    def lost(self, member) -> str:
        """How losing an external member (its link closed, or silent for a lease) reads."""
        return (
            f"lost: nothing heard from it within bus.lease ({self.spec.lease_ns / NS_PER_S:g} s), its link "
            f"was cut, its host went down or its process ended"
        )

    def link_closed(self, zid: str, members) -> None:
        """Zenoh closed the link to session ``zid``: the live member it was is lost."""
        for member in members:
            if member.zid == zid and not member.ended:
                member.cut = True

    def silent(self, member) -> str | None:
        """How a joined external member is lost, its link closed or silent for bus.lease; None
        while it is heard (its heartbeats come every quarter of the lease)."""
        if member.spec.launch != "external" or not member.heard_at or member.ended:
            return None
        if not member.cut and time.monotonic() - member.heard_at <= self.spec.lease_ns / NS_PER_S:
            return None
        return self.lost(member)

    def late(self, names: list[str]) -> str:
        return (
            f"component {', '.join(map(repr, names))} did not join within {self.config.join_timeout_s:g} s "
            f"(run.join_timeout): run `orchestrator join {self.join_dir}/<component>.join` on its host"
        )

    def close(self) -> None:
        if self.desk is not None:
            self.desk.close()

    def remove(self, join_files: bool) -> None:
        """The certificate files of this host's processes, and ``join_files`` (the run is over)."""
        shutil.rmtree(self.directory, ignore_errors=True)
        if self.watch is not None:
            self.watch.close()
            self.watch = None
        if join_files:
            shutil.rmtree(self.join_dir, ignore_errors=True)


def _any_host(endpoint: str) -> str:
    """The endpoint with its host made 0.0.0.0: listen on every interface, at its port."""
    return f"{endpoint.partition('/')[0]}/0.0.0.0:{endpoint.rpartition(':')[2]}"
