"""Noise models shared by the sensor components: plain numpy, no bus, no I/O, no wall clock.

- :class:`NormalStream`: standard normal draws from numpy's PCG64 seeded with an integer. Its
  state (the 128-bit PCG64 state and increment, as uint64 words) is part of the component state,
  so a restored component draws exactly what the original would have.
- :func:`white`: white noise, sigma times a standard normal draw, per sample.
- :class:`BiasRandomWalk`: a bias that starts at a value and takes a normal increment per sample.
- :class:`LatencyBuffer`: a FIFO delaying samples (each with the time it was taken) by a whole
  number of samples; :func:`latency_samples` turns a latency in ns into that number.
- :func:`quat_multiply`, :func:`quat_exp`, :func:`perturb_quaternion`: small-angle rotation noise,
  ``q_noisy = q * exp(phi)``, quaternions [x, y, z, w] (docs/design.md §2).

Determinism: every sample draws the same fixed number of normals, in a fixed order, whatever the
sigmas (a sigma of 0 scales its draws to 0): the noise of the k-th sample depends only on the
seed and k, and the same seed with other sigmas gives the same draws, scaled.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from typing import Any

import numpy as np

from components.errors import ConfigError
from components.units import duration_text

_MASK64 = (1 << 64) - 1


class NormalStream:
    """Standard normal draws from ``numpy.random.Generator(PCG64(seed))`` (an integer seed, or a
    ``SeedSequence`` spawned from one)."""

    def __init__(self, seed: int | np.random.SeedSequence):
        self.rng = np.random.Generator(np.random.PCG64(seed))

    def draw(self, n: int) -> np.ndarray:
        """The next ``n`` standard normal numbers (float64)."""
        return self.rng.standard_normal(n)

    def get_state(self) -> np.ndarray:
        """The generator's state as 6 uint64 words: PCG64 state (high, low), increment (high,
        low), has_uint32, uinteger. Exact: :meth:`set_state` continues the same sequence."""
        s = self.rng.bit_generator.state
        state, inc = int(s["state"]["state"]), int(s["state"]["inc"])
        return np.array(
            [state >> 64, state & _MASK64, inc >> 64, inc & _MASK64, int(s["has_uint32"]), int(s["uinteger"])],
            dtype=np.uint64,
        )

    def set_state(self, words: Any) -> None:
        words = np.asarray(words)
        if words.shape != (6,) or words.dtype != np.uint64:
            raise ValueError(f"noise generator state: expected 6 uint64 words, got {words.dtype} {words.shape}")
        w = [int(x) for x in words]
        self.rng.bit_generator.state = {
            "bit_generator": "PCG64",
            "state": {"state": (w[0] << 64) | w[1], "inc": (w[2] << 64) | w[3]},
            "has_uint32": w[4],
            "uinteger": w[5],
        }


def per_axis(value: Any, n: int = 3) -> np.ndarray:
    """One number for every axis, or n numbers, as a new float64 array of n."""
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy()


def white(sigma: np.ndarray, z: np.ndarray) -> np.ndarray:
    """White noise of standard deviation ``sigma`` (per axis, per sample) from normal draws ``z``."""
    return sigma * z


class BiasRandomWalk:
    """A bias b that starts at ``initial`` and takes an increment ``step_sigma * z`` per sample:
    b_{k+1} = b_k + step_sigma z_k (``step_sigma`` 0: a constant bias)."""

    def __init__(self, initial: np.ndarray, step_sigma: np.ndarray):
        self.bias = np.array(initial, dtype=np.float64)
        self.step_sigma = np.array(step_sigma, dtype=np.float64)

    def advance(self, z: np.ndarray) -> None:
        self.bias = self.bias + self.step_sigma * z


def latency_samples(latency_ns: int, step_ns: int, key: str = "latency") -> int:
    """The number of samples of ``step_ns`` in ``latency_ns``; ConfigError naming ``key`` when it
    is not a whole non-negative number."""
    if latency_ns < 0 or latency_ns % step_ns:
        raise ConfigError(
            key,
            f"must be a non-negative integer multiple of the component's step "
            f"({duration_text(step_ns)}: its `step:` in the config, run.step by default), "
            f"got {duration_text(latency_ns) if latency_ns >= 0 else f'{latency_ns} ns'}",
        )
    return latency_ns // step_ns


class LatencyBuffer:
    """A FIFO of samples (time taken in ns, ``width`` values) that gives each sample back
    ``delay`` pushes later: ``push`` returns the sample pushed ``delay`` pushes before (the one
    just pushed when ``delay`` is 0), or None while the pipeline fills. ``delay`` is None until
    set (a component learns its step at its first step)."""

    def __init__(self, width: int):
        self.width = width
        self.delay: int | None = None
        self.samples: deque[tuple[int, np.ndarray]] = deque()

    def push(self, t_ns: int, values: np.ndarray) -> tuple[int, np.ndarray] | None:
        if self.delay is None:
            raise RuntimeError("LatencyBuffer.push before its delay is set")
        self.samples.append((int(t_ns), np.array(values, dtype=np.float64).reshape(self.width)))
        return self.samples.popleft() if len(self.samples) > self.delay else None

    def get_state(self, prefix: str) -> dict[str, np.ndarray | np.int64]:
        values = np.array([v for _, v in self.samples], dtype=np.float64).reshape(-1, self.width)
        return {
            f"{prefix}delay": np.int64(-1 if self.delay is None else self.delay),
            f"{prefix}times": np.array([t for t, _ in self.samples], dtype=np.int64),
            f"{prefix}values": values,
        }

    def set_state(self, state: Mapping[str, Any], prefix: str) -> None:
        delay = int(state[f"{prefix}delay"])
        times = np.asarray(state[f"{prefix}times"], dtype=np.int64).reshape(-1)
        values = np.asarray(state[f"{prefix}values"], dtype=np.float64).reshape(-1, self.width)
        if len(times) != len(values) or (delay >= 0 and len(times) > delay) or (delay < 0 and len(times)):
            raise ValueError(
                f"latency buffer state: {len(times)} times and {len(values)} samples for a delay of {delay}"
            )
        self.delay = None if delay < 0 else delay
        self.samples = deque((int(t), v.copy()) for t, v in zip(times, values))


# --------------------------------------------------------------------------- rotation noise


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The Hamilton product a b of quaternions [x, y, z, w]: q_A_C = q_A_B q_B_C."""
    ax, ay, az, aw = (float(v) for v in a)
    bx, by, bz, bw = (float(v) for v in b)
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def quat_exp(phi: np.ndarray) -> np.ndarray:
    """The unit quaternion [x, y, z, w] of the rotation vector ``phi`` (axis times angle, rad)."""
    x, y, z = (float(v) for v in phi)
    angle = math.sqrt(x * x + y * y + z * z)
    half = 0.5 * angle
    # sin(a/2)/a, with its series near 0 (accurate to rounding below 1e-4 rad)
    s = math.sin(half) / angle if angle > 1e-4 else 0.5 - angle * angle / 48.0
    return np.array([s * x, s * y, s * z, math.cos(half)])


def normalized(q: np.ndarray, name: str = "quaternion") -> np.ndarray:
    """q / |q|; ValueError naming ``name`` when q is not a rotation (zero or not finite)."""
    q = np.asarray(q, dtype=np.float64)
    norm = float(np.linalg.norm(q))
    if not (math.isfinite(norm) and norm > 1e-12):
        raise ValueError(f"{name} {q.tolist()} is not a rotation (norm {norm:g})")
    return q / norm


def perturb_quaternion(q: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """``q * exp(phi)`` normalized: q rotated by the small rotation ``phi`` (rad) about axes of
    the frame q's second index names (q_A_B * exp(phi): phi in B)."""
    return normalized(quat_multiply(q, quat_exp(phi)))
