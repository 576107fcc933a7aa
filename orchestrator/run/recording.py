"""Recording (docs/design.md §6): signals.parquet in chunks, events.jsonl, config.yaml.

``signals.parquet`` is a Parquet dataset directory: one complete part file per ``chunk_rows``
rows (by count, so two runs of one config end with identical files), each written under a hidden
name, fsynced and renamed into place. The unfinished chunk is made durable too, at least every
``flush_s`` seconds of wall time (``run.record_flush``, 1 s by default): the rows so far are
written as that part, replaced as it grows. Whatever stops the run (a kill -9, a power cut, a
full disk), what is on disk reads with pyarrow and pandas (``pandas.read_parquet(DIR /
"signals.parquet")``) and lacks at most the rows of the last ``flush_s``; a failed write leaves
no partial file and its error names the path and the rows kept.

A run's loop never waits on the disk: :class:`Recording` hands its rows to a writer thread, which
runs the tables' writes in order; the loop hears a write's error at its next row, or at the end.
"""

from __future__ import annotations

import json
import os
import queue
import shutil
import threading
import time
from pathlib import Path

import numpy as np
import yaml


class RecordingError(Exception):
    """The recording cannot be written (its directory removed, the disk full, ...)."""


# The lock of a recording directory: a live run holds an flock on it (see ``claim_directory``).
LOCK_FILE = ".lock"
# What a run (and `orchestrator plot`) leaves in a recording directory: all that --overwrite removes.
RECORDING_ENTRIES = frozenset(
    {
        "signals.parquet",
        "swaps",
        "events.jsonl",
        "config.yaml",
        "logs",
        "plots",
        "frames",
        "ros2.report.json",
        LOCK_FILE,
    }
)


def _holder(lock) -> str:
    """Who holds a lock file, from what it says: 'run NAME (pid P, started ...)'."""
    try:
        lock.seek(0)
        info = json.loads(lock.read() or "{}")
    except (OSError, ValueError):
        info = {}
    if not info:
        return "another run"
    return f"run {info.get('run', '?')} (pid {info.get('pid', '?')}, started {info.get('started', '?')})"


def claim_directory(directory: Path, overwrite: bool, run: str = "") -> object:
    """Make ``directory`` ready for a new recording: create it, or, with ``overwrite``, empty an
    earlier recording there; lock it for this run. RecordingError for a directory a live run
    records into (``overwrite`` or not), for one in use without ``overwrite``, and for one holding
    anything a run does not write (``overwrite`` never deletes a user's own files).

    Returns the lock: an open file ``DIR/.lock`` with an exclusive ``flock`` on it, naming
    ``run`` and this process. Keep it open for the run's life: the kernel drops the lock when
    the process ends, however it ends, so a crashed run never blocks the directory."""
    import datetime
    import fcntl

    if directory.exists() and not directory.is_dir():
        raise RecordingError(f"--record {directory}: exists and is not a directory")
    directory.mkdir(parents=True, exist_ok=True)
    lock = open(directory / LOCK_FILE, "a+")  # noqa: SIM115 (held, locked, for the whole run)
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _holder(lock)
        lock.close()
        raise RecordingError(
            f"--record {directory}: {holder} is recording into this directory now; "
            f"give another directory (it stays locked until that run ends)"
        ) from None
    try:
        entries = sorted(e for e in directory.iterdir() if e.name != LOCK_FILE)
        if entries and not overwrite:
            raise RecordingError(
                f"--record {directory}: the directory is in use (it holds "
                f"{', '.join(e.name for e in entries[:4])}{', ...' if len(entries) > 4 else ''}); "
                f"give another directory, or --overwrite to replace the recording there"
            )
        foreign = [e.name for e in entries if e.name not in RECORDING_ENTRIES]
        if foreign:
            raise RecordingError(
                f"--record {directory} --overwrite: the directory holds more than a recording "
                f"({', '.join(foreign[:4])}); not deleting it: give another directory"
            )
        for entry in entries:
            shutil.rmtree(entry) if entry.is_dir() else entry.unlink()
        lock.seek(0)
        lock.truncate()
        lock.write(
            json.dumps(
                {
                    "run": run,
                    "pid": os.getpid(),
                    "started": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
                }
            )
        )
        lock.flush()
    except BaseException:
        lock.close()
        raise
    return lock


class Table:
    """A Parquet dataset directory of rows (step, time, columns...), written in complete parts of
    ``chunk_rows`` rows, each under a hidden name, fsynced and renamed into place; the unfinished
    part is written the same way at least every ``flush_s`` seconds of wall time (a recording's
    durability is not physics: the clock only decides when bytes reach the disk)."""

    def __init__(self, path: Path, columns: list[str], chunk_rows: int, flush_s: float = 1.0):
        import pyarrow as pa
        import pyarrow.parquet

        self.path = path
        self.path.mkdir(parents=True)
        self.columns = columns
        self.schema = pa.schema([("step", pa.int64()), ("time", pa.float64())] + [(c, pa.float64()) for c in columns])
        self._parts: list[tuple[int, int]] = []  # (first step, last step) of each part on disk
        self._steps = np.empty(chunk_rows, dtype=np.int64)
        self._times = np.empty(chunk_rows)
        self._values = np.empty((chunk_rows, len(columns)))
        self._rows = 0
        self._durable = 0  # rows of the unfinished chunk on disk (its part, partial)
        self.flush_s = float(flush_s)
        self._flushed_at = time.monotonic()

    @property
    def rows_kept(self) -> int:
        """Rows on disk: the complete parts and the unfinished one as last written."""
        return sum(last - first + 1 for first, last in self._parts) + self._durable

    def append(self, step: int, time_s: float, values: np.ndarray) -> None:
        i = self._rows
        self._steps[i], self._times[i] = step, time_s
        self._values[i] = values
        self._rows += 1
        if self._rows == len(self._steps):
            self.flush()
        elif time.monotonic() - self._flushed_at >= self.flush_s:
            self._write_part(self._rows, complete=False)

    def flush(self) -> None:
        if self._rows:
            self._write_part(self._rows)
            self._rows = 0

    def rewind(self, step: int) -> None:
        """Forget the rows after ``step`` (a restart goes back there), on disk too."""
        import pyarrow.parquet as pq

        self._rows = int(np.searchsorted(self._steps[: self._rows], step, side="right"))
        if self._durable > self._rows and self._rows:  # the unfinished part on disk holds rows after step
            self._write_part(self._rows, complete=False)
        elif self._durable > self._rows:
            self._remove_partial()
        if self._rows:
            return  # the parts on disk all come before the buffer
        while self._parts and self._parts[-1][0] > step:
            self._remove_last_part()
        if self._parts and self._parts[-1][1] > step:
            table = pq.read_table(self._part_path(len(self._parts) - 1))
            self._remove_last_part()
            steps = table.column("step").to_numpy()
            n = self._rows = int(np.searchsorted(steps, step, side="right"))
            self._steps[:n], self._times[:n] = steps[:n], table.column("time").to_numpy()[:n]
            for j, column in enumerate(self.columns):
                self._values[:n, j] = table.column(column).to_numpy()[:n]
            if n:
                self._write_part(n, complete=False)  # the rows kept stay on disk

    def close(self) -> None:
        self.flush()
        if not self._parts:  # no row at all: still leave a readable, empty table
            self._write_part(0)

    def _remove_partial(self) -> None:
        self._part_path(len(self._parts)).unlink(missing_ok=True)
        self._durable = 0
        _fsync_directory(self.path)

    def _part_path(self, index: int) -> Path:
        return self.path / f"part-{index:06d}.parquet"

    def _remove_last_part(self) -> None:
        self._part_path(len(self._parts) - 1).unlink()
        self._parts.pop()
        _fsync_directory(self.path)

    def _write_part(self, n: int, complete: bool = True) -> None:
        """Rows [0, n) of the buffer as the next part file (renamed into place: atomic); an
        unfinished one (``complete`` False) is replaced by the next write of the same part."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        arrays = [pa.array(self._steps[:n]), pa.array(self._times[:n])]
        arrays += [pa.array(self._values[:n, j]) for j in range(len(self.columns))]
        final = self._part_path(len(self._parts))
        hidden = self.path / f".{final.name}.tmp"  # readers skip names starting with '.'
        try:
            if not self.path.is_dir():  # writes would still succeed, into a directory no one can see
                raise RecordingError(f"cannot write {self.path}: it was removed during the run")
            with open(hidden, "wb") as file:
                pq.write_table(pa.Table.from_arrays(arrays, schema=self.schema), file)
                file.flush()
                os.fsync(file.fileno())  # the data on disk before the name: a power cut leaves no empty part
            os.replace(hidden, final)
            _fsync_directory(self.path)
        except OSError as error:
            hidden.unlink(missing_ok=True)  # no partial file left behind (a full disk, say)
            kept = self.rows_kept
            last = f", to step {self._last_step_kept()}" if kept else ""
            raise RecordingError(
                f"cannot write {self.path}: {error.strerror or error}; the recording keeps {kept} rows{last}"
            ) from None
        self._flushed_at = time.monotonic()
        if complete:
            self._parts.append((int(self._steps[0]), int(self._steps[n - 1])) if n else (0, -1))
            self._durable = 0
        else:
            self._durable = n

    def _last_step_kept(self) -> int:
        return int(self._steps[self._durable - 1]) if self._durable else self._parts[-1][1]


def _fsync_directory(path: Path) -> None:
    directory = os.open(path, os.O_RDONLY)
    try:
        os.fsync(directory)
    finally:
        os.close(directory)


class _Writer:
    """A thread that runs the calls handed to it in order; the first error a call raises
    (RecordingError, or a bug's) is raised to whoever hands over the next call or waits, and the
    calls after it are not run (the loop that handed them stops at that error, as it would have at a
    write of its own)."""

    def __init__(self):
        self._calls: queue.SimpleQueue = queue.SimpleQueue()
        self.error: Exception | None = None
        self._thread = threading.Thread(target=self._run, name="recording", daemon=True)
        self._thread.start()

    def put(self, call, *args) -> None:
        if self.error is not None:
            raise self.error
        self._calls.put((call, args))

    def wait(self) -> None:
        """Until every call handed over is done."""
        done = threading.Event()
        self._calls.put((done.set, None))
        done.wait()
        if self.error is not None:
            raise self.error

    def stop(self) -> None:
        self._calls.put(None)
        self._thread.join()

    def _run(self) -> None:
        while (item := self._calls.get()) is not None:
            call, args = item
            if args is None:  # a wait: answered whatever came before
                call()
            elif self.error is None:
                try:
                    call(*args)
                except Exception as error:  # for the loop to raise: this thread goes on, to answer waits
                    self.error = error


class Recording:
    """A run's recording directory: ``signals.parquet`` (every component's outputs, one row per
    step), ``swaps/<component>.<generation>.parquet`` (the outputs of a type swapped in for
    another, from the swap on), ``events.jsonl`` and the resolved ``config.yaml``. The tables are
    written on a thread of their own (:class:`_Writer`): the rows handed to :meth:`append` are
    copied."""

    def __init__(
        self,
        directory: str | Path,
        columns: list[str],
        resolved_config: dict,
        *,
        chunk_rows: int = 1000,
        flush_s: float = 1.0,
    ):
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        for stale in ("signals.parquet", "swaps", "events.jsonl"):
            path = self.directory / stale
            shutil.rmtree(path) if path.is_dir() else path.unlink(missing_ok=True)
        self.chunk_rows, self.flush_s = chunk_rows, flush_s
        self.write_config(resolved_config)
        self.signals = Table(self.directory / "signals.parquet", columns, chunk_rows, flush_s)
        self.tables = [self.signals]
        self._events = open(self.directory / "events.jsonl", "a")  # noqa: SIM115 (open until close())
        self._writer = _Writer()

    def write_config(self, resolved_config: dict) -> None:
        """(Re)write config.yaml, atomically: a swap during the run adds itself to its events."""
        path = self.directory / "config.yaml"
        hidden = path.with_name(".config.yaml.tmp")
        hidden.write_text(yaml.dump(resolved_config, Dumper=_ConfigDumper, sort_keys=False))
        os.replace(hidden, path)

    def append(self, step: int, time_s: float, values: np.ndarray, table: Table | None = None) -> None:
        """A row of ``table`` (the signals by default); RecordingError for a write that failed before."""
        self._writer.put((table or self.signals).append, step, time_s, values.copy())

    def add_table(self, name: str, columns: list[str]) -> Table:
        """A table of its own, ``swaps/<name>.parquet``, for columns the signals do not have
        (its rows go through :meth:`append`)."""
        table = Table(self.directory / "swaps" / f"{name}.parquet", columns, self.chunk_rows, self.flush_s)
        self.tables.append(table)
        return table

    def rewind(self, step: int) -> None:
        for table in self.tables:
            self._writer.put(table.rewind, step)
        self._writer.wait()

    def event(self, kind: str, **fields) -> None:
        self._events.write(json.dumps({"event": kind, **fields}) + "\n")
        self._events.flush()

    def close(self) -> None:
        """Write what the tables hold and stop the writer; RecordingError for the first write that
        failed (closing still writes what it can, as after a failed write of the loop's own)."""
        writer = self._writer
        earlier, writer.error = writer.error, None
        try:
            for table in self.tables:
                writer.put(table.close)
            writer.wait()
        except RecordingError:
            if earlier is None:
                raise
        finally:
            writer.stop()
            self._events.close()
        if earlier is not None:
            raise earlier


class _ConfigDumper(yaml.SafeDumper):
    """Lists of numbers on one line ([0.0, 0.0, 1.0]), as a person writes vectors in a config."""


def _list(dumper: yaml.SafeDumper, value: list):
    flow = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", value, flow_style=flow)


_ConfigDumper.add_representer(list, _list)
