"""The recorded row: every component's outputs, in config order, one row per step boundary,
assembled from the batches of outputs the members send, and written to the recording, the tables
of swapped-in types, and the viewer."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import cast

import numpy as np

from components import bus
from components.constants import NS_PER_S
from orchestrator.config.specs import ComponentSpec
from orchestrator.run.recording import Recording, Table

_SIGNALS = bus.SIGNALS_HEADER


class Rows:
    """``row``: the last row recorded, the step boundary the run has reached; ``values``: its values.

    The sinks are set by the engine: ``recording`` (or None), ``tables`` (component -> the table of
    its swapped-in type, written with its whole output vector) and ``signals`` (every
    ``decimation``-th row goes there, 0: none).
    """

    def __init__(self, specs: Iterable[ComponentSpec], step_ns: int):
        specs = list(specs)
        self.step_ns = step_ns
        self.columns: list[str] = []
        self.column_index: dict[tuple[str, str], np.ndarray] = {}
        for spec in specs:
            for v in spec.outputs.variables:
                start = len(self.columns)
                self.columns += v.columns(spec.name)
                self.column_index[spec.name, v.name] = np.arange(start, len(self.columns))
        # before initialization every output holds its declared start value
        self.values = np.concatenate([s.outputs.start_vector() for s in specs] or [np.zeros(0)])
        self.row = 0
        self.recording: Recording | None = None
        self.tables: dict[str, Table] = {}
        self.signals: Callable[[bytes], None] | None = None
        self.decimation = 0

    def placement(self, spec: ComponentSpec) -> tuple[np.ndarray, np.ndarray]:
        """(where in the row, from where in its output vector) ``spec``'s outputs go; a swapped-in
        type's outputs that have no column of that name and size are not in the row."""
        out_dst, out_src = [], []
        for v in spec.outputs.variables:
            index = self.column_index.get((spec.name, v.name))
            if index is not None and len(index) == v.size:
                out_dst.append(index)
                out_src.append(np.arange(spec.outputs.offsets[v.name].start, spec.outputs.offsets[v.name].stop))
        return (
            np.concatenate(out_dst) if out_dst else np.zeros(0, dtype=np.int64),
            np.concatenate(out_src) if out_src else np.zeros(0, dtype=np.int64),
        )

    def take(self, member) -> None:
        """Put ``member.latest`` in the row."""
        self.values[member.out_dst] = member.latest[member.out_src]

    def publish(self) -> None:
        """Send the current row to the viewer."""
        assert self.signals is not None, "the engine sets the viewer's sink before it publishes"
        self.signals(_SIGNALS.pack(self.row, self.row * self.step_ns / NS_PER_S) + self.values.tobytes())

    def advance(self, members: dict, horizon: int) -> None:
        """Record every row up to ``horizon`` whose outputs have all arrived (in ``received`` of
        each member: (tag, outputs), tags increasing); each row takes, of each member, the outputs
        tagged with the member's last step at or before it (``ratio``: its step in run steps)."""
        step_ns = self.step_ns
        # set whenever decimation is (by the engine): narrowed once, out of the loop
        signals = cast(Callable[[bytes], None], self.signals)
        listed = list(members.values())
        while self.row < horizon:
            row = self.row + 1
            due = []
            for m in listed:
                need = row // m.ratio * m.ratio
                if need == m.tag:
                    continue
                received = m.received
                while received and received[0][0] < need:
                    received.popleft()
                if not received or received[0][0] != need:
                    return
                due.append(m)
            for m in due:
                m.tag, m.latest = m.received.popleft()
                self.values[m.out_dst] = m.latest[m.out_src]
            self.row = row
            if self.recording is not None:
                self.recording.append(row, row * step_ns / NS_PER_S, self.values)
                for name, table in self.tables.items():
                    self.recording.append(row, row * step_ns / NS_PER_S, members[name].latest, table)
            if self.decimation and row % self.decimation == 0:
                signals(_SIGNALS.pack(row, row * step_ns / NS_PER_S) + self.values.tobytes())

    def new_table(self, member) -> None:
        """From this row on, ``member`` (of a swapped-in type) is also recorded in a table of its own."""
        assert self.recording is not None, "a swapped-in type gets a table only when the run records"
        name = member.name
        self.tables.pop(name, None)
        columns = [c for v in member.spec.outputs.variables for c in v.columns(name)]
        table = self.tables[name] = self.recording.add_table(f"{name}.{member.generation}", columns)
        self.recording.append(self.row, self.row * self.step_ns / NS_PER_S, member.latest, table)

    def rewind(self, row: int, values: np.ndarray) -> None:
        """Back to ``row`` (a checkpoint's), whose values were ``values``."""
        self.values[:] = values
        self.row = row
        if self.recording is not None:
            self.recording.rewind(row)
