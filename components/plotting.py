"""What a component type's plots are made of: the :class:`Plot` a type declares (its ``plots``),
the :class:`RecordedRun` a plot draws from, a figure on Matplotlib's Agg canvas (no pyplot), and
:class:`PlotError`. ``orchestrator plot DIR`` draws the plots of the types in the recording
(orchestrator/plots/recording.py); Matplotlib is imported only when a figure is made.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np


class PlotError(Exception):
    """A recording that cannot be plotted (missing files or columns)."""


def new_figure(*size):
    from matplotlib.figure import Figure

    return Figure(figsize=size, layout="constrained")


@dataclass(frozen=True)
class Plot:
    """A figure a component type draws from a recording.

    ``file``: the file name, ``{c}`` standing for the component's name and any other ``{field}``
    for a part the figure is drawn once for (``{c}_{body}.png``). ``description``: one line, for
    the docs' table. ``draw(run, c)``: {file name: Figure} for component ``c`` of ``run``; empty
    when the recording holds nothing this plot shows, PlotError when it holds part of it only.
    """

    file: str
    description: str
    draw: Callable[[RecordedRun, str], Mapping[str, object]]

    def matches(self, component: str, file: str) -> bool:
        """Whether ``file`` is one this plot declares for ``component``."""
        pattern = re.escape(self.file).replace(re.escape("{c}"), re.escape(component))
        return re.fullmatch(re.sub(r"\\\{\w+\\\}", "[^/]+", pattern), file) is not None


@dataclass
class RecordedRun:
    """A recording as the plots read it: the resolved ``config`` (config.yaml), the ``columns`` of
    signals.parquet by name and ``time`` (s). ``config_dir``: the directory of the run's original
    config file (relative paths in ``config`` start there), None when unknown."""

    config: dict
    columns: dict[str, np.ndarray]
    time: np.ndarray
    config_dir: Path | None
    record_dir: Path | None = None  # the recording directory (files beside signals.parquet), if read from one

    def parameters(self, component: str) -> dict:
        """The component's parameters as the config gives them (raw: units as written)."""
        return ((self.config.get("components") or {}).get(component) or {}).get("parameters") or {}

    def vector(self, name: str, n: int | None = None) -> np.ndarray | None:
        """Columns ``name[0..n-1]`` as an (rows, n) array (all of them when n is None); None if absent."""
        if n is None:
            n = 0
            while f"{name}[{n}]" in self.columns:
                n += 1
        if n == 0 or any(f"{name}[{i}]" not in self.columns for i in range(n)):
            return None
        return np.column_stack([self.columns[f"{name}[{i}]"] for i in range(n)])

    def variable(self, name: str) -> np.ndarray | None:
        """A recorded variable as an (rows, size) array: a scalar's column, or a vector's columns; None if absent."""
        if name in self.columns:
            return self.columns[name][:, None]
        return self.vector(name)

    def source(self, component: str, variable: str) -> str | None:
        """The output feeding ``component.variable`` (``dynamics.humanoid.position``), if connected."""
        return (self.config.get("connections") or {}).get(f"{component}.{variable}")

    def joint_names(self, urdf, n: int) -> list[str]:
        """Names of a URDF's n movable joints (file order) if it can be found, else tau[i]. ``urdf``
        is resolved as the run resolved it (:func:`read_model`, relative to ``config_dir``)."""
        from components.errors import ConfigError
        from components.robots.model import read_model

        try:
            names = read_model(urdf, self.config_dir, "urdf").movable_joints
        except (ConfigError, OSError):
            names = []
        return names if len(names) == n else [f"tau[{i}]" for i in range(n)]
