"""sensor.camera in the harness: its frames on the capture scene (the dynamics' own initial state),
the seeded noise (its spread, replayed bit for bit, restored mid-run), and its outputs."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from components.camera.render import egl_problem
from components.testing.harness import Harness
from tests.conftest import ROOT

pytestmark = pytest.mark.skipif(egl_problem() is not None, reason=f"no EGL here: {egl_problem()}")

CAPTURE = yaml.safe_load((ROOT / "configs" / "capture_tumbling_target.yaml").read_text())
EPOCH = CAPTURE["run"]["epoch"]
CONFIGS = ROOT / "configs"
STEP = 100_000_000  # ns


@pytest.fixture(scope="module")
def truth():
    """The capture scene's orbit and dynamics outputs at t0."""
    orbit = Harness("orbit.kepler", CAPTURE["components"]["orbit"]["parameters"], epoch=EPOCH, config_dir=CONFIGS)
    dynamics = Harness(
        "dynamics.dart", CAPTURE["components"]["dynamics"]["parameters"], epoch=EPOCH, config_dir=CONFIGS
    )
    o = orbit.initialize()
    for key in ("r_eci", "v_eci", "q_eci_lvlh", "w_lvlh"):
        dynamics.inputs[key] = o[key]
    return {**{f"orbit.{k}": v for k, v in o.items()}, **dynamics.initialize()}


def looking_at(direction) -> list[float]:
    """q_link_camera [x, y, z, w] whose z axis points along ``direction`` (link axes)."""
    from scipy.spatial.transform import Rotation

    z = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    return list(Rotation.from_matrix(np.column_stack([x, np.cross(z, x), z])).as_quat())


def camera(truth, frames=None, **changes):
    """A camera on the servicer's bus, 1.1 m out from its centre towards the target, looking at it."""
    from components.rotations import quat_to_matrix

    R_W_bus = quat_to_matrix(truth["servicer.orientation"])
    towards = R_W_bus.T @ (truth["target.position"] - truth["servicer.position"])
    towards /= np.linalg.norm(towards)
    params = {
        "bodies": {"servicer": "../models/capture/servicer.urdf", "target": "../models/capture/target.urdf"},
        "body": "servicer",
        "link": "bus",
        "position": (1.1 * towards).tolist(),
        "orientation": looking_at(towards),
        "width": 160,
        "height": 120,
        "fx": 60.0,
        "fy": 60.0,
        "cx": 79.5,
        "cy": 59.5,
        "near": 0.05,
        "far": 30.0,
        "ambient": 0.2,
        "seed": 7,
        "pixel_noise": 3.0,
        "depth_noise": 0.002,
        **changes,
    }
    h = Harness("sensor.camera", params, epoch=EPOCH, config_dir=CONFIGS, frames=frames)
    for body in ("servicer", "target"):
        for variable in ("position", "orientation", "q"):
            h.inputs[f"{body}.{variable}"] = truth[f"{body}.{variable}"]
    h.inputs["r_eci"] = truth["orbit.r_eci"]
    return h


def frames(h, n):
    """n frames: (rgb, depth) as the component would write them."""
    out = []
    for _ in range(n):
        out.append(h.component.take(h.t_ns, h._input_views()))
        h.step(STEP)
    return out


def test_the_camera_sees_the_target_and_its_noise_has_the_declared_spread(truth):
    """The target fills part of the image; noisy minus clean has the declared 1-sigma (pixels not clipped, depth where hit), 2 %."""
    clean = frames(camera(truth, pixel_noise=0.0, depth_noise=0.0), 1)[0]
    noisy = frames(camera(truth), 1)[0]
    hit = clean["depth"] > 0
    assert 0.02 < hit.mean() < 0.9
    unclipped = (clean["rgb"] > 20) & (clean["rgb"] < 235)
    assert unclipped.sum() > 5000
    pixel_error = noisy["rgb"].astype(float)[unclipped] - clean["rgb"].astype(float)[unclipped]
    # rounding to whole counts adds 1/12 to the variance
    assert np.std(pixel_error) == pytest.approx(np.sqrt(3.0**2 + 1 / 12), rel=0.02)
    assert np.std(noisy["depth"][hit] - clean["depth"][hit]) == pytest.approx(0.002, rel=0.02)
    assert not noisy["depth"][~hit].any()


def test_noise_replays_bit_for_bit_and_a_restored_camera_continues_it(truth):
    a, b = camera(truth), camera(truth)
    first, second = frames(a, 3), frames(b, 3)
    for x, y in zip(first, second):
        assert x["rgb"].tobytes() == y["rgb"].tobytes() and x["depth"].tobytes() == y["depth"].tobytes()
    assert first[0]["rgb"].tobytes() != first[1]["rgb"].tobytes()  # each frame its own noise
    restored = camera(truth)
    restored.t_ns = a.t_ns
    restored.set_state(a.get_state())
    for x, y in zip(frames(a, 2), frames(restored, 2)):
        assert x["rgb"].tobytes() == y["rgb"].tobytes() and x["depth"].tobytes() == y["depth"].tobytes()
    assert a.outputs["frame"] == restored.outputs["frame"] == 5.0
    other_seed = frames(camera(truth, seed=8), 1)[0]
    assert other_seed["rgb"].tobytes() != first[0]["rgb"].tobytes()


def test_a_lens_with_distortion_bends_the_image_and_says_so_in_the_frame(truth):
    pinhole = frames(camera(truth, pixel_noise=0.0), 1)[0]
    D = [-0.05, 0.005, 0.0, 0.0, 0.0]  # a mild barrel over this 106 deg field of view
    bent = frames(camera(truth, pixel_noise=0.0, distortion=D), 1)[0]
    assert np.array_equal(bent["D"], D) and not pinhole["D"].any()
    assert bent["rgb"].shape == pinhole["rgb"].shape
    # barrel: the centre pixel sees the same ray, the image's edges see wider
    assert np.allclose(bent["depth"][59:61, 79:81], pinhole["depth"][59:61, 79:81], rtol=1e-3)
    assert ((bent["depth"] > 0) != (pinhole["depth"] > 0)).sum() > 100


def test_outputs_say_when_the_frame_was_taken_and_whether_it_was_lit(truth):
    h = camera(truth)
    assert h.initialize()["frame"] == 0.0
    h.step(STEP)
    out = h.step(STEP)
    assert out["t_frame"] == 0.1 and out["frame"] == 2.0 and out["lit"] == 1.0
    # the orbit point moved behind the Earth (opposite the Sun): the frame is dark but for the ambient
    from components.camera.sun import SunClock

    h.inputs["r_eci"] = -6778e3 * SunClock(EPOCH).direction(h.t_ns)
    shadowed = h.component.take(h.t_ns, h._input_views())
    assert h.step(STEP)["lit"] == 0.0
    lit = frames(camera(truth, pixel_noise=0.0), 1)[0]
    assert lit["rgb"].max() > 100  # the Sun on some face
    assert shadowed["rgb"].max() <= 0.2 * 255 + 6 * 3.0  # ambient only (and 6 sigma of noise)
    assert not lit["rgb"][lit["depth"] == 0].any()  # black sky


def test_the_frame_outputs_are_the_frames_it_takes(truth):
    """The images a consumer gets on the bus (the frame outputs ``rgb`` and ``depth``) are the
    frames the camera takes, bit for bit; K, D and T_link_camera are its parameters'; before the
    first step the images are zeros."""
    from components.camera.model import mount_transform

    h = camera(truth)
    assert not h.initialize()["t_frame"] and not h.frames["rgb"].any() and not h.frames["depth"].any()
    twin = camera(truth)  # the same seed: the same noise
    expected = frames(twin, 1)[0]
    out = h.step(STEP)
    assert h.frames["rgb"].dtype == np.uint8 and h.frames["rgb"].shape == (120, 160, 3)
    assert h.frames["rgb"].tobytes() == expected["rgb"].tobytes()
    assert h.frames["depth"].dtype == np.float32 and h.frames["depth"].tobytes() == expected["depth"].tobytes()
    assert np.array_equal(out["K"], [[60.0, 0.0, 79.5], [0.0, 60.0, 59.5], [0.0, 0.0, 1.0]])
    assert np.array_equal(out["D"], np.zeros(5))
    assert np.array_equal(out["T_link_camera"], mount_transform(h.params["position"], h.params["orientation"]))
    assert "depth" not in camera(truth, depth=False).frames


def test_the_recorded_frames_are_the_rendered_ones_bit_for_bit_in_fewer_bytes(truth, tmp_path):
    """With --record (``run.frames``) each frame's file reads back as the frame outputs of its step,
    bit for bit, deflated: smaller than the raw arrays even with pixel noise."""
    from components.camera.frames import frame_files, read_frame

    h = camera(truth, frames=tmp_path / "camera")
    h.initialize()
    rendered = []
    for _ in range(3):
        h.step(STEP)
        rendered.append({key: h.frames[key].copy() for key in ("rgb", "depth")})
    h.component.terminate()  # writes what is queued
    files = frame_files(tmp_path / "camera")
    assert [f.name for f in files] == ["000000.npz", "000001.npz", "000002.npz"]
    for path, frame in zip(files, rendered):
        back = read_frame(path)
        for key in ("rgb", "depth"):
            assert back[key].dtype == frame[key].dtype and back[key].tobytes() == frame[key].tobytes(), (path, key)
        raw = sum(back[key].nbytes for key in back)
        assert path.stat().st_size < 0.8 * raw, f"{path}: expected under {0.8 * raw:.0f} B, got {path.stat().st_size}"
