"""The recording's durability (orchestrator/run/recording.py, issue 34): rows reach the disk at least
every run.record_flush of wall time, a full disk keeps every row written before it and leaves
no partial file, and the parts a run ends with do not depend on when the flushes came."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pandas
import pytest

from orchestrator.run.recording import RecordingError, Table

COLUMNS = [f"c{i}" for i in range(40)]


def rows(k: int) -> np.ndarray:
    return np.sin(np.arange(len(COLUMNS)) * 0.1 + k)


def read(path: Path) -> pandas.DataFrame:
    return pandas.read_parquet(path)


def test_rows_are_on_disk_before_their_chunk_is_complete_and_the_end_is_the_same(tmp_path):
    """flush_s = 0 (every row durable at once): after 7 rows of a 5-row chunk, with the table not
    closed (a kill here), the dataset reads 7 rows, the values bit for bit; rewinding to step 3
    leaves 4 on disk. Closed, its part files are byte for byte those of a table that never flushed
    early (flush_s = 1 h): the final layout is by row count alone."""
    eager, lazy = (
        Table(tmp_path / "eager", COLUMNS, 5, flush_s=0.0),
        Table(tmp_path / "lazy", COLUMNS, 5, flush_s=3600.0),
    )
    for k in range(7):
        eager.append(k, k * 0.01, rows(k))
        lazy.append(k, k * 0.01, rows(k))
    assert len(read(tmp_path / "eager")) == 7 and len(read(tmp_path / "lazy")) == 5
    assert eager.rows_kept == 7
    on_disk = read(tmp_path / "eager")
    assert on_disk[COLUMNS].to_numpy().tobytes() == np.array([rows(k) for k in range(7)]).tobytes()
    eager.rewind(3)
    lazy.rewind(3)
    assert list(read(tmp_path / "eager")["step"]) == [0, 1, 2, 3]
    for k in range(4, 12):
        eager.append(k, k * 0.01, rows(k))
        lazy.append(k, k * 0.01, rows(k))
    eager.close()
    lazy.close()
    parts = sorted(p.name for p in (tmp_path / "eager").iterdir())
    assert (
        parts == sorted(p.name for p in (tmp_path / "lazy").iterdir()) == [f"part-00000{i}.parquet" for i in range(3)]
    )
    assert all((tmp_path / "eager" / p).read_bytes() == (tmp_path / "lazy" / p).read_bytes() for p in parts)


@pytest.fixture
def tiny_disk(tmp_path):
    """A 256 KiB tmpfs (a real ENOSPC); skipped where mounting is not allowed."""
    mount = tmp_path / "tiny"
    mount.mkdir()
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mount)], capture_output=True, text=True
    )
    if done.returncode != 0:
        pytest.skip(
            f"cannot mount a tmpfs here ({done.stderr.strip() or done.returncode}): the full-disk test needs root"
        )
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=False)


def test_a_full_disk_keeps_every_row_flushed_and_says_how_many(tiny_disk):
    """Rows of 40 columns into a 256 KiB tmpfs, every row flushed (flush_s = 0), chunks of 1000:
    the disk fills long before a chunk completes; the error names the path, No space left on device
    and the rows kept, which is exactly what the dataset then reads, every value intact; no hidden
    .tmp file is left."""
    table = Table(tiny_disk / "signals.parquet", COLUMNS, 1000, flush_s=0.0)
    with pytest.raises(RecordingError) as caught:
        for k in range(1000):
            table.append(k, k * 0.01, rows(k))
    message = str(caught.value)
    kept = table.rows_kept
    print(message)
    assert message.startswith(
        f"cannot write {tiny_disk / 'signals.parquet'}: No space left on device; the recording "
        f"keeps {kept} rows, to step {kept - 1}"
    )
    assert 0 < kept < 1000
    on_disk = read(tiny_disk / "signals.parquet")
    assert list(on_disk["step"]) == list(range(kept))
    assert on_disk[COLUMNS].to_numpy().tobytes() == np.array([rows(k) for k in range(kept)]).tobytes()
    assert not [p for p in os.listdir(tiny_disk / "signals.parquet") if p.endswith(".tmp")]


def test_plot_and_view_of_a_recording_with_no_rows_say_so(tmp_path):
    """A recording whose run wrote no row (its table closed empty, as a disk full at once leaves
    it): plot and view both say the recording holds no rows, not a missing column."""
    from components.plotting import PlotError
    from components.viewer.replay import ReplayError, replay
    from orchestrator.plots.recording import figures

    record = tmp_path / "rec"
    Table(record / "signals.parquet", COLUMNS, 1000).close()
    (record / "config.yaml").write_text("run: {name: empty, step: 10 ms}\ncomponents: {}\n")
    (record / "events.jsonl").write_text('{"event": "start", "run_id": "empty-1", "config": "c.yaml"}\n')
    with pytest.raises(PlotError, match="the recording holds no rows"):
        figures(record)
    with pytest.raises(ReplayError, match="the recording holds no rows"):
        replay(record, "save", tmp_path / "x.rrd")


def test_a_recording_written_on_its_thread_has_the_parts_a_table_written_in_line_has(tmp_path):
    """A Recording's rows go to disk on its writer thread: 2500 rows of chunks of 1000, rewound to
    step 1800 and carried on to 2600, then closed, give signals.parquet part files byte for byte those
    of a Table written on the caller's thread; a swapped-in type's table too."""
    from orchestrator.run.recording import Recording

    recording = Recording(tmp_path / "threaded", COLUMNS, {"run": {"name": "t"}})
    swap = recording.add_table("b.1", COLUMNS[:3])
    inline = Table(tmp_path / "inline", COLUMNS, 1000)
    inline_swap = Table(tmp_path / "inline_swap", COLUMNS[:3], 1000)
    values = np.empty(len(COLUMNS))
    for k in [*range(2500), *range(1801, 2601)]:
        if k == 1801:
            recording.rewind(1800)
            inline.rewind(1800)
            inline_swap.rewind(1800)
        values[:] = rows(k)  # one buffer, changed after each append: the recording keeps a copy
        recording.append(k, k * 0.01, values)
        recording.append(k, k * 0.01, values[:3], swap)
        inline.append(k, k * 0.01, values)
        inline_swap.append(k, k * 0.01, values[:3])
    recording.close()
    inline.close()
    inline_swap.close()
    for threaded, in_line in [("threaded/signals.parquet", "inline"), ("threaded/swaps/b.1.parquet", "inline_swap")]:
        parts = sorted(p.name for p in (tmp_path / threaded).iterdir())
        assert (
            parts
            == sorted(p.name for p in (tmp_path / in_line).iterdir())
            == [f"part-00000{i}.parquet" for i in range(3)]
        )
        assert all((tmp_path / threaded / p).read_bytes() == (tmp_path / in_line / p).read_bytes() for p in parts)
    assert list(read(tmp_path / "threaded" / "signals.parquet")["step"]) == list(range(2601))


def test_a_full_disk_under_a_recording_is_raised_to_the_loop_with_the_rows_kept(tiny_disk):
    """The writer thread's RecordingError reaches whoever hands it the next row, or closes it: the
    message is the table's (the path, No space left on device, the rows kept), and the dataset
    reads exactly those rows."""
    from orchestrator.run.recording import Recording

    recording = Recording(tiny_disk, COLUMNS, {"run": {"name": "full"}}, flush_s=0.0)
    with pytest.raises(RecordingError) as caught:
        try:
            for k in range(1000):
                recording.append(k, k * 0.01, rows(k))
        finally:
            recording.close()  # raised at a row or not, closing says it
    message = str(caught.value)
    kept = recording.signals.rows_kept
    assert message.startswith(
        f"cannot write {tiny_disk / 'signals.parquet'}: No space left on device; the recording "
        f"keeps {kept} rows, to step {kept - 1}"
    )
    on_disk = read(tiny_disk / "signals.parquet")
    assert list(on_disk["step"]) == list(range(kept))
    assert on_disk[COLUMNS].to_numpy().tobytes() == np.array([rows(k) for k in range(kept)]).tobytes()
