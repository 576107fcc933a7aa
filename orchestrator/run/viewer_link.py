"""The run's side of the live views: the signals publisher (rows, and the end of the run) and the
observer processes reading it, started and stopped with the run: the viewer
(components/viewer/observer.py for Rerun, components/viewer/foxglove_observer.py for Foxglove) and
the ROS 2 view (components/ros2/observer.py, ``--ros2``)."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
from pathlib import Path

from components import bus
from components.constants import NS_PER_S
from components.ros2 import stream_report
from orchestrator.config.specs import Ros2Spec, RunConfig, ViewerSpec
from orchestrator.run import supervisor
from orchestrator.run.control import StopRequested, raise_stop
from orchestrator.run.members import Wait


class ViewerLink:
    """``signals``: the publisher of the rows for observers (any run has one; it may drop)."""

    def __init__(self, spec: ViewerSpec | None, session, run_id: str, ros2: Ros2Spec | None = None):
        self.spec = spec
        self.ros2 = ros2
        self.process: subprocess.Popen | None = None  # the viewer's
        self.ros2_process: subprocess.Popen | None = None
        self.ros2_report: Path | None = None  # where the ROS 2 view writes what it delivered
        self.rows_sent = 0
        self._signals = bus.publisher(session, bus.signals_key(run_id), drop=True)

    def signals(self, payload: bytes) -> None:
        """Send the observers a row (counted: the ROS 2 view's report says how many arrived)."""
        self.rows_sent += 1
        self._signals.put(payload)

    def _spawn(self, module: str, endpoint: str, run_id: str, setup, env: dict, cpus: frozenset[int]):
        process = subprocess.Popen(
            [sys.executable, "-m", module, "--connect", endpoint, "--run-id", run_id, "--setup", str(setup)],
            stdin=subprocess.DEVNULL,
            preexec_fn=supervisor.child_setup,
            env=env,
        )
        supervisor.keep_to(cpus, process.pid)
        return process

    def start(
        self,
        config: RunConfig,
        columns: list[str],
        *,
        setup,
        endpoint: str,
        run_id: str,
        env: dict,
        cpus: frozenset[int],
        wait: Wait,
        frames_dir: Path | None = None,
        record_dir: Path | None = None,
    ) -> int:
        """Start the observers asked for (setup files ``setup`` and ``ros2.json`` beside it) and wait
        for their liveliness tokens; return the decimation (publish every n-th row), or 0.
        ``frames_dir``: the recording's frames/ (the cameras' images), None without --record;
        ``record_dir``: where the ROS 2 view's report goes (else beside ``setup``)."""
        rates, expected = [], {}
        if self.spec is not None:
            self._start_viewer(self.spec, config, columns, setup, endpoint, run_id, env, cpus, frames_dir)
            rates.append(self.spec.rate_hz)
            expected[bus.VIEWER] = "alive"
        if self.ros2 is not None:
            self._start_ros2(self.ros2, config, columns, setup, endpoint, run_id, env, cpus, record_dir)
            rates.append(self.ros2.rate_hz)
            expected[bus.ROS2] = "alive"
        if not expected:
            return 0
        wait(expected, config.start_timeout_s, "viewer start-up")
        return max(1, round(NS_PER_S / (max(rates) * config.step_ns)))

    def _start_viewer(
        self, spec: ViewerSpec, config: RunConfig, columns: list[str], setup, endpoint, run_id, env, cpus, frames_dir
    ) -> None:
        """The viewer's observer (Rerun, or Foxglove), from its setup file ``setup``."""
        setup.write_text(
            json.dumps(
                {
                    "columns": columns,
                    "config": config.resolved,
                    "step_ns": config.step_ns,
                    "config_dir": str(config.path.parent.resolve()),
                    "epoch": config.epoch,
                    "mode": spec.mode,
                    "file": str(spec.file) if spec.file else None,
                    "open_browser": spec.open_browser,
                    "port": spec.port,
                    "frames_dir": str(frames_dir) if frames_dir else None,
                    "linger": sys.stdin.isatty(),
                }
            )
        )  # foxglove: keep serving after the run (stop() waits for it)
        module = "components.viewer.foxglove_observer" if spec.mode == "foxglove" else "components.viewer.observer"
        self.process = self._spawn(module, endpoint, run_id, setup, env, cpus)

    def _start_ros2(
        self, ros2: Ros2Spec, config: RunConfig, columns: list[str], setup, endpoint, run_id, env, cpus, record_dir
    ) -> None:
        """The ROS 2 view's observer, from ``ros2.json`` beside ``setup``; its report goes to
        ``record_dir`` (else beside ``setup``)."""
        ros2_setup = setup.with_name("ros2.json")
        node = "zenorbit_" + re.sub(r"[^A-Za-z0-9_]", "_", config.name)
        self.ros2_report = (record_dir or setup.parent) / stream_report.REPORT
        ros2_setup.write_text(
            json.dumps(
                {
                    "columns": columns,
                    "config": config.resolved,
                    "config_dir": str(config.path.parent.resolve()),
                    "ros2": {
                        "endpoint": ros2.endpoint,
                        "domain_id": ros2.domain_id,
                        "distro": ros2.distro,
                        "topics": ros2.topics,
                        "node": node,
                        "transport": ros2.transport,
                        "python": ros2.python,
                        "why": ros2.why,
                    },
                    "report": str(self.ros2_report),
                }
            )
        )
        self.ros2_process = self._spawn("components.ros2.observer", endpoint, run_id, ros2_setup, env, cpus)

    def exited(self, name: str = bus.VIEWER) -> str | None:
        """Why the run cannot start, if the observer ``name`` (bus.VIEWER, bus.ROS2) has exited."""
        process, what = (self.ros2_process, "the ROS 2 view") if name == bus.ROS2 else (self.process, "the viewer")
        if process is not None and process.poll() is not None:
            return f"{what} exited during start-up with code {process.returncode} (see its message above)"
        return None

    def stop(self, interrupted: bool, out) -> None:
        """Tell the observers the run is over and let them finish (flush the .rrd; web, foxglove:
        until Ctrl-C; ros2: at once)."""
        if self.process is None and self.ros2_process is None:
            return
        self._signals.put(bus.SIGNALS_END)
        if self.ros2_process is not None:
            self._finish(self.ros2_process, interrupted)
        if self.process is None:
            return
        spec = self.spec
        assert spec is not None, "the viewer runs only when asked for"
        if interrupted and spec.mode == "foxglove":
            self.process.terminate()  # it would linger for the user, who asked to stop
        try:
            if spec.mode in ("web", "foxglove") and sys.stdin.isatty() and not interrupted:
                print(f"run finished; the {spec.mode} viewer stays up until Ctrl-C", file=out, flush=True)
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

    def ros2_stream(self) -> tuple[dict, str] | None:
        """After :meth:`stop`: the ROS 2 view's report (for events.jsonl) and its summary line; None
        without a ROS 2 view."""
        if self.ros2_process is None:
            return None
        assert self.ros2_report is not None, "set when the ROS 2 view started"
        report = stream_report.read(self.ros2_report)
        line = stream_report.summary(report, self.rows_sent, self.ros2_process.poll())
        return {**(report or {"report": None}), "rows_sent": self.rows_sent}, line

    @staticmethod
    def _finish(process: subprocess.Popen, interrupted: bool) -> None:
        if interrupted:
            process.terminate()
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            pass
        if process.poll() is None:
            process.terminate()
            supervisor.reap(process, 5)
