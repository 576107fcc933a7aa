"""`orchestrator` command line (docs/design.md §5).

Exit codes: 0 success; 1 the run failed (a component crashed, hung or produced NaN);
2 bad usage or bad config; 3 the run ended in another outcome than --expect (run.expect) names;
130 interrupted (Ctrl-C).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
from pathlib import Path

from components.extras import missing
from components.outputs import output_problem
from orchestrator.run.wording import count

USAGE_ERROR = 2


def _fail(message: str, code: int = USAGE_ERROR) -> int:
    print(f"error: {message}", file=sys.stderr)
    return code


def _load(path: str, overrides: list[str], full: bool = False, strict: bool = False):
    from orchestrator.config.yaml_file import ConfigErrors
    from orchestrator.config.load import load
    try:
        return load(path, overrides, full, strict), None
    except ConfigErrors as e:
        if _is_campaign(path):
            return None, [f"{path}: a campaign file (config:, disperse:, metrics:), not a run's config: "
                          f"orchestrator sweep {path} --out DIR runs it"]
        return None, e.errors


def _is_campaign(path: str) -> bool:
    """A YAML mapping with the campaign's ``config`` key and none of a run config's."""
    import yaml
    try:
        raw = yaml.safe_load(Path(path).read_text())
    except (OSError, ValueError, yaml.YAMLError):
        return False
    return isinstance(raw, dict) and "config" in raw and not {"run", "components"} & set(raw)


def _check_campaign(path: str) -> int:
    from orchestrator.campaigns.campaign import CampaignErrors, load_campaign
    try:
        campaign = load_campaign(path)
    except CampaignErrors as e:
        for line in e.errors:
            print(f"error: {line}", file=sys.stderr)
        return USAGE_ERROR
    print(f"{path}: ok — a campaign of {count(campaign.count, 'case')}, {count(len(campaign.metrics), 'metric')} "
          f"(orchestrator sweep {path} --out DIR runs it)")
    return 0


def _expect_problem(config, expect: str | None) -> str | None:
    """--expect NAME against the outcomes the run's components declare."""
    from orchestrator.run.outcome import expect_problem
    return f"--expect {problem}" if expect and (problem := expect_problem(config.components, expect)) else None


def cmd_check(args) -> int:
    if not args.set and not args.expect and _is_campaign(args.config):
        return _check_campaign(args.config)
    config, errors = _load(args.config, args.set, full=True, strict=args.strict)
    if errors:
        for line in errors:
            print(f"error: {line}", file=sys.stderr)
        return USAGE_ERROR
    if problem := _expect_problem(config, args.expect):
        return _fail(problem)
    for line in config.notes:
        print(f"warning: {line}", file=sys.stderr)
    shadows = [n for n, s in config.components.items() if s.shadow_of]
    print(f"{args.config}: ok — {count(len(config.components) - len(shadows), 'component')}"
          + (f" and {count(len(shadows), 'shadow')}" if shadows else "") + ", "
          f"{count(len(config.resolved['connections']), 'connection')}, {count(config.steps, 'step')} of "
          f"{config.step_ns / 1e6:g} ms ({config.algorithm})")
    return 0


def cmd_run(args) -> int:
    config, errors = _load(args.config, args.set, strict=args.strict)
    if errors:
        for line in errors:
            print(f"error: {line}", file=sys.stderr)
        return USAGE_ERROR
    if problem := _expect_problem(config, args.expect):
        return _fail(problem)
    lock = None   # held (open, flock'ed) until this process ends: the directory is this run's
    if args.record:
        from orchestrator.run.recording import RecordingError, claim_directory
        try:
            lock = claim_directory(Path(args.record), args.overwrite, config.name)
        except RecordingError as e:
            return _fail(str(e))
        except OSError as e:
            return _fail(f"--record {args.record}: cannot write a recording there ({e.strerror})")
    elif args.overwrite:
        return _fail("--overwrite goes with --record DIR (it replaces the recording in DIR)")
    viewer = None
    if args.view == "off":
        config.viewer = None
    elif args.view:
        from orchestrator.config.load import viewer_spec
        errors: list[str] = []
        viewer = viewer_spec(args.view, "--view", errors, Path.cwd())
        if errors or viewer is None:
            return _fail("; ".join(errors) or "--view: expected spawn, web, save:FILE.rrd or foxglove[:PORT]")
    if getattr(viewer or config.viewer, "mode", None) == "save":   # an .rrd it cannot write: before the run
        if problem := output_problem((viewer or config.viewer).file, "--view save:", "file"):
            return _fail(problem)
    if getattr(viewer or config.viewer, "mode", None) == "spawn":   # fail before the run, not after
        from components.viewer.sinks import spawn_problem
        if spawn_problem():
            return _fail(f"viewer spawn: {spawn_problem()}")
    if getattr(viewer or config.viewer, "mode", None) == "foxglove":   # a taken port: before the run, not after
        from components.viewer.foxglove_observer import port_problem
        if problem := port_problem((viewer or config.viewer).port):
            return _fail(f"viewer foxglove: {problem}")
    ros2 = None
    if args.ros2 is not None:   # --ros2 [ENDPOINT]: the ros2: section's settings (or the defaults), this endpoint
        from orchestrator.config.load import clock_clash, ros2_spec
        errors = []
        ros2 = ros2_spec(config.resolved.get("ros2"), "--ros2", errors, endpoint=args.ros2 or None)
        if errors or ros2 is None:
            return _fail("; ".join(errors))
        if clash := clock_clash(config.components, ros2, "--ros2"):
            return _fail(clash)
    from orchestrator.run.engine import Run
    run = Run(config, record=args.record, profile=args.profile, progress=sys.stderr.isatty(), viewer=viewer,
              ros2=ros2, expect=args.expect)
    try:
        return run.execute()
    finally:
        if lock is not None:
            lock.close()


def _query(entry: dict, request: dict, timeout: float = 30.0) -> dict:
    from components import bus

    session = bus.open_session(connect=[entry["endpoint"]], secret=entry["secret"], settings=entry.get("settings"))
    try:
        for reply in session.get(bus.control_key(entry["run_id"]), payload=json.dumps(request), timeout=timeout):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
        return {"ok": False, "error": f"run {entry['run_id']} did not answer within {timeout:g} s"}
    finally:
        session.close()


def _one_run(name: str):
    from orchestrator.run import runs
    found = runs.find(name)
    if not found:
        names = ", ".join(r["name"] for r in runs.alive()) or "none"
        return None, f"no run named {name!r} is alive (alive: {names}; see `orchestrator ps`)"
    if len(found) > 1:
        return None, f"several runs are named {name!r}: give a run id ({', '.join(r['run_id'] for r in found)})"
    return found[0], None


def cmd_ps(args) -> int:
    from orchestrator.run import runs
    entries = runs.alive()
    if not entries:
        print("no runs alive")
        return 0
    print(f"{'RUN ID':<32}{'PID':>8}  {'TIME':>12}  {'ENDPOINT':<24}COMPONENTS")
    for entry in entries:
        status = _query(entry, {"op": "status"}, timeout=3.0)
        if status.get("ok"):
            when = f"{status['time']:.3f} s"
            comps = ", ".join(f"{n}:{c['type']}" for n, c in status["components"].items())
        else:
            when, comps = "?", status.get("error", "")
        print(f"{entry['run_id']:<32}{entry['pid']:>8}  {when:>12}  {entry['endpoint']:<24}{comps}")
    return 0


def cmd_stop(args) -> int:
    entry, error = _one_run(args.run)
    if error:
        return _fail(error)
    answer = _query(entry, {"op": "stop"})
    if not answer.get("ok"):
        return _fail(answer.get("error", "stop refused"), 1)
    print(f"stopping {entry['run_id']}")
    return 0


def cmd_swap(args) -> int:
    entry, error = _one_run(args.run)
    if error:
        return _fail(error)
    answer = _query(entry, {"op": "swap", "component": args.component, "type": args.type, "set": args.set},
                    timeout=120.0)
    if not answer.get("ok"):  # bad parameters or type: 2; a replacement that failed to start: 1
        return _fail(answer.get("error", "swap refused"), USAGE_ERROR if answer.get("usage", True) else 1)
    print(f"swapped {args.component} at step {answer['step']} (generation {answer['generation']})")
    return 0


def _summary(cls) -> str:
    """The first paragraph of a component's docstring as plain text (:class:`X`, ``X`` -> X)."""
    import re
    paragraph = " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split())
    return re.sub(r":\w+:`~?([^`]+)`|``([^`]+)``", lambda m: m.group(1) or m.group(2), paragraph)


def _one_line(cls) -> str:
    """The summary's first sentence, without its '(type ...)' aside."""
    import re
    sentence = re.split(r"(?<=[a-z)])\.\s+(?=[A-Z])", _summary(cls))[0].rstrip(".")
    return re.sub(r"\s*\(type [^()]*(\([^()]*\)[^()]*)*\)|\s*\(type [^()]*$", "", sentence)


def cmd_types(args) -> int:
    from components import registry
    from components.errors import ConfigError
    for group, names in (("built-in", [t for t in registry.TYPES if not t.startswith("test.")]),
                         ("test blocks (tests and examples)", [t for t in registry.TYPES if t.startswith("test.")])):
        print(f"{group}:")
        for name in names:
            try:
                line = _one_line(registry.load(name))
            except ConfigError as e:
                line = f"(cannot load: {e.message})"
            print(f"  {name:<28}{line}")
    print("\nyour own: type: module:Class or path/to/file.py:Class (a components.sdk.Component subclass); "
          "`orchestrator describe TYPE` for its parameters and variables")
    return 0


def _print_records(record, heading: str = "parameters") -> None:
    """A declared record's fields, then each record nested in it, as aligned columns."""
    from components.schema import table
    for r in record.records():
        nested = r is not record
        about = r.description.replace("``", "")
        print(f"\n{r.name}" + (f": {about}" if about else "") if nested else f"\n{heading}:")
        rows = [(name, kind, default if default in ("required", "-") else f"default {default}", description)
                for name, kind, default, description in table(r.fields)]
        widths = [max([len(row[i]) for row in rows] + [0]) + 2 for i in range(3)]
        for row in rows:
            print("  " + "".join(cell.ljust(width) for cell, width in zip(row, widths)) + row[3])
        if not r.fields:
            print("  (none)")


def cmd_describe(args) -> int:
    import textwrap

    from components import registry
    from components.errors import ConfigError
    from components.sdk import REQUIRED
    from orchestrator.config.yaml_file import ConfigErrors
    from orchestrator.config.yaml_file import apply_overrides
    if args.type == "config":
        from orchestrator.config.schema import CONFIG
        print("config\n  A run config: the YAML file given to run and check (docs/design.md §4).")
        _print_records(CONFIG, "sections")
        return 0
    try:
        cls = registry.load(args.type, Path.cwd())
        given: dict = {}
        apply_overrides(given, args.set)
    except ConfigError as e:
        return _fail(e.message)
    except ConfigErrors as e:
        return _fail(e.errors[0])
    declared = {p.name for p in cls.parameters}
    unknown = [key for key in given if key not in declared]
    if unknown:
        return _fail(f"--set {unknown[0]}: unknown parameter of {args.type} (known: {', '.join(declared) or 'none'})")
    print(cls.type_name or args.type)
    if summary := _summary(cls):
        print(textwrap.fill(summary, 100, initial_indent="  ", subsequent_indent="  "))
    _print_records(cls.schema)
    missing = [p.name for p in cls.parameters if p.default is REQUIRED and p.name not in given]
    print("\nvariables" + (" (with default parameters):" if not given else " (with the parameters given):"))
    if missing:
        print(f"  they depend on the required parameters {', '.join(missing)}: give them to see the "
              f"variables, e.g. orchestrator describe {args.type} --set {missing[0]}=VALUE")
        return 0
    try:   # as a run resolves it (epoch: any will do for the variables)
        resolved = registry.resolve(cls, given, epoch="2000-01-01T12:00:00Z", config_dir=Path.cwd())
        variables, errors = (resolved.inputs.variables + resolved.inputs.frames + resolved.outputs.variables
                             + resolved.outputs.frames), []
    except registry.Unresolved as e:
        variables, errors = [], e.errors
    if errors and not given:   # the defaults alone do not make a valid instance (one of two needed...)
        print(f"  they depend on the parameters ({errors[0]}): give them with --set PARAM=VALUE")
        return 0
    if errors:
        for e in errors:
            print(f"error: --set {e}", file=sys.stderr)
        return USAGE_ERROR
    for v in variables:
        shape = f"{v.shape} {v.dtype} frame " if v.frame else str(v.shape)
        print(f"  {v.causality:<7} {v.name:<28}{shape:<8}{v.unit:<16} {v.description}")
    return 0


def cmd_export_fmu(args) -> int:
    if problem := missing("fmi", "orchestrator export-fmu"):
        return _fail(problem)
    from components.fmi.exported import ExportError, export_fmu, fmu_summary
    from orchestrator.config.yaml_file import ConfigErrors
    from orchestrator.config.yaml_file import apply_overrides
    if not args.output.endswith(".fmu"):
        return _fail(f"-o {args.output}: the output must be a .fmu file, e.g. -o {Path(args.output).stem or 'model'}.fmu")
    if problem := output_problem(args.output, "-o", "file"):
        return _fail(problem)
    parameters: dict = {}
    try:
        apply_overrides(parameters, args.set)
        path = export_fmu(args.type, parameters, Path(args.output), args.epoch, Path.cwd())
    except (ConfigErrors, ExportError) as e:
        for line in e.errors if isinstance(e, ConfigErrors) else e.problems:
            print(f"error: {line}", file=sys.stderr)
        return USAGE_ERROR
    summary = fmu_summary(path)
    state = "state: get/set and serialize" if summary["state"] else "no FMU state (the type has no get_state/set_state)"
    print(f"wrote {args.output} ({count(summary['inputs'], 'input')}, {count(summary['outputs'], 'output')}, "
          f"FMI {summary['fmi_version']} co-simulation, {state})")
    return 0


def cmd_plot(args) -> int:
    from components.plotting import PlotError
    from orchestrator.plots.recording import plot_recording
    out = Path(args.out) if args.out else Path(args.recording) / "plots"
    if problem := output_problem(out, "--out" if args.out else "plot: DIR/plots"):
        return _fail(problem)
    signals = [name.strip() for name in args.signals.split(",") if name.strip()] if args.signals else None
    try:
        written = plot_recording(Path(args.recording), out, signals)
    except PlotError as e:
        return _fail(str(e))
    except Exception as e:  # e.g. a truncated signals.parquet
        return _fail(f"cannot plot {args.recording}: {type(e).__name__}: {e}")
    for path in written:
        print(f"wrote {path}")
    return 0


def cmd_export(args) -> int:
    from orchestrator.export.rosbag2 import ExportError, export_rosbag2
    if problem := output_problem(args.rosbag2, "--rosbag2"):
        return _fail(problem)
    try:
        exported = export_rosbag2(Path(args.recording), Path(args.rosbag2), args.overwrite, args.all_signals)
    except ExportError as e:
        return _fail(str(e))
    except OSError as e:
        return _fail(f"cannot export {args.recording} to {args.rosbag2}: {e}")
    topics = ", ".join(f"{name} ({n})" for name, n in exported.counts.items())
    print(f"wrote {exported.path} (rosbag2, MCAP, {exported.size / 1e6:.1f} MB): {topics}")
    return 0


def cmd_sweep(args) -> int:
    from orchestrator.campaigns.directory import CampaignError
    from orchestrator.campaigns.runner import sweep
    from orchestrator.campaigns.campaign import CampaignErrors, load_campaign
    only = None
    if args.only is not None:
        try:
            only = sorted({int(x) for x in args.only.split(",") if x.strip()})
        except ValueError:
            return _fail(f"--only {args.only}: expected case numbers, e.g. --only 17 or --only 3,17")
    if args.jobs is not None and args.jobs < 1:
        return _fail(f"--jobs {args.jobs}: expected 1 or more")
    if problem := output_problem(args.out, "--out"):   # before any case starts
        return _fail(problem)
    try:
        campaign = load_campaign(args.campaign, check_cases=True if only is None else only)
    except CampaignErrors as e:
        for line in e.errors:
            print(f"error: {line}", file=sys.stderr)
        return USAGE_ERROR
    try:
        return sweep(campaign, Path(args.out), jobs=args.jobs, cluster=args.cluster, resume=args.resume, only=only,
                     retries=args.retries)
    except CampaignError as e:
        return _fail(str(e))


def cmd_figure(args) -> int:
    from components.camera.figure import draw, nearest_frame
    if problem := output_problem(args.out, "--out", "file"):
        return _fail(problem)
    frames = Path(args.recording) / "frames" / args.component
    try:
        path = nearest_frame(frames, args.time)
    except FileNotFoundError as e:
        return _fail(f"{e} (a recording of `orchestrator run --record DIR` with a camera {args.component!r})")
    draw(path, Path(args.out))
    print(f"wrote {args.out}: {path}")
    return 0


def cmd_markers(args) -> int:
    if problem := missing("vision", "orchestrator markers"):
        return _fail(problem)
    from components.errors import ConfigError
    from components.estimators.marker_meshes import write
    try:
        return write(args.layout, args.check)
    except ConfigError as e:
        return _fail(str(e))
    except OSError as e:
        return _fail(f"cannot write the meshes of {args.layout}: {e}")


def cmd_join(args) -> int:
    from orchestrator.hosts.joiner import JoinError, join
    try:
        return join(Path(args.file), args.connect or None, args.listen, args.cpu)
    except JoinError as e:
        return _fail(str(e), e.code)


def cmd_router(args) -> int:
    from orchestrator.config.schema import ENDPOINT
    import re
    from orchestrator.hosts.joiner import JoinError, route
    if args.ros2:
        return _ros2_router(args)
    if args.join is None or not args.listen:
        missing = " and ".join(f for f, given in (("--listen ENDPOINT", args.listen), ("--join FILE", args.join)) if not given)
        return _fail(f"router: expected {missing} (a run's router), or --ros2 (a ROS 2 router, as rmw_zenohd)")
    for endpoint in args.listen:
        if not re.fullmatch(ENDPOINT, endpoint):
            return _fail(f"--listen {endpoint}: expected a Zenoh endpoint like tls/0.0.0.0:7447")
    try:
        return route(Path(args.join), args.listen)
    except JoinError as e:
        return _fail(str(e), e.code)


def _ros2_router(args) -> int:
    from components.ros2 import router
    if args.join is not None:
        return _fail(f"router --ros2: expected no --join (that is a run's router), got --join {args.join}")
    for endpoint in args.listen or []:
        if problem := router.check_endpoint(endpoint):
            return _fail(f"--listen: {problem}")
    try:
        return router.serve(args.listen)
    except router.RouterError as e:
        return _fail(str(e))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="orchestrator", description="Zenorbit: lockstep co-simulation over Zenoh.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def with_set(p):
        p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                       help="override a config key, e.g. run.duration=2s (repeatable)")

    def with_strict(p):
        p.add_argument("--strict", action="store_true", help="the check's warnings (a value outside its plausible "
                       "range, suspect physics) are errors: exit 2, nothing started (as run.strict: true)")

    p = sub.add_parser("run", help="run a config")
    p.add_argument("config")
    p.add_argument("--record", metavar="DIR", help="write signals.parquet, events.jsonl and config.yaml to DIR "
                   "(a new or empty directory)")
    p.add_argument("--overwrite", action="store_true", help="replace the recording already in --record DIR")
    with_set(p)
    with_strict(p)
    p.add_argument("--view", metavar="{spawn,web,save:FILE.rrd,foxglove[:PORT]}",
                   help="live view in Rerun, or served to Foxglove on ws://localhost:PORT (default 8765)")
    p.add_argument("--ros2", nargs="?", const="", metavar="rclpy|zenoh|auto|ENDPOINT",
                   help="publish the run live to ROS 2: rclpy (a real rclpy node, on your ROS 2's middleware, "
                        "Fast DDS by default), zenoh (rmw_zenoh's wire through its router at tcp/localhost:7447), "
                        "ENDPOINT (zenoh through that router), auto (rclpy if a Python here imports it, else "
                        "zenoh); default: the ros2: section's, else auto. ROS_DOMAIN_ID is the domain")
    p.add_argument("--expect", metavar="OUTCOME", help="the outcome the run must come to, one its components declare "
                   "(controller.capture: captured, aborted, undecided): another ends it with exit code 3 "
                   "(overrides run.expect)")
    p.add_argument("--profile", action="store_true", help="print, at the end, each component's compute time and "
                   "waiting time per step (waiting: for its inputs or the horizon, the bus included) and the share "
                   "of the wall time it computes")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("check", help="validate a config without running it")
    p.add_argument("config")
    with_set(p)
    with_strict(p)
    p.add_argument("--expect", metavar="OUTCOME", help="check that the run can come to this outcome (run --expect)")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("ps", help="list runs alive on this machine")
    p.set_defaults(func=cmd_ps)

    p = sub.add_parser("stop", help="stop a run cleanly (recording flushed)")
    p.add_argument("--run", required=True, metavar="NAME", help="run name or run id")
    p.set_defaults(func=cmd_stop)

    p = sub.add_parser("swap", help="replace a component of a running run at the next step boundary")
    p.add_argument("--run", required=True, metavar="NAME", help="run name or run id")
    p.add_argument("component")
    p.add_argument("--type", help="the new component type (default: the same type, state handed over)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a parameter of the new component")
    p.set_defaults(func=cmd_swap)

    p = sub.add_parser("plot", help="PNG plots of a recording: orbit, dynamics, and the paper's Figs. 5-7")
    p.add_argument("recording", metavar="DIR", help="a directory written by run --record")
    p.add_argument("--out", metavar="DIR", help="where to write the PNGs (default: DIR/plots)")
    p.add_argument("--signals", metavar="NAME,NAME", help="plot these columns instead (orbit.r_eci, "
                   "dynamics.target.q[0], ...)")
    p.set_defaults(func=cmd_plot)

    p = sub.add_parser("export", help="a recording as a rosbag2 folder (MCAP storage) for ros2 bag and Foxglove")
    p.add_argument("recording", metavar="DIR", help="a directory written by run --record")
    p.add_argument("--rosbag2", required=True, metavar="OUT", help="the bag folder to write (must not exist)")
    p.add_argument("--overwrite", action="store_true", help="replace OUT (a bag folder) once the new bag is written")
    p.add_argument("--all-signals", action="store_true", help="also the variables of components whose type "
                   "declares no ROS messages, as std_msgs/Float64MultiArray on /COMPONENT/VARIABLE")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("figure", help="a camera's recorded frame as a PNG: its colour image beside its depth")
    p.add_argument("recording", metavar="DIR", help="a directory written by run --record")
    p.add_argument("--component", required=True, help="the camera's component name (its frames' folder)")
    p.add_argument("--time", type=float, required=True, help="the frame taken nearest this time (s)")
    p.add_argument("--out", required=True, metavar="FILE.png", help="the PNG to write")
    p.set_defaults(func=cmd_figure)

    p = sub.add_parser("markers", help="write the meshes (OBJ) of a fiducial marker layout, which the URDF draws")
    p.add_argument("layout", metavar="LAYOUT.yaml", help="the marker layout, e.g. models/capture/grapple_markers.yaml")
    p.add_argument("--check", action="store_true", help="write nothing; exit 1 if the meshes differ from the layout's")
    p.set_defaults(func=cmd_markers)

    p = sub.add_parser("sweep", help="run a campaign: a grid and dispersions over a config's keys, many cases")
    p.add_argument("campaign", metavar="CAMPAIGN.yaml")
    p.add_argument("--out", required=True, metavar="DIR", help="where cases.parquet and the cases go")
    p.add_argument("--jobs", type=int, metavar="N", help="cases at once on this machine (default: the CPUs)")
    p.add_argument("--cluster", metavar="tcp://HOST:8786", help="run the cases on this dask.distributed scheduler")
    p.add_argument("--retries", type=int, default=2, metavar="N",
                   help="--cluster: times a case is retried after an error on its worker (default 2)")
    p.add_argument("--resume", action="store_true", help="finish an interrupted campaign in DIR")
    p.add_argument("--only", metavar="N[,N]", help="run only these cases (numbered from 0)")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("join", help="on another host: serve a launch: external component of a run, from the "
                       "join file the orchestrator wrote")
    p.add_argument("file", metavar="FILE.join", help="DIR/join/<component>.join (copy it over; it holds the run's "
                   "secret: keep it private)")
    p.add_argument("--connect", action="append", metavar="ENDPOINT", help="reach the run here instead of the "
                   "file's endpoints (repeatable)")
    p.add_argument("--listen", metavar="ENDPOINT", help="where the run's other components reach this one "
                   "(default: a free port on every interface)")
    p.add_argument("--cpu", type=int, help="step on this CPU alone")
    p.set_defaults(func=cmd_join)

    p = sub.add_parser("router", help="the run's Zenoh router (bus.router), for hosts that cannot reach each other; "
                       "with --ros2, a ROS 2 router (as rmw_zenohd) for --ros2 on a machine without ROS")
    p.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help="where the run's processes reach it, e.g. tls/0.0.0.0:7447 (repeatable); with --ros2: "
                        "where ROS 2 nodes and runs reach it (default tcp/[::]:7447, rmw_zenohd's)")
    p.add_argument("--join", metavar="FILE", help="DIR/join/router.join, which the orchestrator wrote")
    p.add_argument("--ros2", action="store_true", help="a ROS 2 router instead, in the foreground, with rmw_zenohd's "
                   "default configuration: rmw_zenoh's nodes, `run --ros2` and ros2.bridge (transport zenoh) meet "
                   "there; SIGTERM or Ctrl-C stops it")
    p.set_defaults(func=cmd_router)

    p = sub.add_parser("types", help="list the component types, with a line each")
    p.set_defaults(func=cmd_types)

    p = sub.add_parser("describe", help="print a component type's parameters and variables")
    p.add_argument("type", help="a type from `orchestrator types`, module:Class or file.py:Class")
    p.add_argument("--set", action="append", default=[], metavar="PARAM=VALUE",
                   help="a parameter value (YAML), to see the variables that depend on it (repeatable)")
    p.set_defaults(func=cmd_describe)

    p = sub.add_parser("export-fmu", help="package a component type, its parameters fixed, as an FMI 2.0 "
                       "co-simulation FMU")
    p.add_argument("type", help="a type from `orchestrator types`, module:Class or file.py:Class")
    p.add_argument("--set", action="append", default=[], metavar="PARAM=VALUE",
                   help="a parameter value (YAML), fixed in the FMU (repeatable); files it names go into the FMU")
    p.add_argument("--epoch", metavar="UTC", help="the UTC of t = 0 (run.epoch), e.g. 2022-09-18T12:00:00Z, "
                   "for types that need it")
    p.add_argument("-o", "--output", required=True, metavar="NAME.fmu", help="the FMU to write; NAME is its model "
                   "identifier")
    p.set_defaults(func=cmd_export_fmu)

    from components.viewer.replay import add_view_command   # orchestrator view DIR: replay in Rerun
    add_view_command(sub)
    return parser


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
    except BrokenPipeError:   # `orchestrator types | head`: the reader left; no traceback
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
