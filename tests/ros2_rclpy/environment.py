"""The ROS 2 Jazzy environment the rclpy tests run their nodes in: a venv of its own with the
wheels of ``requirements.txt``, made once and reused (``ZENORBIT_ROS2_VENV``, else
``~/.cache/zenorbit/ros2-jazzy``), rebuilt when the requirements change. ``.ci/run`` makes it
before the suite (``python -m tests.ros2_rclpy.environment``); a test session makes it if it is
missing, under a file lock so two test workers do not both build it.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import subprocess
import sys
from pathlib import Path

REQUIREMENTS = Path(__file__).with_name("requirements.txt")
INSTALL_TIMEOUT_S = 900


def venv_dir() -> Path:
    return Path(os.environ.get("ZENORBIT_ROS2_VENV") or Path.home() / ".cache" / "zenorbit" / "ros2-jazzy")


def ensure() -> Path:
    """The venv's Python, made (or remade) if needed; RuntimeError with pip's last lines if it
    cannot be (no package index reachable, a platform without the wheels)."""
    venv = venv_dir()
    python = venv / "bin" / "python"
    digest = hashlib.sha256(REQUIREMENTS.read_bytes()).hexdigest()
    stamp = venv / "zenorbit-requirements.sha256"
    venv.parent.mkdir(parents=True, exist_ok=True)
    with open(venv.parent / f".{venv.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if python.exists() and stamp.exists() and stamp.read_text() == digest:
            return python
        subprocess.run([sys.executable, "-m", "venv", "--clear", str(venv)], check=True, capture_output=True)
        done = subprocess.run(
            [str(python), "-m", "pip", "install", "-q", "--disable-pip-version-check", "-r", str(REQUIREMENTS)],
            capture_output=True,
            text=True,
            timeout=INSTALL_TIMEOUT_S,
        )
        if done.returncode != 0:
            tail = "\n".join((done.stderr or done.stdout).strip().splitlines()[-5:])
            raise RuntimeError(f"pip could not install the ROS 2 Jazzy wheels into {venv}:\n{tail}")
        check = subprocess.run([str(python), "-c", "import rclpy"], capture_output=True, text=True)
        if check.returncode != 0:
            raise RuntimeError(f"{python} cannot import rclpy after the install: {check.stderr.strip()[-500:]}")
        stamp.write_text(digest)
        return python


if __name__ == "__main__":
    print(ensure())
