"""The ``viewer.rerun`` observer process: signal rows from the bus into Rerun, live.

    python -m components.viewer.observer --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --setup viewer.json

The orchestrator starts it when a run has a viewer (``--view spawn|web|save:FILE.rrd`` or a
``viewer:`` config section) and writes the setup JSON: ``columns``, ``config`` (resolved),
``config_dir``, ``step_ns``, ``epoch``, ``mode`` (spawn | web | save), ``file``, ``open_browser``.

It runs in the observer shell (components/observer_shell.py): the token goes up at once and
rows wait in the FIFO while Rerun, the URDFs and the Pinocchio models load, so the run does not
wait for that. ``END``: the data is flushed and the process exits, except in web mode where it
keeps serving until SIGINT/SIGTERM or until the orchestrator's token goes away. Rows are logged in
batches (a few per second live, every 2 s when saving: far cheaper per row).
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from components import observer_shell
from components.observer_shell import View, ViewError

if TYPE_CHECKING:
    import rerun as rr

    from components.viewer.scene import SceneLogger

FILE_BATCH_S = 2.0  # save: nobody watches, so larger batches still


class RerunView(View):
    """The rows as Rerun entities (:class:`components.viewer.scene.SceneLogger`), streamed or saved."""

    name = "viewer"
    mesh = False  # no camera frames from the bus: the recording's own, from ``frames_dir``

    def __init__(self, shell):
        super().__init__(shell)
        self.mode, self.file = shell.setup.get("mode", "save"), shell.setup.get("file")
        if self.mode == "save":
            self.batch_s = FILE_BATCH_S
        self.scene: SceneLogger | None = None  # from start on
        self.stream: rr.RecordingStream | None = None
        self.url: str | None = None

    def start(self) -> None:
        from components.viewer.scene import SceneLogger
        from components.viewer.sinks import open_stream, spawn_problem

        shell = self.shell
        setup, config = shell.setup, shell.config
        if self.mode == "spawn" and spawn_problem():
            raise ViewError(f"cannot spawn the desktop viewer: {spawn_problem()}", 1)
        self.scene = SceneLogger(
            shell.columns, config, shell.config_dir, warn=shell.log, frames_dir=setup.get("frames_dir")
        )
        self.stream, self.url = open_stream(
            self.mode,
            recording_id=shell.run_id,
            file=self.file,
            blueprint=self.scene.blueprint(),
            open_browser=bool(setup.get("open_browser")),
            name=(config.get("run") or {}).get("name") or shell.run_id,
        )
        self.scene.rec = self.stream
        self.scene.log_static()
        if self.url:
            self.log(f"Rerun web viewer at {self.url}")

    def step(self, batch) -> None:
        if batch is not None:
            assert self.scene is not None, "the shell starts the view before its steps"
            self.scene.log_rows(*batch)

    def finish(self, ended: bool) -> None:
        assert self.stream is not None, "the shell starts the view before it finishes it"
        self.stream.flush(timeout_sec=30.0)

    def linger(self) -> str | None:
        if self.mode != "web":
            return None
        assert self.scene is not None, "the shell starts the view before it lingers"
        return f"run over ({self.scene.rows_logged} rows); still serving {self.url} until Ctrl-C"

    def close(self, completed: bool) -> None:
        from components.viewer.sinks import close_stream

        if self.stream is not None:
            try:
                close_stream(self.stream)
            except Exception as e:  # a viewer that went away must not turn into a traceback
                self.log(f"closing the Rerun stream: {e}")
        if completed and self.mode == "save" and self.file and self.scene is not None:
            self.log(f"saved {self.scene.rows_logged} rows to {self.file}")


def main(argv: list[str] | None = None) -> int:
    return observer_shell.main(RerunView, argv, "python -m components.viewer.observer", __doc__.splitlines()[0])


if __name__ == "__main__":
    sys.exit(main())
