"""Recording (docs/design.md §6): signals.parquet in chunks, events.jsonl, config.yaml.

``signals.parquet`` is a Parquet dataset directory: one complete part file per ``chunk_rows``
rows (by count, never by wall time, so two runs of one config write identical files), each
written under a hidden name and renamed into place. Whatever stops the run, a kill -9 or a power
cut included, what is on disk reads with pyarrow and pandas (``pandas.read_parquet(DIR /
"signals.parquet")``) and lacks at most the rows of the unfinished chunk.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import yaml


class RecordingError(Exception):
    """The recording cannot be written (its directory removed, the disk full, ...)."""


# What a run (and `orchestrator plot`) leaves in a recording directory: all that --overwrite removes.
RECORDING_ENTRIES = frozenset({"signals.parquet", "events.jsonl", "config.yaml", "logs", "plots"})


def claim_directory(directory: Path, overwrite: bool) -> None:
    """Make ``directory`` ready for a new recording: create it, or, with ``overwrite``, empty an
    earlier recording there. RecordingError for a directory in use without ``overwrite``, and for
    one holding anything a run does not write (``overwrite`` never deletes a user's own files)."""
    if directory.exists() and not directory.is_dir():
        raise RecordingError(f"--record {directory}: exists and is not a directory")
    entries = sorted(directory.iterdir()) if directory.is_dir() else []
    if entries and not overwrite:
        raise RecordingError(f"--record {directory}: the directory is in use (it holds "
                             f"{', '.join(e.name for e in entries[:4])}{', ...' if len(entries) > 4 else ''}); "
                             f"give another directory, or --overwrite to replace the recording there")
    foreign = [e.name for e in entries if e.name not in RECORDING_ENTRIES]
    if foreign:
        raise RecordingError(f"--record {directory} --overwrite: the directory holds more than a recording "
                             f"({', '.join(foreign[:4])}); not deleting it: give another directory")
    for entry in entries:
        shutil.rmtree(entry) if entry.is_dir() else entry.unlink()
    directory.mkdir(parents=True, exist_ok=True)


class Recording:
    """Appends rows (step, time, signals...) and events to a directory."""

    def __init__(self, directory: str | Path, columns: list[str], resolved_config: dict, *,
                 chunk_rows: int = 1000):
        import pyarrow as pa

        self.directory = Path(directory)
        self.path = self.directory / "signals.parquet"
        self.directory.mkdir(parents=True, exist_ok=True)
        for stale in (self.path, self.directory / "events.jsonl"):
            shutil.rmtree(stale) if stale.is_dir() else stale.unlink(missing_ok=True)
        self.path.mkdir()
        (self.directory / "config.yaml").write_text(yaml.dump(resolved_config, Dumper=_ConfigDumper, sort_keys=False))
        self.columns = columns
        self.schema = pa.schema([("step", pa.int64()), ("time", pa.float64())]
                                + [(c, pa.float64()) for c in columns])
        self._parts = 0
        self._steps = np.empty(chunk_rows, dtype=np.int64)
        self._times = np.empty(chunk_rows)
        self._values = np.empty((chunk_rows, len(columns)))
        self._rows = 0
        self._events = open(self.directory / "events.jsonl", "a")

    def append(self, step: int, time_s: float, values: np.ndarray) -> None:
        i = self._rows
        self._steps[i], self._times[i] = step, time_s
        self._values[i] = values
        self._rows += 1
        if self._rows == len(self._steps):
            self.flush()

    def flush(self) -> None:
        if self._rows:
            self._write_part(self._rows)
            self._rows = 0

    def _write_part(self, n: int) -> None:
        """Rows [0, n) of the buffer as the next complete part file (renamed into place: atomic)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        arrays = [pa.array(self._steps[:n]), pa.array(self._times[:n])]
        arrays += [pa.array(self._values[:n, j]) for j in range(len(self.columns))]
        name = f"part-{self._parts:06d}.parquet"
        hidden = self.path / f".{name}.tmp"          # readers skip names starting with '.'
        try:
            if not self.path.is_dir():   # writes would still succeed, into a directory no one can see
                raise RecordingError(f"cannot write {self.path}: it was removed during the run")
            with open(hidden, "wb") as file:
                pq.write_table(pa.Table.from_arrays(arrays, schema=self.schema), file)
                file.flush()
                os.fsync(file.fileno())       # the data on disk before the name: a power cut leaves no empty part
            os.replace(hidden, self.path / name)
            directory = os.open(self.path, os.O_RDONLY)
            try:
                os.fsync(directory)
            finally:
                os.close(directory)
        except OSError as error:
            raise RecordingError(f"cannot write {self.path}: {error}") from None
        self._parts += 1

    def event(self, kind: str, **fields) -> None:
        self._events.write(json.dumps({"event": kind, **fields}) + "\n")
        self._events.flush()

    def close(self) -> None:
        try:
            self.flush()
            if not self._parts:   # no row at all: still leave a readable, empty table
                self._write_part(0)
        finally:
            self._events.close()


class _ConfigDumper(yaml.SafeDumper):
    """Lists of numbers on one line ([0.0, 0.0, 1.0]), as a person writes vectors in a config."""


def _list(dumper: yaml.SafeDumper, value: list):
    flow = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", value, flow_style=flow)


_ConfigDumper.add_representer(list, _list)
