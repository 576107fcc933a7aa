"""How a run's Zenoh sessions hold across hosts: mutual TLS, who may send control messages
(Zenoh access control), the lease after which a silent link counts as dead, peer or client mode.

The orchestrator decides these for the whole run and hands them to every process of it as
*bus settings*, a JSON object: to the processes it starts in ``ZENORBIT_BUS`` (file paths in a
directory only its user reads), to a joining component in its join file (``orchestrator join``
writes the PEM text it holds to such a directory and points the settings at it). Keys:

| key | value |
|---|---|
| ``mode`` | ``peer`` (the run's processes link to each other) or ``client`` (all through a router) |
| ``lease_ms`` | Zenoh's link lease: a link silent for this long is closed (keep-alives at a quarter of it) |
| ``tls`` | ``{ca, certificate, key}``: PEM files; every link is TLS and both ends show a certificate of the run's CA |
| ``acl`` | Zenoh's ``access_control`` section (:func:`access_control`) |

The per-run secret (user/password, :func:`components.bus.open_session`) stays what it was: a
link needs both the secret and a certificate of the run.
"""

from __future__ import annotations

import json
import os

from components import protocol

BUS_ENV = "ZENORBIT_BUS"  # the settings, for the processes the orchestrator starts

ORCHESTRATOR_NAME = "zenorbit orchestrator"  # the certificates' common names: who holds them
CLI_NAME = "zenorbit cli"
ROUTER_NAME = "zenorbit router"


def component_name(name: str) -> str:
    return f"zenorbit component {name}"


def from_env() -> dict:
    """The settings the orchestrator gave this process ({} for none: loopback, no TLS)."""
    text = os.environ.get(BUS_ENV)
    return json.loads(text) if text else {}


def apply(config, settings: dict, *, listening: bool) -> None:
    """Write ``settings`` into a Zenoh config. ``listening``: the session accepts links (a TLS
    listener needs its certificate there too)."""

    def put(key: str, value) -> None:
        config.insert_json5(key, json.dumps(value))

    if settings.get("lease_ms"):
        put("transport/link/tx/lease", int(settings["lease_ms"]))
        # a link whose sending has been blocked for a lease is dead too (Zenoh's default: 5 s), so
        # that a cut link closes within the lease even while we send on it
        put("transport/link/tx/queue/congestion_control/block/wait_before_close", int(settings["lease_ms"]) * 1000)
    tls = settings.get("tls")
    if tls:
        base = "transport/link/tls/"
        put(base + "root_ca_certificate", tls["ca"])
        put(base + "connect_certificate", tls["certificate"])
        put(base + "connect_private_key", tls["key"])
        if listening:
            put(base + "listen_certificate", tls["certificate"])
            put(base + "listen_private_key", tls["key"])
        put(base + "enable_mtls", True)
        # the run's CA signs only the run's processes, so a certificate of it is the identity
        # that counts (its common name, checked by access control), wherever the process is
        put(base + "verify_name_on_connect", False)
    if settings.get("acl"):
        put("access_control", settings["acl"])


def access_control(run_id: str, components: list[str]) -> dict:
    """Zenoh access control for a TLS run: only the orchestrator's certificate sends control
    messages (commands, horizons), holds the orchestrator's liveliness token and answers joins
    and CLI queries; nobody sends another process its quit message. Enforced where a message
    comes in, by every process of the run and its router. Step outputs, batches and frames (images)
    go on the consumers' inbox keys (``OUTPUTS``), which the default permission allows to the
    run's processes, whose certificates the TLS links check."""
    others = [component_name(n) for n in components] + [CLI_NAME]
    return {
        "enabled": True,
        "default_permission": "allow",
        "rules": [
            {
                "id": "control",
                "permission": "deny",
                "flows": ["ingress"],
                "messages": ["put", "delete"],
                "key_exprs": [protocol.COMMANDS.covering(run_id)],
            },
            {
                "id": "orchestrator",
                "permission": "deny",
                "flows": ["ingress"],
                "messages": ["liveliness_token", "declare_queryable"],
                "key_exprs": [t.covering(run_id) for t in (protocol.ORCHESTRATOR_ALIVE, protocol.JOIN, protocol.CTL)],
            },
            {
                "id": "quit",
                "permission": "deny",
                "flows": ["ingress"],
                "messages": ["put", "delete"],
                "key_exprs": [protocol.QUITS.covering(run_id)],
            },
        ],
        "subjects": [
            {"id": "not the orchestrator", "cert_common_names": others},
            {"id": "anyone", "cert_common_names": [*others, ORCHESTRATOR_NAME, ROUTER_NAME]},
        ],
        "policies": [
            {"rules": ["control", "orchestrator"], "subjects": ["not the orchestrator"]},
            {"rules": ["quit"], "subjects": ["anyone"]},
        ],
    }
