"""Plots of a campaign directory (``orchestrator plot DIR`` where DIR holds cases.parquet):

| file | content |
|---|---|
| ``metrics_histograms.png`` | a histogram of each numeric metric over the cases that have it |
| ``<metric>_vs_parameters.png`` | the metric against each swept or dispersed quantity (a vector by its parts), every case coloured by its outcome |
| ``outcomes.png`` | the envelope: each case's outcome against each quantity, and a vector's direction as azimuth and elevation |

A quantity that has one value over the campaign (a grid of one point) or is a seed (a key named
``seed`` or ``*_seed``: a sensor's noise draw, no physics) is not drawn against; the figures say
which were left out. Axes carry the unit the campaign file gives (a dispersion's, or
the grid's first value's), metrics their signal's SI unit.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from components.errors import ConfigError
from components.plotting import PlotError, new_figure
from components.units import parse_quantity, unit_scale

OUTCOME_COLOURS = {
    "completed": "tab:blue",
    "failed": "tab:red",
    "interrupted": "tab:grey",
    "captured": "tab:green",
    "aborted": "tab:orange",
    "undecided": "tab:purple",
}
SEED = re.compile(r"(.*_)?seed$")  # a key's last part naming a random draw's seed
PALETTE = ("tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")


@dataclass(frozen=True)
class Quantity:
    """One axis a campaign varies: a number per case, in ``unit`` (as the campaign file gives it)."""

    label: str
    values: np.ndarray
    unit: str


def _unit_of(key: str, values: list, meta: dict) -> tuple[str, float]:
    """(unit, its factor to SI) of a parameter: the dispersion's, else the first grid value's text."""
    unit = (meta.get("units") or {}).get(key)
    if unit is None:
        for raw in (meta.get("grid_values") or {}).get(key, []):
            try:
                unit = parse_quantity(raw, key)[1] if isinstance(raw, str) else None
            except ConfigError:
                continue
            if unit:
                break
    scale = unit_scale(unit) if unit else None
    return (unit, scale[0]) if unit and scale else ("", 1.0)


def quantities(columns: dict[str, list], keys: list[str], meta: dict) -> tuple[list[Quantity], list[str], dict]:
    """The numeric quantities of the campaign's keys (a vector split into its parts), the keys left
    out (one value only, or not numbers), and each vector key's (n, 3) values."""
    out, left_out, vectors = [], [], {}
    for key in keys:
        values = columns[key]
        if SEED.match(re.sub(r"\[\d+\]", "", key.split(".")[-1])):  # which draw, not a quantity
            left_out.append(f"{key} (a seed)")
            continue
        short = ".".join([p for p in key.split(".") if p not in ("components", "parameters")][-2:])
        if all(isinstance(v, (int, float)) for v in values):
            x = np.array(values, dtype=float)
            if len(set(x.tolist())) < 2:
                left_out.append(f"{key} (one value)")
                continue
            unit, factor = _unit_of(key, values, meta)
            out.append(Quantity(short, x / factor, unit))
            continue
        try:
            parsed = np.array([json.loads(v) for v in values], dtype=float)
        except (TypeError, ValueError):
            left_out.append(f"{key} (not numbers)")
            continue
        if parsed.ndim != 2:
            left_out.append(f"{key} (not numbers)")
            continue
        if parsed.shape[1] == 3:
            vectors[short] = parsed
        for i in range(parsed.shape[1]):
            part = parsed[:, i]
            if len(set(part.tolist())) >= 2:
                out.append(Quantity(f"{short}[{i}]", part, _unit_of(key, values, meta)[0]))
    return out, left_out, vectors


def _outcome_colours(outcomes: list[str]) -> dict[str, str]:
    colours, free = {}, iter(PALETTE)
    for name in dict.fromkeys(outcomes):
        colours[name] = OUTCOME_COLOURS.get(name) or next(free, "black")
    return colours


def campaign_figures(directory: Path) -> list[tuple[str, object]]:
    import pyarrow.parquet as pq

    table = pq.read_table(directory / "cases.parquet")
    columns = {name: table.column(name).to_pylist() for name in table.column_names}
    meta_path = directory / "campaign.json"
    meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
    metric_meta = meta.get("metrics") or {}
    metrics = [
        m for m in metric_meta if m in columns and all(isinstance(v, (int, float)) or v is None for v in columns[m])
    ]
    keys = [k for k in (meta.get("dispersed") or []) + (meta.get("grid") or []) if k in columns]
    if not metrics and "outcome" not in columns:
        raise PlotError(f"{directory}: the campaign has no metrics to plot (metrics: in the campaign file)")
    outcome = columns.get("outcome") or columns["status"]
    colours = _outcome_colours(outcome)
    outcome = np.array(outcome)
    out: list[tuple[str, object]] = []
    if metrics:
        cols = min(3, len(metrics))
        rows = math.ceil(len(metrics) / cols)
        fig = new_figure(4.2 * cols, 3.2 * rows)
        for i, name in enumerate(metrics, start=1):
            ax = fig.add_subplot(rows, cols, i)
            values = np.array([math.nan if v is None else v for v in columns[name]], dtype=float)
            values = values[np.isfinite(values)]
            if len(values):
                ax.hist(values, bins=max(5, min(50, int(np.sqrt(len(values))) + 1)), color="tab:blue", alpha=0.8)
            ax.set(
                title=_fits(f"{name} ({len(values)} of {len(outcome)} cases)", cols),
                xlabel=_metric_label(name, metric_meta),
                ylabel="cases",
            )
            ax.grid(True, alpha=0.3)
        out.append(("metrics_histograms.png", fig))
    axes, left_out, vectors = quantities(columns, keys, meta)
    note = f"not drawn against: {'; '.join(left_out)}" if left_out else ""
    for name in metrics if axes else []:
        y = np.array([math.nan if v is None else v for v in columns[name]], dtype=float)
        fig = _gridnew_figure(len(axes))
        for i, q in enumerate(axes, start=1):
            ax = fig.add_subplot(math.ceil(len(axes) / min(3, len(axes))), min(3, len(axes)), i)
            for kind, colour in colours.items():
                chosen = outcome == kind
                if chosen.any():
                    ax.plot(
                        q.values[chosen], y[chosen], "o", markersize=3, color=colour, label=f"{kind} ({chosen.sum()})"
                    )
            ax.set(xlabel=_label(q), ylabel=_metric_label(name, metric_meta))
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize="x-small")
        if note:
            fig.suptitle(_wrapped(note, fig), fontsize="small")
        out.append((f"{re.sub(r'[^A-Za-z0-9_.-]', '_', name)}_vs_parameters.png", fig))
    if axes or vectors:
        out.append(("outcomes.png", _outcomesnew_figure(axes, vectors, outcome, colours, note)))
    return out


def _wrapped(text: str, fig) -> str:
    """``text`` in lines that fit the figure's width (small type: ~15 characters an inch)."""
    import textwrap

    return textwrap.fill(text, width=max(40, int(fig.get_figwidth() * 15)))


def _fits(title: str, cols: int) -> str:
    """A panel's title in lines that fit its width (4.2 in; ~9 characters an inch at the title's size)."""
    import textwrap

    return textwrap.fill(title, width=int(4.2 * 9)) if cols > 1 else title


def _gridnew_figure(panels: int):
    cols = min(3, panels)
    return new_figure(4.2 * cols, 3.2 * math.ceil(panels / cols))


def _label(q: Quantity) -> str:
    return f"{q.label} ({q.unit})" if q.unit else q.label


def _metric_label(name: str, metric_meta: dict) -> str:
    unit = (metric_meta.get(name) or {}).get("unit") or "1"
    return name if unit == "1" else f"{name} ({unit})"


def _outcomesnew_figure(axes: list[Quantity], vectors: dict, outcome: np.ndarray, colours: dict, note: str):
    """Each case's outcome against each quantity (one row per outcome), and each 3-vector's
    direction as azimuth and elevation (a unit axis over the sphere), coloured by outcome."""
    kinds = list(colours)
    panels = len(axes) + len(vectors)
    fig = _gridnew_figure(panels)
    cols = min(3, panels)
    rows = math.ceil(panels / cols)
    for i, q in enumerate(axes, start=1):
        ax = fig.add_subplot(rows, cols, i)
        for row, kind in enumerate(kinds):
            chosen = outcome == kind
            if chosen.any():
                ax.plot(
                    q.values[chosen],
                    np.full(chosen.sum(), row),
                    "o",
                    markersize=4,
                    color=colours[kind],
                    alpha=0.7,
                    label=f"{kind} ({chosen.sum()})",
                )
        ax.set(
            xlabel=_label(q),
            yticks=range(len(kinds)),
            yticklabels=kinds,
            ylim=(-0.5, len(kinds) - 0.5),
            title=_fits(f"outcome against {q.label}", cols),
        )
        ax.grid(True, axis="x", alpha=0.3)
    for j, (label, v) in enumerate(vectors.items(), start=len(axes) + 1):
        ax = fig.add_subplot(rows, cols, j)
        norm = np.linalg.norm(v, axis=1)
        unit = v / np.where(norm > 0, norm, 1.0)[:, None]
        azimuth = np.degrees(np.arctan2(unit[:, 1], unit[:, 0]))
        elevation = np.degrees(np.arcsin(np.clip(unit[:, 2], -1.0, 1.0)))
        for kind in kinds:
            chosen = outcome == kind
            if chosen.any():
                ax.plot(
                    azimuth[chosen],
                    elevation[chosen],
                    "o",
                    markersize=5,
                    color=colours[kind],
                    label=f"{kind} ({chosen.sum()})",
                )
        ax.set(
            xlabel=f"{label}: azimuth (deg)",
            ylabel=f"{label}: elevation (deg)",
            xlim=(-180, 180),
            ylim=(-90, 90),
            title=_fits(f"outcome over the direction of {label}", cols),
        )
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="x-small")
    if note:
        fig.suptitle(_wrapped(note, fig), fontsize="small")
    return fig
