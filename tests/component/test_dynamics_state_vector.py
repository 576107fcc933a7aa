"""A dynamics whose outputs are its bodies' states alone returns them as one vector
(components/dynamics/component.py StateVector): the same numbers, bit for bit, as its outputs by
name, orientations sign-continuous; any other output puts it back on the outputs by name."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from components.testing.harness import Harness
from tests.unit.test_dynamics_engines import circular

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
# two tumbling bodies, one with joints (its q and qd sit between the orientations in the vector)
BODIES = {
    "target": {"urdf": "../models/target.urdf", "frame": "lvlh", "twist": [0, 0, 0, 0.4, -0.3, 0.9]},
    "humanoid": {"urdf": "../models/humanoid_torso.urdf", "position": [5, 0, 0], "twist": [0, 0, 0, -0.5, 0.2, 0.7]},
}


def run(engine: str, by_name: bool, steps: int, **params) -> np.ndarray:
    h = Harness(engine, {"bodies": BODIES, "gravity_gradient": True, **params}, config_dir=CONFIGS)
    if by_name:
        h.component.state_vector = None
    h.inputs.update(circular(0.0))
    h.initialize()
    rows = [h._outputs.copy()]
    for k in range(steps):
        h.inputs.update(circular(k * 0.05))
        h.step(50_000_000)
        rows.append(h._outputs.copy())
    return np.array(rows)


@pytest.mark.parametrize("engine, steps", [("dynamics.pinocchio", 400), ("dynamics.dart", 120)])
def test_the_state_vector_is_the_outputs_by_name_bit_for_bit(engine, steps):
    h = Harness(engine, {"bodies": BODIES}, config_dir=CONFIGS)
    assert h.component.state_vector is not None
    vector, by_name = run(engine, False, steps), run(engine, True, steps)
    assert vector.tobytes() == by_name.tobytes()
    orientation = h.output_layout.offsets["target.orientation"]
    q = vector[:, orientation]
    assert (np.einsum("ij,ij->i", q[1:], q[:-1]) > 0.0).all()  # sign-continuous ...
    assert (q[:, 3] < 0.0).any()  # ... through the turns where w >= 0 would flip it


def test_any_output_besides_the_states_puts_the_outputs_back_by_name():
    for params in ({"link_outputs": True}, {"frame_outputs": True}, {"imu": ["target"]}):
        h = Harness("dynamics.pinocchio", {"bodies": BODIES, **params}, config_dir=CONFIGS)
        assert h.component.state_vector is None, params
