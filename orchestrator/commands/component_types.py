"""``orchestrator types``, ``describe``, ``export-fmu`` and ``markers``: the component types, what they
declare, and the files made from them."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from components.extras import missing
from components.outputs import output_problem
from orchestrator.commands.exits import fail, fail_all
from orchestrator.run.wording import count

if TYPE_CHECKING:
    from components.sdk import Variable


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

    for group, names in (
        ("built-in", [t for t in registry.TYPES if not t.startswith("test.")]),
        ("test blocks (tests and examples)", [t for t in registry.TYPES if t.startswith("test.")]),
    ):
        print(f"{group}:")
        for name in names:
            try:
                line = _one_line(registry.load(name))
            except ConfigError as e:
                line = f"(cannot load: {e.message})"
            print(f"  {name:<28}{line}")
    print(
        "\nyour own: type: module:Class or path/to/file.py:Class (a components.sdk.Component subclass); "
        "`orchestrator describe TYPE` for its parameters and variables"
    )
    return 0


def _print_records(record, heading: str = "parameters") -> None:
    """A declared record's fields, then each record nested in it, as aligned columns."""
    from components.schema import table

    for r in record.records():
        nested = r is not record
        about = r.description.replace("``", "")
        print(f"\n{r.name}" + (f": {about}" if about else "") if nested else f"\n{heading}:")
        rows = [
            (name, kind, default if default in ("required", "-") else f"default {default}", description)
            for name, kind, default, description in table(r.fields)
        ]
        widths = [max([len(row[i]) for row in rows] + [0]) + 2 for i in range(3)]
        for row in rows:
            print("  " + "".join(cell.ljust(width) for cell, width in zip(row, widths)) + row[3])
        if not r.fields:
            print("  (none)")


def cmd_describe(args) -> int:
    import textwrap

    from components import registry
    from components.errors import ConfigError
    from components.sdk import REQUIRED, RunSettings
    from orchestrator.config.yaml_file import ConfigErrors, apply_overrides

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
        return fail(e.message)
    except ConfigErrors as e:
        return fail(e.errors[0])
    declared = {p.name for p in cls.parameters}
    unknown = [key for key in given if key not in declared]
    if unknown:
        return fail(f"--set {unknown[0]}: unknown parameter of {args.type} (known: {', '.join(declared) or 'none'})")
    print(cls.type_name or args.type)
    if summary := _summary(cls):
        print(textwrap.fill(summary, 100, initial_indent="  ", subsequent_indent="  "))
    _print_records(cls.schema)
    missing = [p.name for p in cls.parameters if p.default is REQUIRED and p.name not in given]
    print("\nvariables" + (" (with default parameters):" if not given else " (with the parameters given):"))
    if missing:
        print(
            f"  they depend on the required parameters {', '.join(missing)}: give them to see the "
            f"variables, e.g. orchestrator describe {args.type} --set {missing[0]}=VALUE"
        )
        return 0
    variables: list[Variable]
    errors: Sequence[Exception]
    try:  # as a run resolves it (epoch: any will do for the variables)
        resolved = registry.resolve(cls, given, RunSettings("2000-01-01T12:00:00Z", Path.cwd()))
        variables, errors = (
            (resolved.inputs.variables + resolved.inputs.frames + resolved.outputs.variables + resolved.outputs.frames),
            [],
        )
    except registry.Unresolved as e:
        variables, errors = [], e.errors
    if errors and not given:  # the defaults alone do not make a valid instance (one of two needed...)
        print(f"  they depend on the parameters ({errors[0]}): give them with --set PARAM=VALUE")
        return 0
    if errors:
        return fail_all(f"--set {e}" for e in errors)
    for v in variables:
        shape = f"{v.shape} {v.dtype} frame " if v.frame else str(v.shape)
        print(f"  {v.causality:<7} {v.name:<28}{shape:<8}{v.unit:<16} {v.description}")
    return 0


def cmd_export_fmu(args) -> int:
    if problem := missing("fmi", "orchestrator export-fmu"):
        return fail(problem)
    from components.fmi.exported import export_fmu, fmu_summary
    from components.fmi.spec import ExportError
    from orchestrator.config.yaml_file import ConfigErrors, apply_overrides

    if not args.output.endswith(".fmu"):
        return fail(
            f"-o {args.output}: the output must be a .fmu file, e.g. -o {Path(args.output).stem or 'model'}.fmu"
        )
    if problem := output_problem(args.output, "-o", "file"):
        return fail(problem)
    parameters: dict = {}
    try:
        apply_overrides(parameters, args.set)
        path = export_fmu(args.type, parameters, Path(args.output), args.epoch, Path.cwd())
    except (ConfigErrors, ExportError) as e:
        return fail_all(e.errors if isinstance(e, ConfigErrors) else e.problems)
    summary = fmu_summary(path)
    state = "state: get/set and serialize" if summary["state"] else "no FMU state (the type has no get_state/set_state)"
    print(
        f"wrote {args.output} ({count(summary['inputs'], 'input')}, {count(summary['outputs'], 'output')}, "
        f"FMI {summary['fmi_version']} co-simulation, {state})"
    )
    return 0


def cmd_markers(args) -> int:
    if problem := missing("vision", "orchestrator markers"):
        return fail(problem)
    from components.errors import ConfigError
    from components.estimators.marker_meshes import write

    try:
        return write(args.layout, args.check)
    except ConfigError as e:
        return fail(str(e))
    except OSError as e:
        return fail(f"cannot write the meshes of {args.layout}: {e}")
