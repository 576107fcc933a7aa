"""What every plot module shares: its error and a figure on Matplotlib's Agg canvas (no pyplot)."""


class PlotError(Exception):
    """A recording that cannot be plotted (missing files or columns)."""


def new_figure(*size):
    from matplotlib.figure import Figure
    return Figure(figsize=size, layout="constrained")
