"""Assembling the recorded rows (orchestrator/run/rows.py) from the batches members send, no bus."""

from __future__ import annotations

import numpy as np
import pytest

from components import bus
from orchestrator.config.load import load
from orchestrator.run.members import Member
from orchestrator.run.rows import Rows

CONFIG = """
run: {name: rows, epoch: 2022-09-18T12:00:00Z, duration: 1 s, step: 10 ms}
components:
  fast: {type: test.integrator, parameters: {x0: 0.5}}
  slow: {type: test.counter, step: 30 ms}
"""


class Sink:
    """A recording, or a table, that keeps what it is given: a row given with a table goes to that
    table, as the recording's writer hands it on."""

    def __init__(self):
        self.rows: list[tuple[int, float, list[float]]] = []

    def append(self, k: int, t: float, values: np.ndarray, table: Sink | None = None) -> None:
        (table or self).rows.append((k, t, values.tolist()))


@pytest.fixture
def setup(tmp_path):
    path = tmp_path / "rows.yaml"
    path.write_text(CONFIG)
    config = load(path)
    rows = Rows(config.components.values(), config.step_ns)
    members = {}
    for name, spec in config.components.items():
        member = members[name] = Member(
            spec=spec,
            generation=0,
            process=None,
            log_path=None,
            ratio=spec.step_ns // config.step_ns,
            latest=spec.outputs.start_vector(),
        )
        member.out_dst, member.out_src = rows.placement(spec)
    rows.recording = Sink()
    return rows, members


def receive(member: Member, tags: list[int], outputs: list[list[float]]) -> None:
    member.received.extend(zip(tags, np.array(outputs, dtype=float)))


def test_columns_follow_the_config_and_start_at_the_start_values(setup):
    rows, _ = setup
    assert rows.columns == ["fast.x", "fast.u_time", "slow.n"]
    assert rows.column_index["slow", "n"].tolist() == [2]
    assert rows.values.tolist() == [0.5, 0.0, 0.0]


def test_a_row_is_recorded_once_every_member_has_sent_its_outputs_for_it(setup):
    rows, members = setup
    fast, slow = members["fast"], members["slow"]
    receive(fast, [1, 2, 3, 4, 5], [[10, 0.01], [20, 0.02], [30, 0.03], [40, 0.04], [50, 0.05]])
    rows.advance(members, horizon=6)
    # slow (every 3 steps) holds its start value until its tag 3 arrives
    assert [(k, v) for k, _, v in rows.recording.rows] == [(1, [10, 0.01, 0]), (2, [20, 0.02, 0])]
    receive(slow, [3, 6], [[1], [2]])
    rows.advance(members, horizon=6)
    assert [(k, v) for k, _, v in rows.recording.rows[2:]] == [
        (3, [30, 0.03, 1]),
        (4, [40, 0.04, 1]),
        (5, [50, 0.05, 1]),
    ]
    assert rows.row == 5 and (fast.tag, slow.tag) == (5, 3) and [t for t, _ in slow.received] == [6]
    receive(fast, [6, 7], [[60, 0.06], [70, 0.07]])
    rows.advance(members, horizon=6)  # tag 7 is there, but row 7 is not granted yet
    assert rows.row == 6 and rows.recording.rows[-1] == (6, pytest.approx(0.06), [60, 0.06, 2])
    assert rows.values.tolist() == [60, 0.06, 2] and [t for t, _ in fast.received] == [7]


def test_rows_go_to_the_tables_of_swapped_in_types_and_every_nth_to_the_viewer(setup):
    rows, members = setup
    table, signals = Sink(), []
    rows.tables["slow"] = table
    rows.signals, rows.decimation = signals.append, 2
    receive(members["fast"], [1, 2, 3], [[1, 0], [2, 0], [3, 0]])
    receive(members["slow"], [3], [[7]])
    rows.advance(members, horizon=3)
    assert [(k, v) for k, _, v in table.rows] == [(1, [0]), (2, [0]), (3, [7])]
    assert len(signals) == 1
    k, t = bus.SIGNALS_HEADER.unpack_from(signals[0])
    assert (k, t) == (2, 0.02)
    assert np.frombuffer(signals[0], offset=bus.SIGNALS_HEADER.size).tolist() == [2, 0, 0]


def test_a_swapped_in_type_fills_only_the_columns_it_shares(setup, tmp_path):
    rows, _ = setup
    path = tmp_path / "other.yaml"
    path.write_text(CONFIG.replace("test.counter, step: 30 ms", "test.integrator, step: 30 ms"))
    other = load(path).components["slow"]  # outputs x and u_time: no column slow.n
    out_dst, out_src = rows.placement(other)
    assert out_dst.tolist() == [] and out_src.tolist() == []
    out_dst, out_src = rows.placement(load(path).components["fast"])
    assert out_dst.tolist() == [0, 1] and out_src.tolist() == [0, 1]
