"""Joining a run from another host, on loopback (real processes, real Zenoh with TLS): the join file,
`orchestrator join`, what is refused (a wrong secret, a certificate of another CA, a second join,
control messages from a component's identity), run.join_timeout, and a joined component left
alone when its orchestrator dies. The same across real network namespaces: tests/hosts/."""

from __future__ import annotations

import json
import signal
import stat
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from components import bus, protocol
from orchestrator.hosts.tls import _pem_certificate, _pem_key, issue, make_ca
from orchestrator.run import runs
from tests.conftest import ROOT, orchestrator, start_run, wait_for_step, wait_until

pytestmark = pytest.mark.integration

CHAIN = """
run: {{name: {name}, epoch: 2022-09-18T12:00:00Z, duration: {duration}, step: 1 ms, realtime: {realtime},
       join_timeout: {join_timeout}}}
bus: {{tls: {tls}}}
components:
  src: {{type: test.constant, parameters: {{value: 1234.5678}}}}
  a: {{type: test.integrator, launch: {launch}, parameters: {{gain: 0.37}}}}
  b: {{type: test.integrator, parameters: {{gain: 1.3}}}}
connections:
  a.u: src.y
  b.u: a.x
"""


def chain(name="joined", duration="0.5 s", realtime=0, join_timeout="60 s", tls="true", launch="external") -> str:
    return CHAIN.format(
        name=name, duration=duration, realtime=realtime, join_timeout=join_timeout, tls=tls, launch=launch
    )


def join(path, *extra, **popen) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "orchestrator.cli", "join", str(path), *extra],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **popen,
    )


def join_file(record, name="a"):
    path = record / "join" / f"{name}.join"
    return wait_until(lambda: path if path.exists() else None, f"the join file {path}")


def table(record):
    return pq.read_table(record / "signals.parquet").to_pandas()


def test_a_component_joins_from_its_join_file_and_the_run_equals_the_local_one(write_config, tmp_path):
    """The join file (mode 0600) names the run, the component and its generation and holds the
    secret and the component's certificate; `orchestrator join` serves it until the run ends and
    exits 0; the signals equal those of the same run with every component local, bit for bit."""
    local = tmp_path / "local"
    assert orchestrator("run", write_config(chain(launch="local"), "local.yaml"), "--record", local).returncode == 0
    record = tmp_path / "rec"
    run = start_run(write_config(chain()), record)
    joined = None
    try:
        path = join_file(record)
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
        body = json.loads(path.read_text())
        assert (body["component"], body["generation"], body["run"]) == ("a", 0, "joined")
        assert len(body["secret"]) == 64 and "BEGIN PRIVATE KEY" in body["settings"]["tls"]["key"]
        assert all(e.startswith("tls/") for e in body["connect"])
        joined = join(path)
        _, err = run.communicate(timeout=120)
        _joined_out, joined_err = joined.communicate(timeout=60)
    finally:
        for p in (run, joined):
            if p is not None and p.poll() is None:
                p.kill()
    assert run.returncode == 0, err
    assert f"orchestrator join {path}" in err
    assert joined.returncode == 0 and "as 'a', generation 0" in joined_err, joined_err
    here, there = table(local), table(record)
    assert len(there) == 501 and there["a.x"].iloc[-1] > 0
    assert there.equals(here)


def _tampered(path, tmp_path, name, change) -> str:
    body = json.loads(path.read_text())
    change(body)
    out = tmp_path / f"{name}.join"
    out.write_text(json.dumps(body))
    out.chmod(0o600)  # a join file others can read is refused before anything else
    return str(out)


def _foreign_certificate(body) -> None:
    """The component's certificate and key from another CA (same common name), the run's CA kept."""
    ca_key, ca_certificate = make_ca("someone else's CA")
    key, certificate = issue(ca_key, ca_certificate, "zenorbit component a")
    body["settings"]["tls"].update(certificate=_pem_certificate(certificate).decode(), key=_pem_key(key).decode())


def test_a_wrong_secret_a_foreign_certificate_and_a_second_join_are_refused(write_config, tmp_path):
    record = tmp_path / "rec"
    run = start_run(write_config(chain(name="refusals", duration="600 s", realtime=1.0)), record)
    first = None
    try:
        path = join_file(record)
        for name, change in (("secret", lambda b: b.update(secret="0" * 64)), ("certificate", _foreign_certificate)):
            refused = orchestrator("join", _tampered(path, tmp_path, name, change), timeout=120)
            assert refused.returncode == 1, (name, refused.stderr)
            assert "refused the link: wrong secret or certificate" in refused.stderr, (name, refused.stderr)
        first = join(path)
        wait_for_step("refusals", 20, run=run)
        second = orchestrator("join", path, timeout=120)
        assert second.returncode == 1 and "a second join is refused" in second.stderr, second.stderr
        assert first.poll() is None  # the first one serves on
        assert orchestrator("stop", "--run", "refusals").returncode == 0
        _, err = run.communicate(timeout=120)
        first.communicate(timeout=60)
    finally:
        for p in (run, first):
            if p is not None and p.poll() is None:
                p.kill()
    assert run.returncode == 0, err
    assert "warning: refused a join for 'a'" in err and "has joined already" in err
    assert "warning: refused a link to the run's bus: wrong secret" in err, err
    assert "warning: refused a link to the run's bus: a certificate not of this run's CA" in err, err
    assert first.returncode == 0
    data = table(record)
    assert np.allclose(data["a.x"], 0.37 * 1234.5678 * data["time"], rtol=1e-9)  # a stepped on, untouched


def test_only_the_orchestrator_sends_control_messages(write_config, tmp_path):
    """Zenoh access control: a process holding a component's certificate and the secret (its
    join file) publishes `terminate` on the command keys of every component: none is taken; the
    run goes on to its end."""
    from components import bus_security

    record = tmp_path / "rec"
    run = start_run(write_config(chain(name="acl", duration="600 s", realtime=1.0, launch="local")), record)
    try:
        wait_for_step("acl", 20, run=run)
        entry = runs.find("acl")[0]
        rid = entry["run_id"]
        tls = {
            part: entry["settings"]["tls"][part].replace("cli.", "component.a.")
            for part in ("ca", "certificate", "key")
        }
        settings = {**entry["settings"], "tls": tls}
        assert bus_security.component_name("a")  # the identity the run gave component a
        with bus.open_session(
            ["tls/127.0.0.1:0"], [entry["endpoint"]], mesh=True, secret=entry["secret"], settings=settings
        ) as session:
            wait_until(lambda: len(list(session.info.peers_zid())) == 4, "links to the run's 4 processes", run=run)
            for name in ("src", "a", "b"):
                for generation in (0, 1):
                    session.put(bus.command_key(rid, name, generation), protocol.Terminate(final=True).encode())
            session.put(bus.quit_key(rid, "b", 0), protocol.Quit().encode())
            row = wait_for_step("acl", 20, run=run)
            wait_for_step("acl", row + 200, run=run)  # still stepping: nothing was taken
        assert orchestrator("stop", "--run", "acl").returncode == 0
        _, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err


def test_a_component_that_does_not_join_fails_the_run_naming_it(write_config, tmp_path):
    text = chain(name="nojoin", join_timeout="2 s").replace("join_timeout:", "start_timeout: 2 s, join_timeout:")
    result = orchestrator("run", write_config(text), "--record", tmp_path / "rec")
    assert result.returncode == 1
    assert "component 'a' did not join within 2 s (run.join_timeout)" in result.stderr, result.stderr
    assert "Traceback" not in result.stderr


def test_a_joined_component_gives_up_when_its_orchestrator_is_gone(write_config, tmp_path):
    """kill -9 of the orchestrator: the joined component tries to reach the run again for
    run.join_timeout, then exits 1 saying so."""
    record = tmp_path / "rec"
    run = start_run(write_config(chain(name="gone", duration="600 s", realtime=1.0, join_timeout="3 s")), record)
    joined = None
    try:
        joined = join(join_file(record))
        wait_for_step("gone", 20, run=run)
        run.send_signal(signal.SIGKILL)
        run.wait(timeout=30)
        _, err = joined.communicate(timeout=120)
    finally:
        for p in (run, joined):
            if p is not None and p.poll() is None:
                p.kill()
    assert joined.returncode == 1, err
    assert "lost the run 'gone'" in err and "cannot reach the run 'gone'" in err, err


def test_the_join_file_of_a_run_that_ended_says_it_is_not_alive(write_config, tmp_path):
    """A run stopped (SIGINT) before its external component joined: its join file then finds
    nothing listening where the run was, and `orchestrator join` ends (exit 1) saying the run is not
    alive, told apart from a run out of reach (issue 34). A copy readable by others is refused
    before anything else (exit 2), with the chmod that fixes it."""
    record = tmp_path / "rec"
    run = start_run(write_config(chain(name="ended", duration="600 s", realtime=1.0, join_timeout="300 s")), record)
    try:
        path = join_file(record)
        copy = tmp_path / "a.join"
        copy.write_bytes(path.read_bytes())
        copy.chmod(0o600)
        run.send_signal(signal.SIGINT)
        run.wait(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
    joined = join(copy)
    _, err = joined.communicate(timeout=120)
    assert joined.returncode == 1, err
    assert "the run 'ended' at " in err and "is not alive: nothing has listened there for 10 s" in err, err
    copy.chmod(0o644)
    shared = join(copy)
    _, err = shared.communicate(timeout=60)
    assert (
        shared.returncode == 2 and "readable or writable by others (mode 644)" in err and f"chmod 600 {copy}" in err
    ), err
