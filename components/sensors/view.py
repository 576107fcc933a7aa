"""What a sensor draws in Rerun (its type's ``view``): each measurement beside the true value it was
made from (the output feeding the ``*_true`` input, when recorded), in a tab.

| entity | what |
|---|---|
| ``/plots/<sensor>/<output>/measured``, ``/plots/<sensor>/<output>/true`` | the measurement and its true value, per element |
"""

from __future__ import annotations

from components.viewer.scene import LIGHT_AXIS_COLORS, Batch, Layout, View, entity_path


class SensorView(View):
    """``measures`` (the type's, output -> the input it measures) as pairs of plot series."""

    def __init__(self, name, parameters, scene):
        super().__init__(name, parameters, scene)
        self.pairs = []  # (output, its columns, its true value's columns or None)
        for output, true_input in scene.types[name].measures.items():
            measured = scene.take(name, output)
            if measured is None:
                continue
            source = scene.connections.get(f"{name}.{true_input}", "")
            component, _, variable = source.partition(".")
            self.pairs.append((output, measured, scene.find(component, variable, len(measured)) if source else None))

    def log_static(self, scene):
        for output, measured, true in self.pairs:
            names = [output] if len(measured) == 1 else [f"{output}[{k}]" for k in range(len(measured))]
            scene.series(entity_path("plots", self.name, output, "measured"), names)
            if true is not None:
                scene.series(
                    entity_path("plots", self.name, output, "true"),
                    [f"{n} true" for n in names],
                    LIGHT_AXIS_COLORS if len(names) <= 3 else None,
                )

    def log_rows(self, scene, batch: Batch):
        for output, measured, true in self.pairs:
            batch.scalars(entity_path("plots", self.name, output, "measured"), measured)
            if true is not None:
                batch.scalars(entity_path("plots", self.name, output, "true"), true)

    def layout(self, scene):
        import rerun.blueprint as rrb

        return Layout(
            tabs=[
                rrb.TimeSeriesView(
                    origin=entity_path("plots", self.name, output), name=f"{self.name}.{output}: measured and true"
                )
                for output, _, _ in self.pairs
            ]
        )
