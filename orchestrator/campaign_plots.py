"""Plots of a campaign directory (``orchestrator plot DIR`` where DIR holds cases.parquet):

| file | content |
|---|---|
| ``metrics_histograms.png`` | a histogram of each metric over the completed cases |
| ``<metric>_vs_parameters.png`` | the metric against each dispersed (or grid) parameter; failed cases marked as red crosses at the bottom of the panel |
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np


def _figure(*size):
    from matplotlib.figure import Figure
    return Figure(figsize=size, layout="constrained")


def campaign_figures(directory: Path) -> list[tuple[str, object]]:
    import pyarrow.parquet as pq

    from orchestrator.plots import PlotError

    table = pq.read_table(directory / "cases.parquet")
    columns = {name: table.column(name).to_pylist() for name in table.column_names}
    meta_path = directory / "campaign.json"
    meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
    metrics = [m for m in (meta.get("metrics") or {}) if m in columns]
    params = [k for k in (meta.get("dispersed") or []) + (meta.get("grid") or []) if k in columns]
    if not metrics:
        raise PlotError(f"{directory}: the campaign has no metrics to plot (metrics: in the campaign file)")
    status = np.array(columns["status"])
    ok, failed = status == "completed", status == "failed"
    out: list[tuple[str, object]] = []
    cols = min(3, len(metrics))
    rows = math.ceil(len(metrics) / cols)
    fig = _figure(4.2 * cols, 3.2 * rows)
    for i, name in enumerate(metrics, start=1):
        ax = fig.add_subplot(rows, cols, i)
        values = np.array(columns[name], dtype=float)[ok]
        values = values[np.isfinite(values)]
        if len(values):
            ax.hist(values, bins=max(5, min(50, int(np.sqrt(len(values))) + 1)), color="tab:blue", alpha=0.8)
        ax.set(title=f"{name} ({len(values)} completed, {int(failed.sum())} failed)", xlabel=name, ylabel="cases")
        ax.grid(True, alpha=0.3)
    out.append(("metrics_histograms.png", fig))
    numeric = [p for p in params if all(isinstance(v, (int, float)) for v in columns[p])]
    for name in metrics if numeric else []:
        y = np.array(columns[name], dtype=float)
        cols = min(3, len(numeric))
        rows = math.ceil(len(numeric) / cols)
        fig = _figure(4.2 * cols, 3.2 * rows)
        for i, param in enumerate(numeric, start=1):
            ax = fig.add_subplot(rows, cols, i)
            x = np.array(columns[param], dtype=float)
            ax.plot(x[ok], y[ok], "o", markersize=3, color="tab:blue", label="completed")
            if failed.any():
                finite = y[ok & np.isfinite(y)]
                floor = float(np.min(finite)) if len(finite) else 0.0
                ax.plot(x[failed], np.full(int(failed.sum()), floor), "x", color="tab:red", markersize=7,
                        label="failed")
                ax.legend(fontsize="x-small")
            ax.set(xlabel=f"{param} (SI)", ylabel=name)
            ax.grid(True, alpha=0.3)
        out.append((f"{re.sub(r'[^A-Za-z0-9_.-]', '_', name)}_vs_parameters.png", fig))
    return out
