"""The orchestrator's word on links it refused: a process with the wrong secret or a certificate
not of the run's CA never becomes a link, so only Zenoh's log knows of it. Zenoh logs to this
process's stdout; while a run watches, stdout goes through a pipe whose reader turns Zenoh's
lines about refused links into one warning each (on the run's ``out``) and passes every other
line that is not Zenoh's on to the real stdout."""

from __future__ import annotations

import os
import re
import sys
import threading

# Zenoh's log targets that tell of refused links, and what to read in their lines
FILTER = "zenoh_link_tls::unicast=warn,zenoh_transport::unicast::establishment::accept=debug"
REFUSALS = (
    (re.compile(r"Invalid password"), "wrong secret (user/password)"),
    (
        re.compile(
            r"invalid peer certificate|UnknownIssuer|UnknownCA|BadCertificate|certificate required", re.IGNORECASE
        ),
        "a certificate not of this run's CA, or none",
    ),
)
ZENOH_LINE = re.compile(r"^\S+Z\s+(TRACE|DEBUG|INFO|WARN|ERROR)\b")

_started = False


def refusal(line: str) -> str | None:
    """Why a Zenoh log line says a link was refused, or None."""
    for pattern, why in REFUSALS:
        if pattern.search(line):
            return why
    return None


class LinkWatch:
    """Warn on ``out`` of links refused while it is open (Zenoh's log is set up once per process)."""

    def __init__(self, out):
        global _started
        import zenoh

        self.out = out
        sys.stdout.flush()
        os.environ.setdefault("NO_COLOR", "1")  # plain lines to read
        self.saved = os.dup(1)
        read, write = os.pipe()
        os.dup2(write, 1)
        os.close(write)
        self.reader = threading.Thread(target=self._read, args=(read,), daemon=True)
        self.reader.start()
        if not _started:
            zenoh.init_log_from_env_or(FILTER)
            _started = True

    def _read(self, descriptor: int) -> None:
        with os.fdopen(descriptor, "rb") as lines:
            for raw in lines:
                line = raw.decode(errors="replace")
                if not ZENOH_LINE.match(line):
                    os.write(self.saved, raw)
                elif why := refusal(line):
                    print(f"warning: refused a link to the run's bus: {why}", file=self.out, flush=True)

    def close(self) -> None:
        """Give stdout back (the reader ends with the pipe)."""
        sys.stdout.flush()
        os.dup2(self.saved, 1)
        os.close(self.saved)
