"""The plot of a shadow (``orchestrator plot DIR``): ``<c>_shadow.png`` for each component ``<c>``
with a ``shadow`` in the recording's config.yaml, one panel per output both record: main - shadow
over time, per element for up to ``PER_ELEMENT`` elements, else the norm of the difference."""

from __future__ import annotations

import math
import re

import numpy as np

PER_ELEMENT = 7
_COLUMN = re.compile(r"(?P<variable>[^\[]+)(\[(?P<index>\d+)\])?$")


def _outputs(columns: dict, component: str) -> dict[str, list[str]]:
    """{output: its columns in element order} of ``component`` in the recording."""
    found: dict[str, list[tuple[int, str]]] = {}
    prefix = f"{component}."
    for column in columns:
        if column.startswith(prefix) and (match := _COLUMN.match(column[len(prefix) :])):
            found.setdefault(match["variable"], []).append((int(match["index"] or 0), column))
    return {name: [c for _, c in sorted(entries)] for name, entries in found.items()}


def shadow_figures(config: dict, columns: dict, t: np.ndarray) -> list[tuple[str, object]]:
    from matplotlib.figure import Figure

    made: list[tuple[str, object]] = []
    for name, entry in (config.get("components") or {}).items():
        if not (entry or {}).get("shadow"):
            continue
        shadow = f"{name}_shadow"
        mains, shadows = _outputs(columns, name), _outputs(columns, shadow)
        shared = [v for v in mains if v in shadows and len(mains[v]) == len(shadows[v])]
        if not shared:
            continue
        cols = min(3, len(shared))
        rows = math.ceil(len(shared) / cols)
        fig = Figure(figsize=(4.2 * cols, 2.6 * rows), layout="constrained")
        fig.suptitle(f"{name} - {shadow} ({entry['type']} - {entry['shadow']['type']})")
        for i, variable in enumerate(shared):
            ax = fig.add_subplot(rows, cols, i + 1)
            difference = np.column_stack([columns[c] for c in mains[variable]]) - np.column_stack(
                [columns[c] for c in shadows[variable]]
            )
            if difference.shape[1] <= PER_ELEMENT:
                for k in range(difference.shape[1]):
                    ax.plot(t, difference[:, k], linewidth=1.0, label=f"[{k}]" if difference.shape[1] > 1 else None)
                if difference.shape[1] > 1:
                    ax.legend(loc="upper right", fontsize="x-small", ncols=2)
                ax.set_title(variable)
            else:
                ax.plot(t, np.linalg.norm(difference, axis=1), linewidth=1.0)
                ax.set_title(f"|{variable}| ({difference.shape[1]} elements)")
            ax.set_xlabel("time (s)")
            ax.grid(True, alpha=0.3)
        made.append((f"{shadow}.png", fig))
    return made
