"""`orchestrator` command line (docs/design.md §5): the parser, the one declaration of every
command and argument; each command's handler is in :mod:`orchestrator.commands`.

Exit codes: 0 success; 1 the run failed (a component crashed, hung or produced NaN);
2 bad usage or bad config; 3 the run ended in another outcome than --expect (run.expect) names;
130 interrupted (Ctrl-C).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

from orchestrator.commands import component_types, hosts, live, recordings, running


def build_parser() -> argparse.ArgumentParser:
    """Every command and its arguments, in the order of --help (one function per command)."""
    parser = argparse.ArgumentParser(prog="orchestrator", description="Zenorbit: lockstep co-simulation over Zenoh.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in COMMANDS:
        add(sub)

    from components.viewer.replay import add_view_command  # orchestrator view DIR: replay in Rerun

    add_view_command(sub)
    return parser


def _with_set(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a config key, e.g. run.duration=2s (repeatable)",
    )


def _with_strict(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--strict",
        action="store_true",
        help="the check's warnings (a value outside its plausible "
        "range, suspect physics) are errors: exit 2, nothing started (as run.strict: true)",
    )


def _add_run(sub) -> None:
    p = sub.add_parser("run", help="run a config")
    p.add_argument("config")
    p.add_argument(
        "--record",
        metavar="DIR",
        help="write signals.parquet, events.jsonl and config.yaml to DIR (a new or empty directory)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace the recording already in --record DIR")
    _with_set(p)
    _with_strict(p)
    p.add_argument(
        "--view",
        metavar="{spawn,web,save:FILE.rrd,foxglove[:PORT]}",
        help="live view in Rerun, or served to Foxglove on ws://localhost:PORT (default 8765)",
    )
    p.add_argument(
        "--ros2",
        nargs="?",
        const="",
        metavar="rclpy|zenoh|auto|ENDPOINT",
        help="publish the run live to ROS 2: rclpy (a real rclpy node, on your ROS 2's middleware, "
        "Fast DDS by default), zenoh (rmw_zenoh's wire through its router at tcp/localhost:7447), "
        "ENDPOINT (zenoh through that router), auto (rclpy if a Python here imports it, else "
        "zenoh); default: the ros2: section's, else auto. ROS_DOMAIN_ID is the domain",
    )
    p.add_argument(
        "--expect",
        metavar="OUTCOME",
        help="the outcome the run must come to, one its components declare "
        "(controller.capture: captured, aborted, undecided): another ends it with exit code 3 "
        "(overrides run.expect)",
    )
    p.add_argument(
        "--profile",
        action="store_true",
        help="print, at the end, each component's compute time and "
        "waiting time per step (waiting: for its inputs or the horizon, the bus included) and the share "
        "of the wall time it computes",
    )
    p.set_defaults(func=running.cmd_run)


def _add_check(sub) -> None:
    p = sub.add_parser("check", help="validate a config without running it")
    p.add_argument("config")
    _with_set(p)
    _with_strict(p)
    p.add_argument("--expect", metavar="OUTCOME", help="check that the run can come to this outcome (run --expect)")
    p.set_defaults(func=running.cmd_check)


def _add_ps(sub) -> None:
    p = sub.add_parser("ps", help="list runs alive on this machine")
    p.set_defaults(func=live.cmd_ps)


def _add_stop(sub) -> None:
    p = sub.add_parser("stop", help="stop a run cleanly (recording flushed)")
    p.add_argument("--run", required=True, metavar="NAME", help="run name or run id")
    p.set_defaults(func=live.cmd_stop)


def _add_swap(sub) -> None:
    p = sub.add_parser("swap", help="replace a component of a running run at the next step boundary")
    p.add_argument("--run", required=True, metavar="NAME", help="run name or run id")
    p.add_argument("component")
    p.add_argument("--type", help="the new component type (default: the same type, state handed over)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a parameter of the new component")
    p.set_defaults(func=live.cmd_swap)


def _add_plot(sub) -> None:
    p = sub.add_parser("plot", help="PNG plots of a recording: orbit, dynamics, and the paper's Figs. 5-7")
    p.add_argument("recording", metavar="DIR", help="a directory written by run --record")
    p.add_argument("--out", metavar="DIR", help="where to write the PNGs (default: DIR/plots)")
    p.add_argument(
        "--signals", metavar="NAME,NAME", help="plot these columns instead (orbit.r_eci, dynamics.target.q[0], ...)"
    )
    p.set_defaults(func=recordings.cmd_plot)


def _add_export(sub) -> None:
    p = sub.add_parser("export", help="a recording as a rosbag2 folder (MCAP storage) for ros2 bag and Foxglove")
    p.add_argument("recording", metavar="DIR", help="a directory written by run --record")
    p.add_argument("--rosbag2", required=True, metavar="OUT", help="the bag folder to write (must not exist)")
    p.add_argument("--overwrite", action="store_true", help="replace OUT (a bag folder) once the new bag is written")
    p.add_argument(
        "--all-signals",
        action="store_true",
        help="also the variables of components whose type "
        "declares no ROS messages, as std_msgs/Float64MultiArray on /COMPONENT/VARIABLE",
    )
    p.set_defaults(func=recordings.cmd_export)


def _add_figure(sub) -> None:
    p = sub.add_parser("figure", help="a camera's recorded frame as a PNG: its colour image beside its depth")
    p.add_argument("recording", metavar="DIR", help="a directory written by run --record")
    p.add_argument("--component", required=True, help="the camera's component name (its frames' folder)")
    p.add_argument("--time", type=float, required=True, help="the frame taken nearest this time (s)")
    p.add_argument("--out", required=True, metavar="FILE.png", help="the PNG to write")
    p.set_defaults(func=recordings.cmd_figure)


def _add_markers(sub) -> None:
    p = sub.add_parser("markers", help="write the meshes (OBJ) of a fiducial marker layout, which the URDF draws")
    p.add_argument("layout", metavar="LAYOUT.yaml", help="the marker layout, e.g. models/capture/grapple_markers.yaml")
    p.add_argument("--check", action="store_true", help="write nothing; exit 1 if the meshes differ from the layout's")
    p.set_defaults(func=component_types.cmd_markers)


def _add_sweep(sub) -> None:
    p = sub.add_parser("sweep", help="run a campaign: a grid and dispersions over a config's keys, many cases")
    p.add_argument("campaign", metavar="CAMPAIGN.yaml")
    p.add_argument("--out", required=True, metavar="DIR", help="where cases.parquet and the cases go")
    p.add_argument("--jobs", type=int, metavar="N", help="cases at once on this machine (default: the CPUs)")
    p.add_argument("--cluster", metavar="tcp://HOST:8786", help="run the cases on this dask.distributed scheduler")
    p.add_argument(
        "--retries",
        type=int,
        default=2,
        metavar="N",
        help="--cluster: times a case is retried after an error on its worker (default 2)",
    )
    p.add_argument("--resume", action="store_true", help="finish an interrupted campaign in DIR")
    p.add_argument("--only", metavar="N[,N]", help="run only these cases (numbered from 0)")
    p.set_defaults(func=running.cmd_sweep)


def _add_join(sub) -> None:
    p = sub.add_parser(
        "join",
        help="on another host: serve a launch: external component of a run, from the join file the orchestrator wrote",
    )
    p.add_argument(
        "file",
        metavar="FILE.join",
        help="DIR/join/<component>.join (copy it over; it holds the run's secret: keep it private)",
    )
    p.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="reach the run here instead of the file's endpoints (repeatable)",
    )
    p.add_argument(
        "--listen",
        metavar="ENDPOINT",
        help="where the run's other components reach this one (default: a free port on every interface)",
    )
    p.add_argument("--cpu", type=int, help="step on this CPU alone")
    p.set_defaults(func=hosts.cmd_join)


def _add_router(sub) -> None:
    p = sub.add_parser(
        "router",
        help="the run's Zenoh router (bus.router), for hosts that cannot reach each other; "
        "with --ros2, a ROS 2 router (as rmw_zenohd) for --ros2 on a machine without ROS",
    )
    p.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="where the run's processes reach it, e.g. tls/0.0.0.0:7447 (repeatable); with --ros2: "
        "where ROS 2 nodes and runs reach it (default tcp/[::]:7447, rmw_zenohd's)",
    )
    p.add_argument("--join", metavar="FILE", help="DIR/join/router.join, which the orchestrator wrote")
    p.add_argument(
        "--ros2",
        action="store_true",
        help="a ROS 2 router instead, in the foreground, with rmw_zenohd's "
        "default configuration: rmw_zenoh's nodes, `run --ros2` and ros2.bridge (transport zenoh) meet "
        "there; SIGTERM or Ctrl-C stops it",
    )
    p.set_defaults(func=hosts.cmd_router)


def _add_types(sub) -> None:
    p = sub.add_parser("types", help="list the component types, with a line each")
    p.set_defaults(func=component_types.cmd_types)


def _add_describe(sub) -> None:
    p = sub.add_parser("describe", help="print a component type's parameters and variables")
    p.add_argument("type", help="a type from `orchestrator types`, module:Class or file.py:Class")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="PARAM=VALUE",
        help="a parameter value (YAML), to see the variables that depend on it (repeatable)",
    )
    p.set_defaults(func=component_types.cmd_describe)


def _add_export_fmu(sub) -> None:
    p = sub.add_parser(
        "export-fmu", help="package a component type, its parameters fixed, as an FMI 2.0 co-simulation FMU"
    )
    p.add_argument("type", help="a type from `orchestrator types`, module:Class or file.py:Class")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="PARAM=VALUE",
        help="a parameter value (YAML), fixed in the FMU (repeatable); files it names go into the FMU",
    )
    p.add_argument(
        "--epoch", metavar="UTC", help="the UTC of t = 0 (run.epoch), e.g. 2022-09-18T12:00:00Z, for types that need it"
    )
    p.add_argument(
        "-o", "--output", required=True, metavar="NAME.fmu", help="the FMU to write; NAME is its model identifier"
    )
    p.set_defaults(func=component_types.cmd_export_fmu)


# the order of --help
COMMANDS = (
    _add_run,
    _add_check,
    _add_ps,
    _add_stop,
    _add_swap,
    _add_plot,
    _add_export,
    _add_figure,
    _add_markers,
    _add_sweep,
    _add_join,
    _add_router,
    _add_types,
    _add_describe,
    _add_export_fmu,
)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if threading.current_thread() is threading.main_thread():
        # Ctrl-C is every command's whatever was inherited: one started with `&` from a script has
        # SIGINT ignored (each command ends with 130, keeping what it did: sweep says --resume)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # `orchestrator types | head`: the reader left; no traceback
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
