"""Recorded camera frames on disk (components/camera/frames.py) and in the rosbag2 export
(orchestrator/export/rosbag2.py): a frame reads back bit for bit, deflated or stored (older
recordings), and the export reads the frames one at a time, so its memory does not grow with
their number."""

from __future__ import annotations

import io
import tracemalloc
import zipfile

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import yaml

from components.camera.frames import frame_path, read_frame, write_frame
from orchestrator.export.rosbag2 import export_rosbag2

HEIGHT, WIDTH = 240, 320


def _frame(k: int) -> dict[str, np.ndarray]:
    """A frame as sensor.camera records it, of noise (it does not compress: the worst case)."""
    rng = np.random.default_rng(k)
    return {
        "rgb": rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8),
        "depth": rng.random((HEIGHT, WIDTH), dtype=np.float32),
        "K": np.array([[200.0, 0.0, 159.5], [0.0, 200.0, 119.5], [0.0, 0.0, 1.0]]),
        "D": np.zeros(5),
        "T_link_camera": np.eye(4),
        "T_W_camera": np.eye(4),
        "t": np.float64(0.1 * k),
    }


def _recording(directory, frames: int, stored: bool = False):
    """A recording of one camera (no other component) with ``frames`` frames and 11 rows."""
    directory.mkdir(parents=True)
    config = {
        "run": {"name": "frames", "epoch": "2022-09-18T12:00:00Z", "duration": 1.0, "step": 0.1},
        "components": {
            "camera": {
                "type": "sensor.camera",
                "parameters": {
                    "bodies": {},
                    "body": "servicer",
                    "link": "bus",
                    "width": WIDTH,
                    "height": HEIGHT,
                    "fx": 200.0,
                    "fy": 200.0,
                    "cx": 159.5,
                    "cy": 119.5,
                },
            }
        },
    }
    (directory / "config.yaml").write_text(yaml.safe_dump(config))
    pq.write_table(pa.table({"time": np.linspace(0.0, 1.0, 11)}), directory / "signals.parquet")
    (directory / "frames" / "camera").mkdir(parents=True)
    for k in range(frames):
        path = frame_path(directory / "frames" / "camera", k)
        if stored:
            np.savez(path, **_frame(k))  # as recordings before deflate were written
        else:
            write_frame(path, _frame(k))
    return directory


def test_a_frame_reads_back_bit_for_bit_and_deflated():
    frame = _frame(1)
    buffer = io.BytesIO()
    write_frame(buffer, frame)
    buffer.seek(0)
    back = read_frame(buffer)
    assert sorted(back) == sorted(frame)
    for key, value in frame.items():
        assert back[key].dtype == value.dtype and back[key].shape == value.shape, key
        assert back[key].tobytes() == value.tobytes(), key
    with zipfile.ZipFile(io.BytesIO(buffer.getvalue())) as archive:
        assert {info.compress_type for info in archive.infolist()} == {zipfile.ZIP_DEFLATED}
    buffer.seek(0)
    assert sorted(read_frame(buffer, ("t", "absent"))) == ["t"]  # only what is asked, what it holds


def _exported_peak(tmp_path, frames: int) -> tuple[int, dict[str, int]]:
    recording = _recording(tmp_path / f"rec{frames}", frames)
    tracemalloc.start()
    try:
        exported = export_rosbag2(recording, tmp_path / f"bag{frames}", warn=lambda message: None)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return peak, exported.counts


def test_the_exports_memory_does_not_grow_with_the_number_of_frames(tmp_path):
    """Peak memory (tracemalloc, numpy's arrays included) of exporting 6 frames and 24: held in
    memory, the 18 more would add ~18 x 0.5 MB at least; streamed, less than one frame more."""
    frame_bytes = HEIGHT * WIDTH * (3 + 4)  # 0.54 MB: rgb8 + float32 depth
    _exported_peak(tmp_path / "warm", 2)  # imports and the type store, once
    few, counts = _exported_peak(tmp_path, 6)
    many, counts_many = _exported_peak(tmp_path, 24)
    assert counts["/camera/image_raw"] == 6 and counts_many["/camera/image_raw"] == 24
    assert counts_many["/camera/depth/image_raw"] == counts_many["/camera/camera_info"] == 24
    assert many - few < frame_bytes, f"expected the peak to grow by < {frame_bytes} B, got {few} -> {many} B"


def test_an_older_uncompressed_recording_exports_the_same_bag(tmp_path):
    """Frames written uncompressed (before deflate) export to the same bytes as deflated ones."""
    from mcap.reader import make_reader

    bags = []
    for stored in (False, True):
        recording = _recording(tmp_path / f"rec{stored}", 3, stored=stored)
        export_rosbag2(recording, tmp_path / f"bag{stored}", warn=lambda message: None)
        with open(next((tmp_path / f"bag{stored}").glob("*.mcap")), "rb") as f:
            bags.append(
                [
                    (channel.topic, message.log_time, message.data)
                    for _, channel, message in make_reader(f).iter_messages()
                ]
            )
    assert len(bags[0]) == 11 + 3 * 3 and bags[0] == bags[1]
    images = [data for topic, _, data in bags[0] if topic == "/camera/image_raw"]
    assert images[2].endswith(_frame(2)["rgb"].tobytes())  # CDR: the data array last, as rendered
