"""The sensors' plot (``orchestrator plot``): each measurement against the true value it was made
from (the output feeding the sensor's ``*_true`` input), element by element."""

from __future__ import annotations

from collections.abc import Mapping

from components.plotting import Plot, RecordedRun, new_figure


def measured_against_true(pairs: Mapping[str, str]) -> Plot:
    """The plot of a sensor whose outputs are measurements of its inputs: ``pairs`` maps an output
    (``rate``) to the input it measures (``rate_true``)."""

    def draw(run: RecordedRun, c: str) -> dict:
        found = {output: run.variable(f"{c}.{output}") for output in pairs}
        if all(measured is None for measured in found.values()):
            return {}
        shown = {output: measured for output, measured in found.items() if measured is not None}
        fig = new_figure(9.0, 3.0 * len(shown))
        for row, (output, measured) in enumerate(shown.items(), start=1):
            ax = fig.add_subplot(len(shown), 1, row)
            source = run.source(c, pairs[output])
            true = run.variable(source) if source else None
            for k in range(measured.shape[1]):
                ax.plot(run.time, measured[:, k], color=f"C{k % 10}", linewidth=1.0, label=f"{output}[{k}]")
                if true is not None and true.shape == measured.shape:
                    ax.plot(
                        run.time,
                        true[:, k],
                        color=f"C{k % 10}",
                        linestyle="--",
                        linewidth=1.0,
                        label=f"{pairs[output]}[{k}]",
                    )
            truth = f"against {source} (dashed)" if true is not None else f"({pairs[output]} not recorded)"
            ax.set(xlabel="time (s)", title=f"{c}.{output} (solid) {truth}")
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper right", fontsize="x-small", ncols=2)
        return {f"{c}_measured.png": fig}

    return Plot(
        "{c}_measured.png",
        f"{', '.join(pairs)} (solid) against the outputs feeding {', '.join(pairs.values())} (dashed), per element",
        draw,
    )
