"""Process groups (``components.<name>.process: <group>``): which components share a process, and
what the members of a group must agree on for that to be possible."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from orchestrator.config.specs import ComponentSpec


def processes(specs: list[ComponentSpec]) -> list[list[ComponentSpec]]:
    """The processes that run ``specs``: one per group (its members in the order given), one per
    component outside a group; in the order of each process's first component."""
    grouped: dict[str, list[ComponentSpec]] = {}
    found: list[list[ComponentSpec]] = []
    for spec in specs:
        if spec.process is None:
            found.append([spec])
        elif spec.process in grouped:
            grouped[spec.process].append(spec)
        else:
            grouped[spec.process] = [spec]
            found.append(grouped[spec.process])
    return found


def dedicated_cpu(members: list[ComponentSpec]) -> bool | str:
    """A process's dedicated_cpu: what its members that ask for a CPU ask (problems() has them agree)."""
    return next((m.dedicated_cpu for m in members if m.dedicated_cpu), False)


def problems(specs: list[ComponentSpec]) -> list[str]:
    """Why the config's groups cannot each run as one process, as ``key: message`` lines."""
    found = []
    for members in processes(specs):
        group = members[0].process
        if group is None:
            continue
        names = ", ".join(m.name for m in members)
        external = [m.name for m in members if m.launch == "external"]
        if external and len(external) < len(members):
            local = ", ".join(m.name for m in members if m.launch == "local")
            found.append(
                f"components.{external[0]}.process: group {group!r} is one process, started by the "
                f"orchestrator or by you: expected its members all launch: local, got launch: external "
                f"({', '.join(external)}) beside launch: local ({local})"
            )
        elif external:
            found.append(
                f"components.{external[0]}.process: group {group!r} ({names}) is launch: external; "
                f"orchestrator join serves one component: expected launch: local members, or no "
                f"process: on external ones"
            )
        asking = {m.name: m.dedicated_cpu for m in members if m.dedicated_cpu}
        if len(set(asking.values())) > 1:
            given = ", ".join(f"{n}: {str(v).lower()}" for n, v in asking.items())
            found.append(
                f"components.{next(iter(asking))}.dedicated_cpu: the members of group {group!r} share one "
                f"process and its CPU: expected those that ask for one to agree (true or process), "
                f"got {given}"
            )
        for member in members:
            problem = member.cls.group_problem(member.typed, member.run)
            if problem:
                found.append(
                    f"components.{member.name}.process: {member.name} ({member.type}) cannot join group "
                    f"{group!r}: {problem}; run it in a process of its own (no process: key)"
                )
    return found
