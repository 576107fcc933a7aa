"""Where the Rerun data goes: a spawned desktop viewer, the web viewer on localhost, or an .rrd file.

Rerun's usage analytics are switched off here (``analytics_off``) before any viewer starts: Rerun
0.41 has no environment variable or ``rr.init`` option for that. Its native viewer and the SDK's
web-viewer server read ``$XDG_CONFIG_HOME/rerun/analytics.json`` (what ``rerun analytics disable``
writes); we point ``XDG_CONFIG_HOME`` of this process (inherited by a spawned viewer) at a private
directory holding ``analytics_enabled: false``, leaving the user's own Rerun config untouched. The
web viewer (in the browser) skips analytics when opened with ``notebook=true`` in its URL, which
the URL we print carries. ``ZENORBIT_RERUN_ANALYTICS=1`` leaves all of this alone.

Ports: ``ZENORBIT_RERUN_WEB_PORT`` and ``ZENORBIT_RERUN_GRPC_PORT`` fix the web viewer's ports (e.g. for an
SSH tunnel); by default free ports are chosen. ``ZENORBIT_RERUN_SPAWN_PORT`` (default 9876, Rerun's)
is the desktop viewer's.
"""

from __future__ import annotations

import json
import os
import socket
import webbrowser
from pathlib import Path
from urllib.parse import quote

APP_ID = "zenorbit"
MODES = ("spawn", "web", "save")


def analytics_off() -> None:
    """Make Rerun (SDK process and the viewer it spawns) see analytics disabled. Idempotent."""
    if os.environ.get("ZENORBIT_RERUN_ANALYTICS") == "1":
        return
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "zenorbit" / "rerun-config"
    config = base / "rerun" / "analytics.json"
    try:
        config.parent.mkdir(parents=True, exist_ok=True)
        if not config.is_file():
            config.write_text(
                json.dumps(
                    {
                        "analytics_enabled": False,
                        "analytics_id": "zenorbit-disabled",
                        "metadata": {},
                        "config_file_path": str(config),
                        "data_dir_path": str(base / "analytics-data"),
                    }
                )
            )
    except OSError:
        return  # read-only home: nothing we can do without touching the user's config
    os.environ["XDG_CONFIG_HOME"] = str(base)


def spawn_problem() -> str | None:
    """Why ``spawn`` (the desktop viewer) cannot work here, or None: no ``rerun`` executable, or
    Linux without a display (then use ``web`` or ``save:FILE.rrd``)."""
    import shutil
    import sys

    if shutil.which("rerun") is None:
        return "the Rerun viewer executable `rerun` is not on PATH; use web or save:FILE.rrd"
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return "no display here (neither DISPLAY nor WAYLAND_DISPLAY is set); use web or save:FILE.rrd"
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _port(variable: str, default: int | None = None) -> int:
    value = os.environ.get(variable)
    if value:
        return int(value)
    return default if default is not None else free_port()


def web_url(web_port: int, grpc_uri: str) -> str:
    """The address to open: the web viewer, told where the data is (and to skip analytics)."""
    return f"http://127.0.0.1:{web_port}/?url={quote(grpc_uri, safe='')}&notebook=true"


def open_stream(
    mode: str,
    *,
    recording_id: str,
    file: str | Path | None = None,
    blueprint=None,
    open_browser: bool = False,
    name: str | None = None,
):
    """A ``rr.RecordingStream`` sending to ``mode``; returns (stream, URL of the web viewer or None).

    save: ``file`` (.rrd), written as logged and completed by ``close_stream``. spawn: the desktop
    viewer (started if none listens on its port). web: a gRPC server plus the web viewer, both on
    localhost; the data stays in this process (up to Rerun's server memory limit, 1 GiB)."""
    if mode not in MODES:
        raise ValueError(f"viewer mode: expected one of {', '.join(MODES)}, got {mode!r}")
    analytics_off()
    import rerun as rr

    stream = rr.RecordingStream(APP_ID, recording_id=recording_id)
    if name:
        stream.send_recording_name(name)
    url = None
    if mode == "save":
        if not file:
            raise ValueError("viewer mode save needs a file (.rrd)")
        Path(file).parent.mkdir(parents=True, exist_ok=True)
        stream.save(str(file), default_blueprint=blueprint)
    elif mode == "spawn":
        stream.spawn(port=_port("ZENORBIT_RERUN_SPAWN_PORT", 9876), default_blueprint=blueprint)
    else:
        grpc_uri = stream.serve_grpc(grpc_port=_port("ZENORBIT_RERUN_GRPC_PORT"), default_blueprint=blueprint)
        web_port = _port("ZENORBIT_RERUN_WEB_PORT")
        rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=grpc_uri)
        url = web_url(web_port, grpc_uri)
        if open_browser:
            webbrowser.open(url)
    return stream, url


def close_stream(stream) -> None:
    """Flush everything logged and close the sinks (an .rrd gets its footer)."""
    try:
        stream.flush(timeout_sec=30.0)
    finally:
        stream.disconnect()
