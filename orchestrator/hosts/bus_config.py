"""The ``bus:`` section, checked across its keys: where the run listens and links, through a router
or not, its lease, and whether its links are TLS (docs/design.md §4, §7)."""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class BusSpec:
    listen: list[str]  # tls/ in place of tcp/ when ``tls``
    connect: list[str]
    mode: str  # peer | client
    router: str | None
    lease_ns: int
    tls: bool
    ca: tuple[Path, Path] | None  # the user's CA (certificate, key), else one made for the run
    plaintext_beyond: tuple[str, ...] = ()  # endpoints beyond loopback in plain TCP (bus.plaintext allowed it)

    @property
    def lease_ms(self) -> int:
        return max(1, self.lease_ns // 1_000_000)


def host_of(endpoint: str) -> str:
    """The host of ``proto/host:port`` (an IPv6 address without its brackets)."""
    address = endpoint.partition("/")[2].rpartition(":")[0]
    return address[1:-1] if address.startswith("[") else address


def is_loopback(endpoint: str) -> bool:
    host = host_of(endpoint)
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # a host name: another machine, as far as we can tell


def with_protocol(endpoint: str, protocol: str) -> str:
    return f"{protocol}/{endpoint.partition('/')[2]}"


def check(section: dict, config_dir: Path, errors: list[str], file) -> BusSpec | None:
    """The section as a BusSpec, or None with the problems added to ``errors``."""
    before = len(errors)
    router = section["router"]
    named: list[tuple[str, int | None, str]] = [
        *(("listen", i, e) for i, e in enumerate(section["listen"])),
        *(("connect", i, e) for i, e in enumerate(section["connect"])),
    ]
    if router:
        named.append(("router", None, router))
    beyond = [e for _, _, e in named if not is_loopback(e)]
    asked = {True: "true", False: "false"}.get(section["tls"], "auto")
    tls = asked == "true" or (asked == "auto" and bool(beyond))
    errors += _protocol_problems(named, tls, asked, file)
    if beyond and not tls and section["plaintext"] != "accept-the-risk":
        errors.append(
            f"{file}: bus.tls: false, and the bus leaves loopback ({', '.join(beyond)}): every process "
            f"would listen there in plain TCP, the run's traffic and secret readable on that network; "
            f"set bus.tls: true (or auto), or say bus.plaintext: accept-the-risk"
        )
    if section["mode"] == "client" and not router:
        errors.append(
            f"{file}: bus.mode: client sends everything through a router; give bus.router "
            f"(started with orchestrator router)"
        )
    if section["lease"] < 100_000_000:
        errors.append(
            f"{file}: bus.lease: expected at least 100 ms (keep-alives go every quarter of it), "
            f"got {section['lease'] / 1e6:g} ms"
        )
    ca = _ca(section, config_dir, tls, asked, file, errors, before) if section["ca"] is not None else None
    if len(errors) > before:
        return None
    protocol = "tls" if tls else "tcp"

    def tcp_as(endpoint: str) -> str:
        return with_protocol(endpoint, protocol) if endpoint.startswith(("tcp/", "tls/")) else endpoint

    return BusSpec(
        listen=[tcp_as(e) for e in section["listen"]],
        connect=[tcp_as(e) for e in section["connect"]],
        mode=section["mode"],
        router=tcp_as(router) if router else None,
        lease_ns=section["lease"],
        tls=tls,
        ca=ca,
        plaintext_beyond=tuple(beyond) if not tls else (),
    )


def _protocol_problems(named: list[tuple[str, int | None, str]], tls: bool, asked: str, file) -> list[str]:
    """Each endpoint's protocol against bus.tls: TLS needs tcp/ or tls/, and tls/ needs TLS."""
    problems = []
    for key, i, endpoint in named:
        where = f"bus.{key}" + (f"[{i}]" if i is not None else "")
        protocol = endpoint.partition("/")[0]
        if tls and protocol not in ("tcp", "tls"):
            problems.append(
                f"{file}: {where}: {endpoint} cannot carry TLS (bus.tls is {asked}"
                f"{', and the bus leaves loopback' if asked == 'auto' else ''}); expected tcp/ or tls/"
            )
        if not tls and protocol == "tls":
            problems.append(
                f"{file}: {where}: {endpoint} is TLS, and bus.tls is {asked}"
                f"{' (the bus stays on loopback)' if asked == 'auto' else ''}; "
                f"write tcp/, or set bus.tls: true"
            )
    return problems


def _ca(section: dict, config_dir: Path, tls: bool, asked: str, file, errors: list[str], before: int):
    """bus.ca's certificate and key paths; loaded to check them when the section has no other
    problem (``errors`` had ``before`` of them when it began)."""
    if not tls:
        errors.append(f"{file}: bus.ca: a CA is for TLS, and bus.tls is {asked}")
    paths = []
    for part in ("certificate", "key"):
        path = (config_dir / section["ca"][part]).resolve()
        if not path.is_file():
            errors.append(f"{file}: bus.ca.{part}: file {section['ca'][part]!r} not found ({path})")
        paths.append(path)
    ca = tuple(paths)
    if len(errors) == before:
        from orchestrator.hosts.tls import load_ca

        try:
            load_ca(*ca)
        except ValueError as e:
            errors.append(f"{file}: bus.ca: {e}")
    return ca
