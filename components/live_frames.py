"""A component's frame outputs for the live views: one DROP publisher per output on
``v/<name>/<output>``, low priority, and nothing encoded or sent while no view subscribes (the
frame message itself: :func:`components.bus.encode_view_frame`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from components.bus import encode_view_frame, view_key


class LiveFrameSender:
    """A component's frame outputs for the live views (``v/<name>/<output>``): one publisher per
    output, congestion control DROP (a slow or stalled view never holds up a step), and nothing
    encoded or sent while no view subscribes (Zenoh's matching status, kept by a listener)."""

    def __init__(self, session, run_id: str, name: str):
        self.session, self.run_id, self.name = session, run_id, name
        self.publishers: dict[str, Any] = {}  # output -> its Zenoh publisher
        self.listeners: list = []
        self.watched: dict[str, bool] = {}  # output -> a view subscribes (set from Zenoh's thread)

    def declare(self, outputs) -> None:
        """Publishers for ``outputs`` (once each), declared early so that matching is known by the first step."""
        for output in outputs:
            if output in self.publishers:
                continue
            publisher = self.publishers[output] = publisher_for_views(
                self.session, view_key(self.run_id, self.name, output)
            )
            self.listeners.append(
                publisher.declare_matching_listener(
                    lambda status, output=output: self.watched.__setitem__(output, status.matching)
                )
            )
            self.watched[output] = self.watched.get(output, False) or publisher.matching_status.matching

    def send(self, output: str, taken_ns: int, generation: int, tag: int, frame: np.ndarray) -> bool:
        """Send one frame if a view watches ``output``; whether it was sent (handed to Zenoh)."""
        if not self.watched.get(output):
            return False
        import zenoh

        try:
            self.publishers[output].put(encode_view_frame(taken_ns, generation, tag, output, frame))
        except zenoh.ZError:  # a view must never stop a step
            return False
        return True

    def undeclare(self) -> None:
        for declared in (*self.listeners, *self.publishers.values()):
            try:
                declared.undeclare()
            except Exception:  # the session is gone: so are they
                pass
        self.listeners, self.publishers, self.watched = [], {}, {}


def publisher_for_views(session, key: str):
    """DROP (Zenoh waits at most its ``wait_before_drop`` for a full queue), low priority: frames
    for views yield to the step data on every link."""
    import zenoh

    return session.declare_publisher(
        key,
        congestion_control=zenoh.CongestionControl.DROP,
        reliability=zenoh.Reliability.RELIABLE,
        priority=zenoh.Priority.DATA_LOW,
        express=False,
    )
