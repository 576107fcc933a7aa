"""The sensors' noise models (components/noise.py) against independent references:
numpy's own generator for the seeded stream, the rotation-matrix helpers of components.rotations
for the quaternion product and exponential, closed forms for the random walk and the latency."""

from __future__ import annotations

import math

import numpy as np
import pytest

from components.bus import decode_state, encode_state
from components.errors import ConfigError
from components.noise import (
    BiasRandomWalk,
    LatencyBuffer,
    NormalStream,
    latency_samples,
    normalized,
    per_axis,
    perturb_quaternion,
    quat_exp,
    quat_multiply,
    white,
)
from components.rotations import exp_so3, matrix_to_quat, quat_to_matrix

MS = 1_000_000


def test_stream_is_numpys_pcg64_and_replays_from_its_seed():
    reference = np.random.Generator(np.random.PCG64(42)).standard_normal(30)
    a, b = NormalStream(42), NormalStream(42)
    got = np.concatenate([a.draw(6) for _ in range(5)])
    assert got.tobytes() == reference.tobytes()  # blocks of 6 = one draw of 30, bit for bit
    assert np.concatenate([b.draw(6) for _ in range(5)]).tobytes() == got.tobytes()
    assert not np.array_equal(NormalStream(43).draw(30), reference)


@pytest.mark.parametrize("seed", [0, 7, 2**63 + 12345, 2**100])  # 128-bit PCG64 words survive
def test_stream_state_through_the_bus_encoding_continues_bit_for_bit(seed):
    a = NormalStream(seed)
    a.draw(1001)
    a.rng.integers(0, 10, dtype=np.uint32)  # leaves a buffered uint32 (has_uint32) in the state
    words = a.get_state()
    assert words.dtype == np.uint64 and words.shape == (6,)
    b = NormalStream(999)  # another seed: the state replaces it
    b.set_state(decode_state(encode_state({"rng": words}))["rng"])
    assert b.rng.bit_generator.state == a.rng.bit_generator.state
    assert b.draw(500).tobytes() == a.draw(500).tobytes()
    assert b.rng.integers(0, 2**32, dtype=np.uint32) == a.rng.integers(0, 2**32, dtype=np.uint32)


def test_stream_refuses_a_malformed_state():
    with pytest.raises(ValueError, match="6 uint64 words"):
        NormalStream(1).set_state(np.zeros(5, dtype=np.uint64))
    with pytest.raises(ValueError, match="6 uint64 words"):
        NormalStream(1).set_state(np.zeros(6))


def test_white_noise_and_per_axis():
    assert per_axis(2.0).tolist() == [2.0, 2.0, 2.0]
    assert per_axis([1.0, 2.0, 3.0]).tolist() == [1.0, 2.0, 3.0]
    z = np.random.default_rng(3).standard_normal((20000, 3))
    noise = white(per_axis([0.1, 0.2, 0.0]), z)
    assert np.allclose(noise.std(axis=0), [0.1, 0.2, 0.0], rtol=0.03)


def test_bias_random_walk_is_the_running_sum_of_its_increments():
    z = np.random.default_rng(5).standard_normal((400, 3))
    walk = BiasRandomWalk(per_axis([1.0, -1.0, 0.5]), per_axis(0.01))
    for row in z:
        walk.advance(row)
    assert np.allclose(walk.bias, [1.0, -1.0, 0.5] + 0.01 * z.sum(axis=0), rtol=0, atol=1e-12)
    constant = BiasRandomWalk(per_axis(0.3), per_axis(0.0))
    for row in z:
        constant.advance(row)
    assert constant.bias.tolist() == [0.3] * 3


def test_bias_random_walk_spread_grows_as_the_square_root_of_the_samples():
    """b_N - b_0 over 4000 independent walks of N = 100 samples: std = sigma sqrt(N) (within 5 %:
    4000 walks give a relative standard error of about 1.1 %)."""
    z = np.random.default_rng(11).standard_normal((100, 4000))
    walk = BiasRandomWalk(np.zeros(4000), np.full(4000, 0.02))
    for row in z:
        walk.advance(row)
    assert walk.bias.std() == pytest.approx(0.02 * 10.0, rel=0.05)


def test_latency_samples_counts_whole_steps_and_names_the_key_otherwise():
    assert latency_samples(200 * MS, 10 * MS) == 20
    assert latency_samples(0, 10 * MS) == 0
    with pytest.raises(ConfigError) as error:
        latency_samples(25 * MS, 10 * MS, "latency")
    assert error.value.key == "latency"
    assert (
        "integer multiple of the component's step (10 ms" in error.value.message and "got 25 ms" in error.value.message
    )
    with pytest.raises(ConfigError, match="latency"):
        latency_samples(-10 * MS, 10 * MS)


def test_latency_buffer_gives_each_sample_back_delay_pushes_later():
    buffer = LatencyBuffer(2)
    buffer.delay = 3
    out = [buffer.push(k * MS, [k, -k]) for k in range(8)]
    assert out[:3] == [None, None, None]
    for k in range(3, 8):
        t, values = out[k]
        assert t == (k - 3) * MS and values.tolist() == [k - 3, 3 - k]
    immediate = LatencyBuffer(1)
    immediate.delay = 0
    t, values = immediate.push(5, [1.5])
    assert t == 5 and values.tolist() == [1.5]


def test_latency_buffer_state_round_trip_mid_pipeline():
    a = LatencyBuffer(3)
    a.delay = 4
    for k in range(2):
        a.push(k, [k, k, k])
    state = decode_state(encode_state(a.get_state("x_")))
    b = LatencyBuffer(3)
    b.set_state(state, "x_")
    for k in range(2, 10):
        ra, rb = a.push(k, [k, 2 * k, 3 * k]), b.push(k, [k, 2 * k, 3 * k])
        assert (ra is None and rb is None) or (ra[0] == rb[0] and ra[1].tobytes() == rb[1].tobytes())
    fresh = LatencyBuffer(3)  # never stepped: no delay yet
    fresh.set_state(decode_state(encode_state(LatencyBuffer(3).get_state("x_"))), "x_")
    assert fresh.delay is None and not fresh.samples
    with pytest.raises(RuntimeError):
        fresh.push(0, [0, 0, 0])


def test_quat_exp_matches_rodrigues_including_the_small_angle_series():
    rng = np.random.default_rng(2)
    for scale in (1e-9, 1e-5, 0.99e-4, 1.01e-4, 1e-2, 1.0, 3.0):
        phi = rng.standard_normal(3)
        phi *= scale / np.linalg.norm(phi)
        q = quat_exp(phi)
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
        assert np.allclose(quat_to_matrix(q), exp_so3(phi), rtol=0, atol=1e-15)
        assert q[3] > 0.0 and np.allclose(q[:3] / math.sin(scale / 2), phi / scale, atol=1e-9)


def test_quat_multiply_composes_rotations():
    rng = np.random.default_rng(4)
    for _ in range(20):
        a, b = normalized(rng.standard_normal(4)), normalized(rng.standard_normal(4))
        assert np.allclose(quat_to_matrix(quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-14)
    identity = np.array([0.0, 0.0, 0.0, 1.0])
    assert quat_multiply(identity, a).tolist() == a.tolist()


def test_perturb_quaternion_rotates_about_the_second_frames_axes():
    """q_A_B * exp(phi) = R_A_B exp(phi): phi is in B."""
    q = matrix_to_quat(exp_so3([0.3, -1.2, 0.5]))
    phi = np.array([0.01, 0.02, -0.015])
    noisy = perturb_quaternion(q, phi)
    assert np.allclose(quat_to_matrix(noisy), quat_to_matrix(q) @ exp_so3(phi), atol=1e-14)
    assert np.linalg.norm(noisy) == pytest.approx(1.0, abs=1e-15)


def test_normalized_refuses_what_is_no_rotation():
    assert normalized([0.0, 0.0, 0.0, 2.0]).tolist() == [0.0, 0.0, 0.0, 1.0]
    with pytest.raises(ValueError, match=r"q_true .* is not a rotation"):
        normalized([0.0, 0.0, 0.0, 0.0], "q_true")
    with pytest.raises(ValueError, match="not a rotation"):
        normalized([np.nan, 0.0, 0.0, 1.0])
