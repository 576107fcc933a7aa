"""The messages ``ros2.bridge`` takes from a ROS 2 node: held per topic as they arrive (from Zenoh's
threads: :meth:`Arrivals.put` only stores and notifies), taken per step (on the component's thread)
by one of two rules, with a wall-clock timeout and an interrupt. No Zenoh, no ROS here.

- ``stamped``: step k takes, on each topic, the message whose header stamp is t_k's ROS time; on a
  topic whose type has no header, the first message that arrived after the step's inputs went out
  (:meth:`Arrivals.expect`), an answer to them. Messages stamped earlier than the step are dropped,
  later ones kept for their step. Nothing by the timeout: :class:`Timeout`, naming the topic.
- ``latest``: step k takes the newest message of each topic, whatever its stamp (or none yet).
"""

from __future__ import annotations

import threading
import time

from components.errors import ComponentError

STAMPED, LATEST = "stamped", "latest"
HELD_PER_TOPIC = 1024  # messages stamped ahead of the step kept per topic (a node far ahead is dropped from)


class Timeout(ComponentError):
    """No message for the step on a topic within the timeout."""


class Interrupted(ComponentError):
    """The run is ending while a step waits (the orchestrator's terminate, or it went away)."""


class Arrivals:
    """What arrived on each of ``topics``: ``stamped`` says, per topic, whether its messages carry a
    header stamp (else they are answers, in arrival order)."""

    def __init__(self, stamped: dict[str, bool]):
        self.stamped = dict(stamped)
        self._lock = threading.Condition()
        self._by_stamp: dict[str, dict[int, object]] = {t: {} for t, s in stamped.items() if s}
        self._answers: dict[str, list] = {t: [] for t, s in stamped.items() if not s}
        self._newest: dict[str, object] = {}
        self._floor: dict[str, int] = {t: -1 for t in stamped}  # stamps below it are stale
        self.dropped: dict[str, int] = {t: 0 for t in stamped}
        self._interrupted = False

    def put(self, topic: str, stamp: int | None, message) -> None:
        """A message (``stamp``: its header stamp, ns; None for a type without a header)."""
        with self._lock:
            self._newest[topic] = message
            if stamp is None:
                self._answers[topic].append(message)
            elif stamp >= self._floor[topic] and len(self._by_stamp[topic]) < HELD_PER_TOPIC:
                self._by_stamp[topic][stamp] = message  # a repeated stamp: the newer message wins
            else:
                self.dropped[topic] += 1
            self._lock.notify_all()

    def expect(self) -> None:
        """The step's inputs are about to go out: what arrived before on a topic without a header
        is not an answer to them (dropped, counted)."""
        with self._lock:
            for topic, answers in self._answers.items():
                self.dropped[topic] += len(answers)
                answers.clear()

    def take_stamped(self, stamp: int, timeout_s: float) -> dict[str, object]:
        """Each topic's message for the step stamped ``stamp`` (ns), waiting up to ``timeout_s``
        (wall clock) for the last of them; :class:`Timeout` naming the first topic still missing."""
        deadline = time.monotonic() + timeout_s
        taken: dict[str, object] = {}
        with self._lock:
            for topic, held in self._by_stamp.items():  # older ones can no longer be taken
                self._floor[topic] = stamp
                stale = [s for s in held if s < stamp]
                for s in stale:
                    del held[s]
                self.dropped[topic] += len(stale)
            while True:
                if self._interrupted:
                    raise Interrupted(f"the run is ending: stopped waiting for {', '.join(self._missing(taken))}")
                for topic in self._missing(taken):
                    if topic in self._by_stamp:
                        if stamp in self._by_stamp[topic]:
                            taken[topic] = self._by_stamp[topic].pop(stamp)
                    elif self._answers[topic]:
                        taken[topic] = self._answers[topic].pop(0)
                missing = self._missing(taken)
                if not missing:
                    return taken
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise Timeout(self._timeout_message(missing[0], stamp, timeout_s))
                self._lock.wait(remaining)

    def take_latest(self) -> dict[str, object]:
        """The newest message of each topic that has had one."""
        with self._lock:
            return dict(self._newest)

    def interrupt(self) -> None:
        """From any thread: a wait under way, and every later one, raises :class:`Interrupted`."""
        with self._lock:
            self._interrupted = True
            self._lock.notify_all()

    @property
    def interrupted(self) -> bool:
        return self._interrupted

    def _missing(self, taken: dict) -> list[str]:
        return [t for t in self.stamped if t not in taken]

    def _timeout_message(self, topic: str, stamp: int, timeout_s: float) -> str:
        when = f"{stamp // 1_000_000_000}.{stamp % 1_000_000_000:09d}"
        if self.stamped[topic]:
            held = sorted(self._by_stamp[topic])
            seen = f"holding stamps {held[0]}..{held[-1]} ns" if held else "holding none ahead of it"
            return (
                f"no message on {topic} stamped {when} (ROS time, s) within {timeout_s:g} s (wait_for: stamped; "
                f"{seen}, {self.dropped[topic]} older dropped); is the node running, and does it stamp its "
                f"answer with the stamp of the inputs it answers?"
            )
        return (
            f"no message on {topic} within {timeout_s:g} s of the inputs stamped {when} (wait_for: stamped; "
            f"its type has no header: the bridge waits for one answer per step); is the node running?"
        )
