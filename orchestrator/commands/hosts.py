"""``orchestrator join`` and ``router``: serving a run's component or its router on another host, and a
ROS 2 router."""

from __future__ import annotations

from pathlib import Path

from orchestrator.commands.exits import fail


def cmd_join(args) -> int:
    from orchestrator.hosts.joiner import JoinError, join

    try:
        return join(Path(args.file), args.connect or None, args.listen, args.cpu)
    except JoinError as e:
        return fail(str(e), e.code)


def cmd_router(args) -> int:
    import re

    from orchestrator.config.schema import ENDPOINT
    from orchestrator.hosts.joiner import JoinError, route

    if args.ros2:
        return _ros2_router(args)
    if args.join is None or not args.listen:
        missing = " and ".join(
            f for f, given in (("--listen ENDPOINT", args.listen), ("--join FILE", args.join)) if not given
        )
        return fail(f"router: expected {missing} (a run's router), or --ros2 (a ROS 2 router, as rmw_zenohd)")
    for endpoint in args.listen:
        if not re.fullmatch(ENDPOINT, endpoint):
            return fail(f"--listen {endpoint}: expected a Zenoh endpoint like tls/0.0.0.0:7447")
    try:
        return route(Path(args.join), args.listen)
    except JoinError as e:
        return fail(str(e), e.code)


def _ros2_router(args) -> int:
    from components.ros2 import router

    if args.join is not None:
        return fail(f"router --ros2: expected no --join (that is a run's router), got --join {args.join}")
    for endpoint in args.listen or []:
        if problem := router.check_endpoint(endpoint):
            return fail(f"--listen: {problem}")
    try:
        return router.serve(args.listen)
    except router.RouterError as e:
        return fail(str(e))
