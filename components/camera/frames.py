"""Recorded camera frames: ``DIR/frames/<component>/<k>.npz``, written off the stepping thread.

Each frame is an ``.npz`` whose arrays are deflated (zip's deflate at level 1, :func:`write_frame`):
``numpy.load`` reads it as it reads any ``.npz``, bit for bit (lossless), and so it reads the
uncompressed frames of older recordings. A 640x480 frame of the vision capture (rgb8 with pixel
noise, float32 depth) is about 1.15 MB instead of 2.15 MB (benchmarks/bench_frames.py; noise
does not compress, so a noisy image stays near half its size).

:class:`FrameWriter` takes each frame (a dict of arrays) and writes it from a thread of its own
(zlib releases the GIL while it compresses) under a hidden name renamed into place once
complete, so a reader never sees half a file. ``close()`` writes what is queued and joins the
thread: a run that ends (terminate) loses no frame. A write that fails is raised by the next
``put`` or by ``close``, naming the file.
"""

from __future__ import annotations

import os
import queue
import threading
import zipfile
from pathlib import Path

import numpy as np

LEVEL = 1  # deflate level: 6 (numpy's savez_compressed) costs ~3x the time for <1 % fewer bytes here


def frame_path(directory: str | Path, k: int) -> Path:
    """The file of frame ``k`` (the component's k-th step, from 0)."""
    return Path(directory) / f"{k:06d}.npz"


def frame_files(directory: str | Path) -> list[Path]:
    """The complete frame files in ``directory``, in frame order (none if it does not exist)."""
    directory = Path(directory)
    return sorted(p for p in directory.glob("*.npz") if not p.name.startswith(".")) if directory.is_dir() else []


def write_frame(file, arrays: dict[str, np.ndarray], level: int = LEVEL) -> None:
    """``arrays`` as an ``.npz`` (one ``<key>.npy`` member each, deflated) into ``file`` (a path
    or a binary file object)."""
    with zipfile.ZipFile(file, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=level) as archive:
        for key, value in arrays.items():
            with archive.open(f"{key}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)


def read_frame(path: str | Path, keys: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The arrays of a frame file (only ``keys`` of them when given, those it holds: a member not
    asked for is not decompressed). Reads deflated and uncompressed (older) frames alike."""
    with np.load(path, allow_pickle=False) as stored:
        return {key: stored[key] for key in (stored.files if keys is None else keys) if key in stored.files}


class FrameWriter:
    """Writes frames into ``directory`` (created) from a thread; at most ``backlog`` frames wait
    (``put`` blocks beyond: a disk slower than the renderer slows the run rather than filling the
    memory)."""

    def __init__(self, directory: str | Path, backlog: int = 8):
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.queue: queue.Queue = queue.Queue(maxsize=backlog)
        self.error: Exception | None = None
        self.thread = threading.Thread(target=self._run, name="frame-writer", daemon=True)
        self.thread.start()

    def put(self, k: int, arrays: dict[str, np.ndarray]) -> None:
        self._raise()
        self.queue.put((k, arrays))

    def close(self) -> None:
        if self.thread.is_alive():
            self.queue.put(None)
            self.thread.join()
        self._raise()

    def _raise(self) -> None:
        if self.error is not None:
            error, self.error = self.error, None
            raise error

    def _run(self) -> None:
        while True:
            item = self.queue.get()
            if item is None:
                return
            k, arrays = item
            path = frame_path(self.directory, k)
            hidden = path.with_name(f".{path.name}.part")
            try:
                with open(hidden, "wb") as f:
                    write_frame(f, arrays)
                os.replace(hidden, path)
            except OSError as e:
                self.error = OSError(f"cannot write camera frame {path}: {e}")
