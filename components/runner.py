"""Bus adapter: runs one component as its own process, in a run driven by the orchestrator.

    python -m components.runner --connect tcp/127.0.0.1:7447 --run-id demo-1a2b3c4d --name orbit

The orchestrator starts it (or a user does, for ``launch: external``) and sends, on the
component's command key: ``instantiate`` (type + parameters), ``wire`` (which sources feed which
inputs), ``initialize``, ``sync``, ``start``, step horizons, ``get_state``/``set_state`` and
``terminate``. Steps need no message from the orchestrator: its sources send their outputs to
its inbox directly and it steps ``k`` as soon as it holds every input tagged for ``k`` and ``k``
is below the horizon (see :mod:`components.schedule`). It sends its outputs once per step to
each consumer, and in batches to the orchestrator. All work happens on the main thread, reading
the one Zenoh FIFO of its inbox (see :mod:`components.bus`); a watchdog thread only flushes
batches. The process exits after ``terminate``, or when the orchestrator's liveliness token
goes away.

With ``--member NAME:GENERATION`` repeated instead of ``--name``, it runs a process group: those
components in this one process (see :mod:`components.group`); either way :mod:`components.serving`
serves them.
"""

from __future__ import annotations

import argparse
import os
import sys

from components import bus, bus_security
from components.group import ORPHANED
from components.serving import serve


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m components.runner", description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True, help="the orchestrator's Zenoh endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--name", help="the component's name in the config")
    parser.add_argument("--generation", type=int, default=0)
    parser.add_argument(
        "--member",
        action="append",
        type=_member,
        default=[],
        metavar="NAME:GENERATION",
        help="a component of a process group (repeated, instead of --name): all in this process",
    )
    parser.add_argument(
        "--stepping",
        metavar="FILE",
        help="a group's file of 4 bytes where it marks the member whose code runs (the orchestrator reads it)",
    )
    parser.add_argument(
        "--listen",
        help="where the other components reach this one directly "
        "(default: port 0 on the address used to reach the orchestrator)",
    )
    parser.add_argument("--cpu", type=int, help="step on this CPU alone (the config's dedicated_cpu)")
    parser.add_argument(
        "--orchestrator",
        metavar="ZID",
        help="the Zenoh id of the orchestrator's session: exit when the link to it closes",
    )
    args = parser.parse_args(argv)
    secret = os.environ.get(bus.SECRET_ENV)
    if not secret:
        parser.error(
            f"{bus.SECRET_ENV} is not set: give the run's secret in it, as the orchestrator's "
            f"command for an external component does"
        )
    if (args.name is None) == (not args.member):
        parser.error("give either --name (one component) or --member (each component of a group)")
    if args.member and len(args.member) == 1:
        parser.error("a group of one is a component: give --name")
    ended = serve(
        args.connect,
        args.run_id,
        args.member or [(args.name, args.generation)],
        args.listen,
        secret,
        args.cpu,
        bus_security.from_env(),
        args.orchestrator,
        args.stepping,
    )
    return 1 if ended == ORPHANED else 0


def _member(text: str) -> tuple[str, int]:
    name, colon, generation = text.rpartition(":")
    if not colon or not name or not generation.isdigit():
        raise argparse.ArgumentTypeError(f"expected NAME:GENERATION (e.g. dynamics:0), got {text!r}")
    return name, int(generation)


if __name__ == "__main__":
    sys.exit(main())
