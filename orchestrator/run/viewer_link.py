"""The run's side of the live viewer: the signals publisher (rows, and the end of the run) and the
observer process (components/viewer/observer.py for Rerun, components/viewer/foxglove_observer.py
for Foxglove), started and stopped with the run."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

from components import bus
from components.constants import NS_PER_S
from orchestrator.run import supervisor
from orchestrator.config.specs import RunConfig, ViewerSpec
from orchestrator.run.control import StopRequested, raise_stop
from orchestrator.run.members import Wait


class ViewerLink:
    """``signals``: the publisher of the rows for observers (any run has one; it may drop)."""

    def __init__(self, spec: ViewerSpec | None, session, run_id: str):
        self.spec = spec
        self.process: subprocess.Popen | None = None
        self.signals = bus.publisher(session, bus.signals_key(run_id), drop=True)

    def start(self, config: RunConfig, columns: list[str], *, setup, endpoint: str, run_id: str, env: dict,
              cpus: frozenset[int], wait: Wait, frames_dir: Path | None = None) -> int:
        """Start the observer, if asked (setup file at ``setup``), and wait for its liveliness
        token; return the decimation (publish every n-th row), or 0."""
        if self.spec is None:
            return 0
        setup.write_text(json.dumps({
            "columns": columns, "config": config.resolved, "step_ns": config.step_ns,
            "config_dir": str(config.path.parent.resolve()), "epoch": config.epoch,
            "mode": self.spec.mode, "file": str(self.spec.file) if self.spec.file else None,
            "open_browser": self.spec.open_browser, "port": self.spec.port,
            "frames_dir": str(frames_dir) if frames_dir else None,   # the cameras' images (with --record)
            "linger": sys.stdin.isatty()}))   # foxglove: keep serving after the run (stop() waits for it)
        module = "components.viewer.foxglove_observer" if self.spec.mode == "foxglove" else "components.viewer.observer"
        self.process = subprocess.Popen(
            [sys.executable, "-m", module, "--connect", endpoint,
             "--run-id", run_id, "--setup", str(setup)],
            stdin=subprocess.DEVNULL, preexec_fn=supervisor.child_setup, env=env)
        supervisor.keep_to(cpus, self.process.pid)
        wait({bus.VIEWER: "alive"}, config.start_timeout_s, "viewer start-up")
        return max(1, round(NS_PER_S / (self.spec.rate_hz * config.step_ns)))

    def exited(self) -> str | None:
        """Why the run cannot start, if the observer has exited."""
        if self.process.poll() is not None:
            return f"the viewer exited during start-up with code {self.process.returncode} (see its message above)"
        return None

    def stop(self, interrupted: bool, out) -> None:
        """Tell the observer the run is over and let it finish (flush the .rrd; web, foxglove: until Ctrl-C)."""
        if self.process is None:
            return
        self.signals.put(bus.SIGNALS_END)
        if interrupted and self.spec.mode == "foxglove":
            self.process.terminate()   # it would linger for the user, who asked to stop
        try:
            if self.spec.mode in ("web", "foxglove") and sys.stdin.isatty() and not interrupted:
                print(f"run finished; the {self.spec.mode} viewer stays up until Ctrl-C", file=out, flush=True)
                # the clean-up ignores signals; this one wait is what Ctrl-C (or SIGTERM) is for
                signal.signal(signal.SIGINT, signal.default_int_handler)
                signal.signal(signal.SIGTERM, raise_stop)
                try:
                    self.process.wait()
                finally:
                    signal.signal(signal.SIGINT, signal.SIG_IGN)
                    signal.signal(signal.SIGTERM, signal.SIG_IGN)
            else:
                self.process.wait(timeout=30)
        except (KeyboardInterrupt, StopRequested, subprocess.TimeoutExpired):
            pass
        if self.process.poll() is None:
            self.process.terminate()
            supervisor.reap(self.process, 5)
