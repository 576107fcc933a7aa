"""``orchestrator check``, ``run`` and ``sweep``: a config (or a campaign) checked, run, or swept."""

from __future__ import annotations

import sys
from io import IOBase
from pathlib import Path

from components.outputs import output_problem
from orchestrator.commands.exits import fail, fail_all
from orchestrator.run.wording import count


def _load(path: str, overrides: list[str], full: bool = False, strict: bool = False):
    from orchestrator.config.load import load
    from orchestrator.config.yaml_file import ConfigErrors

    try:
        return load(path, overrides, full, strict), None
    except ConfigErrors as e:
        if _is_campaign(path):
            return None, [
                f"{path}: a campaign file (config:, disperse:, metrics:), not a run's config: "
                f"orchestrator sweep {path} --out DIR runs it"
            ]
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
    from orchestrator.campaigns.campaign_file import CampaignErrors, load_campaign

    try:
        campaign = load_campaign(path)
    except CampaignErrors as e:
        return fail_all(e.errors)
    print(
        f"{path}: ok — a campaign of {count(campaign.count, 'case')}, {count(len(campaign.metrics), 'metric')} "
        f"(orchestrator sweep {path} --out DIR runs it)"
    )
    return 0


def _expect_problem(config, expect: str | None) -> str | None:
    """--expect NAME against the outcomes the run's components declare."""
    from orchestrator.config.outcomes import expect_problem

    return f"--expect {problem}" if expect and (problem := expect_problem(config.components, expect)) else None


def cmd_check(args) -> int:
    if not args.set and not args.expect and _is_campaign(args.config):
        return _check_campaign(args.config)
    config, errors = _load(args.config, args.set, full=True, strict=args.strict)
    if errors:
        return fail_all(errors)
    if problem := _expect_problem(config, args.expect):
        return fail(problem)
    for line in config.notes:
        print(f"warning: {line}", file=sys.stderr)
    shadows = [n for n, s in config.components.items() if s.shadow_of]
    print(
        f"{args.config}: ok — {count(len(config.components) - len(shadows), 'component')}"
        + (f" and {count(len(shadows), 'shadow')}" if shadows else "")
        + ", "
        f"{count(len(config.resolved['connections']), 'connection')}, {count(config.steps, 'step')} of "
        f"{config.step_ns / 1e6:g} ms ({config.algorithm})"
    )
    return 0


def cmd_run(args) -> int:
    config, errors = _load(args.config, args.set, strict=args.strict)
    if errors:
        return fail_all(errors)
    if problem := _expect_problem(config, args.expect):
        return fail(problem)
    lock = None  # held (open, flock'ed) until this process ends: the directory is this run's
    if args.record:
        from orchestrator.run.recording import RecordingError, claim_directory

        try:
            lock = claim_directory(Path(args.record), args.overwrite, config.name)
        except RecordingError as e:
            return fail(str(e))
        except OSError as e:
            return fail(f"--record {args.record}: cannot write a recording there ({e.strerror})")
    elif args.overwrite:
        return fail("--overwrite goes with --record DIR (it replaces the recording in DIR)")
    viewer, problem = _viewer(args.view, config)
    if problem is not None:
        return fail(problem)
    ros2, problem = _ros2(args.ros2, config)
    if problem is not None:
        return fail(problem)
    from orchestrator.run.engine import Run

    run = Run(
        config,
        record=args.record,
        profile=args.profile,
        progress=sys.stderr.isatty(),
        viewer=viewer,
        ros2=ros2,
        expect=args.expect,
    )
    try:
        return run.execute()
    finally:
        if lock is not None:
            assert isinstance(lock, IOBase), "claim_directory's lock is an open file"
            lock.close()


def _viewer(view: str | None, config):
    """(--view's viewer, None for the config's; or the problem that stops the run before it starts)."""
    viewer = None
    if view == "off":
        config.viewer = None
    elif view:
        from orchestrator.config.views import viewer_spec

        errors: list[str] = []
        viewer = viewer_spec(view, "--view", errors, Path.cwd())
        if errors or viewer is None:
            return None, "; ".join(errors) or "--view: expected spawn, web, save:FILE.rrd or foxglove[:PORT]"
    chosen = viewer or config.viewer
    mode = getattr(chosen, "mode", None)
    if mode == "save":
        assert chosen.file is not None, "viewer_spec refuses save without a file"
        if problem := output_problem(chosen.file, "--view save:", "file"):  # an .rrd it cannot write: before the run
            return None, problem
    if mode == "spawn":  # fail before the run, not after
        from components.viewer.sinks import spawn_problem

        if spawn_problem():
            return None, f"viewer spawn: {spawn_problem()}"
    if mode == "foxglove":  # a taken port: before the run, not after
        from components.viewer.foxglove_observer import port_problem

        if problem := port_problem(chosen.port):
            return None, f"viewer foxglove: {problem}"
    return viewer, None


def _ros2(endpoint: str | None, config):
    """(--ros2 [ENDPOINT]: the ros2: section's settings (or the defaults) with this endpoint, None
    without --ros2; or the problem)."""
    if endpoint is None:
        return None, None
    from orchestrator.config.views import clock_clash, ros2_spec

    errors: list[str] = []
    ros2 = ros2_spec(config.resolved.get("ros2"), "--ros2", errors, endpoint=endpoint or None)
    if errors or ros2 is None:
        return None, "; ".join(errors)
    return ros2, clock_clash(config.components, ros2, "--ros2") or None


def cmd_sweep(args) -> int:
    from orchestrator.campaigns.campaign_file import CampaignErrors, load_campaign
    from orchestrator.campaigns.directory import CampaignError
    from orchestrator.campaigns.runner import sweep

    only = None
    if args.only is not None:
        try:
            only = sorted({int(x) for x in args.only.split(",") if x.strip()})
        except ValueError:
            return fail(f"--only {args.only}: expected case numbers, e.g. --only 17 or --only 3,17")
    if args.jobs is not None and args.jobs < 1:
        return fail(f"--jobs {args.jobs}: expected 1 or more")
    if problem := output_problem(args.out, "--out"):  # before any case starts
        return fail(problem)
    try:
        campaign = load_campaign(args.campaign, check_cases=True if only is None else only)
    except CampaignErrors as e:
        return fail_all(e.errors)
    try:
        return sweep(
            campaign,
            Path(args.out),
            jobs=args.jobs,
            cluster=args.cluster,
            resume=args.resume,
            only=only,
            retries=args.retries,
        )
    except CampaignError as e:
        return fail(str(e))
