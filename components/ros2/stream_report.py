"""What the ROS 2 view delivered: per topic the messages it published and those it dropped,
counted by the observer (components/ros2/observer.py) whatever the transport, written at the end
of the run to ``ros2.report.json`` and read by the orchestrator for events.jsonl (``ros2_stream``)
and the run's summary line."""

from __future__ import annotations

import json
from pathlib import Path

REPORT = "ros2.report.json"
NO_LINK = "no link"  # no link to the ROS side's router: the message goes nowhere
FAILED = "publish failed"  # the publish raised (a dead rclpy process, a closed session)
REASONS = (NO_LINK, FAILED)


class StreamCounts:
    """Counts of one ROS 2 view. ``published``: handed to the transport (what then is lost in
    transit is not seen here); ``dropped``: per topic, and per reason in ``why``."""

    def __init__(self):
        self.published: dict[str, int] = {}
        self.dropped: dict[str, int] = {}
        self.why: dict[str, int] = {}
        self.rows = 0  # rows of the run the view received
        self.links_lost = 0  # times the link to the router went down
        self.links_back = 0  # ... and came back

    def sent(self, topic: str, n: int = 1) -> None:
        self.published[topic] = self.published.get(topic, 0) + n

    def drop(self, topic: str, reason: str, n: int = 1) -> None:
        if reason not in REASONS:
            raise ValueError(f"unknown reason {reason!r}")
        self.dropped[topic] = self.dropped.get(topic, 0) + n
        self.why[reason] = self.why.get(reason, 0) + n

    def as_dict(self) -> dict:
        return {
            "published": dict(sorted(self.published.items())),
            "dropped": dict(sorted(self.dropped.items())),
            "why": dict(sorted(self.why.items())),
            "rows": self.rows,
            "links_lost": self.links_lost,
            "links_back": self.links_back,
        }

    def write(self, path: str | Path) -> None:
        """Whole or not at all: written beside, then renamed (the orchestrator may read it at once)."""
        path = Path(path)
        partial = path.with_name("." + path.name)
        partial.write_text(json.dumps(self.as_dict(), indent=1) + "\n")
        partial.replace(path)


def read(path: str | Path) -> dict | None:
    """The report at ``path``; None if there is none or it is not one."""
    try:
        report = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(report, dict) or not all(isinstance(report.get(k), dict) for k in ("published", "dropped")):
        return None
    return report


def summary(report: dict | None, rows_sent: int, exit_code: int | None = None) -> str:
    """The line a run prints at its end for its ROS 2 view. ``rows_sent``: the rows the orchestrator
    sent the view (every n-th, ros2.rate); ``exit_code``: the observer's, said when there is no report."""
    if report is None:
        code = f" (it exited with code {exit_code})" if exit_code is not None else ""
        return f"ROS 2 view: no report from its process{code}; what it delivered is unknown"
    published, dropped = report["published"], report["dropped"]
    line = (
        f"ROS 2 view: {sum(published.values())} messages published on {len(published)} topics; "
        f"of the {rows_sent} rows sent to it, {report.get('rows', 0)} arrived"
    )
    if not any(dropped.values()):
        return line + "; dropped: none"
    total = sum(dropped.values())
    topics = ", ".join(f"{topic} {n}" for topic, n in sorted(dropped.items(), key=lambda kv: (-kv[1], kv[0])) if n)
    why = ", ".join(f"{reason}: {n}" for reason, n in sorted(report.get("why", {}).items()) if n)
    line += f"; dropped: {total} messages ({topics}; {why})"
    if report.get("links_lost"):
        line += (
            f"; the link to the ROS 2 router went down {report['links_lost']} time(s), "
            f"came back {report.get('links_back', 0)}"
        )
    return line
