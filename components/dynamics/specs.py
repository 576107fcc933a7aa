"""The dynamics' validated parameters as what its world is built from: each body's URDF model and
``BodySpec``, the atmosphere."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from components.errors import ConfigError
from components.robots.model import body_items, read_model
from components.robots.urdf import UrdfModel
from components.sdk import RunSettings


def load_models(params: Mapping[str, Any], run: RunSettings) -> dict[str, UrdfModel]:
    """Parsed URDF of every body (xml.etree only); ConfigError naming ``bodies.<name>.urdf``."""
    return {
        name: read_model(body["urdf"], run.config_dir, f"bodies.{name}.urdf", run.packages)
        for name, body in body_items(params["bodies"])
    }


def initial_twist(body: Mapping[str, Any]) -> list[float]:
    """A body's ``twist`` as the 6-vector (linear, angular) in its ``frame``: given so, or from its
    parts ``{rate, axis, axes, linear}`` (the axis normalized, in the body's own axes turned into
    the frame by ``orientation`` for ``axes: body``)."""
    twist = body["twist"]
    if not isinstance(twist, Mapping):
        return list(twist)
    axis = np.asarray(twist["axis"], dtype=float)
    norm = float(np.linalg.norm(axis))
    if not norm > 0.0:
        raise ConfigError("twist.axis", f"expected a direction (a vector that is not zero), got {list(twist['axis'])}")
    axis = axis / norm
    if twist["axes"] == "body":
        from components.rotations import quat_to_matrix

        axis = quat_to_matrix(np.asarray(body["orientation"], dtype=float)) @ axis
    return [float(x) for x in twist["linear"]] + [float(x) for x in twist["rate"] * axis]


def body_twist(name: str, body: Mapping[str, Any]) -> list[float]:
    try:
        return initial_twist(body)
    except ConfigError as e:
        raise ConfigError(f"bodies.{name}.{e.key}", e.message) from None


def body_specs(params: Mapping[str, Any], models: Mapping[str, UrdfModel]):
    """BodySpec of every body, values in SI; ConfigError naming the key."""
    from components.dynamics.world import BodySpec, ModelError, check_spec

    specs = []
    for name, body in body_items(params["bodies"]):
        model = models[name]
        area, cd, srp_area = body["drag_area"], body["drag_cd"], body["srp_area"]
        spec = BodySpec(
            name=name,
            urdf=model.path,
            frame=body["frame"],
            position=body["position"],
            orientation=body["orientation"],
            twist=body_twist(name, body),
            q=dict(body["q"]),
            qd=dict(body["qd"]),
            locked_joints=tuple(body["locked_joints"]),
            drag_area=area if isinstance(area, Mapping) else {model.root: area},
            drag_cd=cd,
            srp_area=srp_area if isinstance(srp_area, Mapping) else {model.root: srp_area},
            srp_cr=body["srp_cr"],
            srp_facets={link: list(facets) for link, facets in body["srp_facets"].items()},
        )
        try:
            check_spec(spec, model)
        except ModelError as e:
            raise ConfigError(f"bodies.{e.key}", e.message) from None
        specs.append(spec)
    return specs


def world_atmosphere(atmosphere: Mapping | None, epoch):
    """The world's atmosphere: None (the table), one exponential layer, or NRLMSISE-00 as a local exponential."""
    from components.space.atmosphere import ExponentialAtmosphere, LocalExponential, Nrlmsise00
    from components.space.parameters import exponential_layer

    if atmosphere is None or atmosphere["model"] == "exponential":
        layer = exponential_layer(atmosphere)
        return None if layer is None else ExponentialAtmosphere(single=layer)
    return LocalExponential(
        Nrlmsise00(atmosphere["f107"], atmosphere["f107a"], atmosphere["ap"], model=atmosphere["model"]), epoch
    )
