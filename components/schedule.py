"""Who steps when, and on which inputs: the lockstep rules as pure functions, no processes.

Outputs are *tagged* with the step index of the time they hold: a component's ``initialize``
gives tag 0; stepping ``k`` with ratio ``r`` (its step in run steps) gives tag ``k + r``. A
component with ratio ``r`` steps at every ``k`` with ``k % r == 0``.

Step ``k`` of component ``c`` reads from each source ``s`` the output with tag

    floor(j / r_s) * r_s,   j = k + 1 if Gauss-Seidel and s precedes c in config order, else k

(Jacobi: the values at t_k; Gauss-Seidel: the values at t_(k+1) of those before it; a slower
source holds its last output until its next one is due). Row ``k`` of the recording holds, for
each component, its output with tag ``floor(k / r) * r``.

Because each step consumes exactly the inputs tagged for it, the same config gives the same
numbers whether the components run in one process, one after another, or in parallel processes
that exchange outputs directly (the data dependencies are the barrier).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ALGORITHMS = ("jacobi", "gauss-seidel")


@dataclass(frozen=True)
class Route:
    """Inputs of one consumer fed by one source: ``inputs[dst] = source_outputs[src]``."""

    source: str
    src: np.ndarray  # indices in the source's output vector
    dst: np.ndarray  # indices in the consumer's input vector
    ratio: int  # the source's step in run steps
    ahead: int  # 1: the consumer reads the source's values at t_(k+1) (Gauss-Seidel)

    def tag(self, k: int) -> int:
        """The source output tag read by the consumer's step ``k``."""
        return (k + self.ahead) // self.ratio * self.ratio

    def to_json(self) -> dict:
        return {
            "source": self.source,
            "src": self.src.tolist(),
            "dst": self.dst.tolist(),
            "ratio": self.ratio,
            "ahead": self.ahead,
        }

    @classmethod
    def from_json(cls, data: dict) -> Route:
        return cls(
            data["source"],
            np.asarray(data["src"], dtype=np.int64),
            np.asarray(data["dst"], dtype=np.int64),
            int(data["ratio"]),
            int(data["ahead"]),
        )


def fed_inputs(route: Route, input_offsets: dict[str, slice]) -> list[str]:
    """The consumer's input variables that ``route`` feeds (their values are sampled at
    ``route.tag(k)`` times the run step)."""
    dst = set(route.dst.tolist())
    return [name for name, s in input_offsets.items() if s.start in dst]


def routes(
    consumer: str,
    input_offsets: dict[str, slice],
    connections,
    output_offsets: dict[str, dict[str, slice]],
    ratios: dict[str, int],
    order: list[str],
    algorithm: str,
) -> list[Route]:
    """The routes into ``consumer``, one per source component.

    ``connections`` are (dst component, dst variable, src component, src variable);
    ``output_offsets[source][variable]`` the slice of a variable in its source's output vector.
    """
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}")
    by_source: dict[str, tuple[list, list]] = {}
    for dst, dst_var, src, src_var in connections:
        if dst != consumer or dst_var not in input_offsets:  # not ours, or a frame (frame_routes)
            continue
        d, s = input_offsets[dst_var], output_offsets[src][src_var]
        pair = by_source.setdefault(src, ([], []))
        pair[0].append(np.arange(s.start, s.stop))
        pair[1].append(np.arange(d.start, d.stop))
    result = []
    for source, (src, dst) in by_source.items():
        ahead = int(algorithm == "gauss-seidel" and order.index(source) < order.index(consumer))
        result.append(Route(source, np.concatenate(src), np.concatenate(dst), ratios[source], ahead))
    return result


@dataclass(frozen=True)
class FrameRoute:
    """A frame input of one consumer fed by a frame output of one source; read by tag as a
    :class:`Route` is (a frame travels on its own message, not in the float64 vector)."""

    source: str
    output: str  # the source's frame output
    input: str  # the consumer's frame input
    ratio: int
    ahead: int

    def tag(self, k: int) -> int:
        return (k + self.ahead) // self.ratio * self.ratio


def frame_routes(
    consumer: str, frame_inputs: list[str], connections, ratios: dict[str, int], order: list[str], algorithm: str
) -> list[FrameRoute]:
    """The frame routes into ``consumer`` (its frame inputs named in ``frame_inputs``), one per connection."""
    return [
        FrameRoute(
            src,
            src_var,
            dst_var,
            ratios[src],
            int(algorithm == "gauss-seidel" and order.index(src) < order.index(consumer)),
        )
        for dst, dst_var, src, src_var in connections
        if dst == consumer and dst_var in frame_inputs
    ]


def frame_consumers(name: str, frame_outputs: list[str], connections) -> dict[str, list[str]]:
    """Who gets each of ``name``'s frame outputs: output -> consumers (sorted, itself excluded)."""
    found: dict[str, set[str]] = {}
    for dst, _, src, src_var in connections:
        if src == name and src_var in frame_outputs and dst != name:
            found.setdefault(src_var, set()).add(dst)
    return {output: sorted(consumers) for output, consumers in found.items()}


def is_due(ratio: int, k: int) -> bool:
    """Does a component with this ratio step at run step ``k``?"""
    return k % ratio == 0


def next_due(ratio: int, k: int) -> int:
    """The first step >= k at which a component with this ratio steps."""
    return -(-k // ratio) * ratio


def first_step_at(t_ns: int, step_ns: int) -> int:
    """The first run step at or after time ``t_ns``: the step of an event or a fault at ``t_ns``
    (ceiling division in integers, exact)."""
    return -(-t_ns // step_ns)


def row_tag(ratio: int, row: int) -> int:
    """The output tag of a component with this ratio that row ``row`` of the recording holds."""
    return row // ratio * ratio


def initialization_order(names: list[str], connections) -> list[str]:
    """Sources before the components they feed; config order breaks cycles."""
    feeds = {n: {s for d, _, s, _ in connections if d == n and s != n} for n in names}
    done: list[str] = []
    while len(done) < len(feeds):
        pending = [n for n in feeds if n not in done]
        ready = [n for n in pending if feeds[n] <= set(done)]
        done.append(ready[0] if ready else pending[0])
    return done


def batch_consumers(name: str, connections) -> list[str]:
    """The consumers of ``name`` that are on no loop back to it (a self-connection aside): they
    never hold it up, so it may send them its outputs in batches; the others get every step's."""
    consumers: dict[str, set[str]] = {}
    for d, _, s, _ in connections:
        if d != s:
            consumers.setdefault(s, set()).add(d)

    def reaches(start: str) -> bool:
        seen, stack = set(), [start]
        while stack:
            node = stack.pop()
            if node == name:
                return True
            if node not in seen:
                seen.add(node)
                stack.extend(consumers.get(node, ()))
        return False

    return sorted(c for c in consumers.get(name, ()) if not reaches(c))
