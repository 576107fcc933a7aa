"""The bus across hosts, without running anything: the ``bus:`` section's checks, the run's
certificates against its CA, the access control Zenoh accepts, where other hosts reach the run,
and the join desk's answers."""

import textwrap
import types

import pytest

from components import bus_security
from orchestrator.config.load import load
from orchestrator.config.yaml_file import ConfigErrors
from orchestrator.hosts.bus_config import is_loopback
from orchestrator.hosts.run_bus import interface_addresses, reachable_endpoints

BASE = """
run: {name: spread, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 1 ms}
components:
  src: {type: test.constant, parameters: {value: 1.0}}
  far: {type: test.integrator, launch: external, on_failure: restart}
connections:
  far.u: src.y
"""


def bus_of(write_config, section: str = ""):
    return load(write_config(BASE + section)).bus


def errors_of(write_config, section: str) -> list[str]:
    with pytest.raises(ConfigErrors) as e:
        load(write_config(BASE + textwrap.dedent(section)))
    return e.value.errors


def test_the_default_bus_stays_on_loopback_without_tls(write_config):
    spec = bus_of(write_config)
    assert spec.listen == ["tcp/127.0.0.1:0"] and not spec.tls and spec.mode == "peer" and spec.router is None
    assert spec.lease_ns == 10 * 10**9
    assert load(write_config(BASE)).join_timeout_s == 300.0


def test_leaving_loopback_turns_tls_on_and_tcp_endpoints_into_tls(write_config):
    spec = bus_of(write_config, "bus: {listen: [tcp/0.0.0.0:7447], lease: 2 s}\n")
    assert spec.tls and spec.listen == ["tls/0.0.0.0:7447"] and spec.lease_ms == 2000
    assert bus_of(write_config, "bus: {router: tcp/192.0.2.9:7447, mode: client}\n").router == "tls/192.0.2.9:7447"
    # no TLS beyond loopback only when asked for in words: refused naming the way out, else a warning
    refused = errors_of(write_config, "bus: {listen: [tcp/0.0.0.0:7447], tls: false}\n")
    assert any(
        "bus.tls: false, and the bus leaves loopback (tcp/0.0.0.0:7447): every process would listen there in plain TCP"
        in line
        and "bus.plaintext: accept-the-risk" in line
        for line in refused
    ), refused
    config = load(write_config(BASE + "bus: {listen: [tcp/0.0.0.0:7447], tls: false, plaintext: accept-the-risk}\n"))
    plain = config.bus
    assert not plain.tls and plain.listen == ["tcp/0.0.0.0:7447"] and plain.plaintext_beyond == ("tcp/0.0.0.0:7447",)
    assert any("bus: plain TCP beyond loopback (tcp/0.0.0.0:7447)" in note for note in config.notes), config.notes
    assert not load(write_config(BASE + "bus: {tls: false}\n")).notes  # loopback in plain: no word
    assert bus_of(write_config, "bus: {tls: true}\n").listen == ["tls/127.0.0.1:0"]


@pytest.mark.parametrize(
    "section, expected",
    [
        ("bus: {listen: [udp/0.0.0.0:7447]}", "bus.listen[0]: udp/0.0.0.0:7447 cannot carry TLS (bus.tls is auto"),
        ("bus: {listen: [tls/127.0.0.1:0]}", "bus.listen[0]: tls/127.0.0.1:0 is TLS, and bus.tls is auto"),
        ("bus: {mode: client}", "bus.mode: client sends everything through a router; give bus.router"),
        ("bus: {lease: 50 ms}", "bus.lease: expected at least 100 ms"),
        ("bus: {tls: maybe}", "bus.tls: expected"),
        (
            "bus: {tls: true, ca: {certificate: nowhere.pem, key: nowhere.key}}",
            "bus.ca.certificate: file 'nowhere.pem' not found",
        ),
        ("run: {join_timeout: soon}", "run.join_timeout"),
    ],
)
def test_each_bus_error_names_its_key(write_config, section, expected):
    if section.startswith("run:"):
        text = BASE.replace("step: 1 ms}", "step: 1 ms, join_timeout: soon}")
        with pytest.raises(ConfigErrors) as e:
            load(write_config(text))
        found = e.value.errors
    else:
        found = errors_of(write_config, section + "\n")
    assert any(expected in line for line in found), found


def test_the_run_certificates_come_from_the_users_ca_and_name_their_holders(write_config, tmp_path):
    """bus.ca: every certificate of the run is signed by the user's CA (its signature checks with
    the CA's public key) and names its holder; a certificate that is no CA is refused."""
    from cryptography import x509
    from cryptography.hazmat.primitives.asymmetric import ec

    from orchestrator.hosts.tls import RunCertificates, _pem_certificate, _pem_key, issue, make_ca

    ca_key, ca_certificate = make_ca("my lab")
    (tmp_path / "ca.pem").write_bytes(_pem_certificate(ca_certificate))
    (tmp_path / "ca.key").write_bytes(_pem_key(ca_key))
    spec = bus_of(write_config, "bus: {tls: true, ca: {certificate: ca.pem, key: ca.key}}\n")
    made = RunCertificates(tmp_path / "run", {"component.far": bus_security.component_name("far")}, spec.ca)
    certificate = x509.load_pem_x509_certificate(made.pem("component.far")["certificate"].encode())
    ca_key.public_key().verify(
        certificate.signature, certificate.tbs_certificate_bytes, ec.ECDSA(certificate.signature_hash_algorithm)
    )
    assert certificate.subject.rfc4514_string() == "CN=zenorbit component far"
    assert (tmp_path / "run" / "component.far.key").stat().st_mode & 0o777 == 0o600
    leaf_key, leaf = issue(ca_key, ca_certificate, "not a CA")
    (tmp_path / "leaf.pem").write_bytes(_pem_certificate(leaf))
    (tmp_path / "leaf.key").write_bytes(_pem_key(leaf_key))
    found = errors_of(write_config, "bus: {tls: true, ca: {certificate: leaf.pem, key: leaf.key}}")
    assert any("is not a CA certificate" in line for line in found), found
    found = errors_of(write_config, "bus: {tls: true, ca: {certificate: ca.pem, key: leaf.key}}")
    assert any("is not the key of the certificate" in line for line in found), found


def test_zenoh_takes_the_access_control_as_written():
    """Zenoh refuses a config it cannot read (a misspelt key of access_control is an error), and
    takes ours."""
    import json

    import zenoh

    from components import bus

    acl = bus_security.access_control("spread-1", ["src", "far"])
    config = bus.session_config()
    config.insert_json5("access_control", json.dumps(acl))
    zenoh.open(config).close()
    broken = bus.session_config()
    with pytest.raises(zenoh.ZError):
        broken.insert_json5("access_control", json.dumps({**acl, "rulez": acl["rules"]}))
        zenoh.open(broken).close()


def test_loopback_and_the_endpoints_other_hosts_reach():
    assert is_loopback("tcp/127.0.0.1:7447") and is_loopback("tls/127.8.0.1:1") and is_loopback("tcp/[::1]:1")
    assert is_loopback("tcp/localhost:1") and not is_loopback("tcp/0.0.0.0:1") and not is_loopback("tcp/host.lab:1")
    here = reachable_endpoints(["tls/0.0.0.0:7447", "tls/192.0.2.9:7448"])
    assert here == [*(f"tls/{a}:7447" for a in interface_addresses()), "tls/192.0.2.9:7448", "tls/127.0.0.1:7447"]
    assert all(not a.startswith("127.") for a in interface_addresses())


def test_the_join_desk_grants_a_waited_generation_once_and_refuses_a_second_join():
    import io

    import zenoh

    from components import bus, queries
    from orchestrator.hosts.join import JoinDesk

    session = zenoh.open(bus.session_config())
    try:
        desk = JoinDesk(session, "spread-1", io.StringIO())
        far = types.SimpleNamespace(name="far", generation=0, ended=False, host="", zid="")
        request = queries.Join("192.0.2.2", "flight", 42, "abc")
        assert type(desk._decide("far", request)) is queries.JoinRefused  # not invited yet
        desk.invite(far)
        assert desk._decide("far", request) == queries.Granted(0, str(session.zid()))
        assert far.host == "host 192.0.2.2 (flight), pid 42" and far.zid == "abc"
        second = desk._decide("far", queries.Join("192.0.2.2", "flight", 43, "abc"))
        assert type(second) is queries.JoinRefused and "a second join is refused" in second.error
        far.ended = True  # terminated for a restart
        assert desk._decide("far", request) == queries.Wait()
        desk.invite(types.SimpleNamespace(name="far", generation=1, ended=False, host="", zid=""))
        assert desk._decide("far", request) == queries.Granted(1, str(session.zid()))
        desk.close()
        assert desk._decide("far", request) == queries.Over()
    finally:
        session.close()
