"""Fiducial markers fixed to a link, declared once in a YAML file beside the model: read by the
estimator (``estimator.fiducial``) and by the generator of the markers' meshes
(``orchestrator markers``). No OpenCV here: the file is plain data.

A marker's frame is OpenCV's ArUco convention: origin at the centre of its black square, x to the
right and y up as the printed marker reads, z out of its face (towards whoever sees it). Its pose
in the link frame is ``position`` (m) and ``orientation`` (``q_link_marker`` [x, y, z, w]);
``size`` (m) is the side of the black square. Each marker's mesh adds ``quiet_zone`` white
cells around that square (a detector needs white around the border), so the drawn square is
``size * (cells + 2 quiet_zone) / cells`` on a side, ``cells`` the dictionary's bits plus its
one-cell black border.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from components.errors import ConfigError
from components.rotations import quat_to_matrix
from components.schema import Float, Int, ListOf, Parameter, Problems, Record, Str, Vector

# dictionary name (cv2.aruco's) -> bits on a side of its markers
DICTIONARIES = {
    "DICT_4X4_50": 4,
    "DICT_4X4_100": 4,
    "DICT_5X5_50": 5,
    "DICT_5X5_100": 5,
    "DICT_6X6_50": 6,
    "DICT_6X6_100": 6,
    "DICT_APRILTAG_36h11": 6,
}
# how many markers each dictionary holds (ids 0 .. n-1)
DICTIONARY_SIZES = {
    "DICT_4X4_50": 50,
    "DICT_4X4_100": 100,
    "DICT_5X5_50": 50,
    "DICT_5X5_100": 100,
    "DICT_6X6_50": 50,
    "DICT_6X6_100": 100,
    "DICT_APRILTAG_36h11": 587,
}

MARKER = Record(
    "Marker",
    (
        Parameter("id", Int(minimum=0), description="the marker's id in the dictionary"),
        Parameter(
            "size",
            Float("m", positive=True, plausible=(1e-3, 10.0)),
            description="side of its black square (the outer edge of its border)",
        ),
        Parameter("position", Vector(3, "m", plausible=(-100.0, 100.0)), description="its centre in the link frame"),
        Parameter(
            "orientation", Vector(4), description="q_link_marker [x, y, z, w]: marker x right, y up, z out of its face"
        ),
    ),
)
LAYOUT = Record(
    "MarkerLayout",
    (
        Parameter("dictionary", Str(tuple(DICTIONARIES)), description="the markers' dictionary (OpenCV aruco)"),
        Parameter("link", Str(), description="the link they are fixed to: the estimator measures its frame's pose"),
        Parameter("quiet_zone", Int(minimum=1), description="white cells drawn around each marker's black square"),
        Parameter(
            "mesh",
            Str(),
            description="where the generator writes the markers' meshes, relative to this file: "
            "<mesh>_white.obj and <mesh>_black.obj",
        ),
        Parameter("markers", ListOf(MARKER, min_items=1), description="the markers"),
    ),
)


@dataclass(frozen=True)
class Marker:
    id: int
    size: float  # m: side of the black square
    p_link_marker: np.ndarray  # m: centre, link frame
    R_link_marker: np.ndarray  # 3x3: marker axes in the link frame

    def corners(self, side: float | None = None) -> np.ndarray:
        """The square's corners (m, link frame) in OpenCV's order: top-left, top-right,
        bottom-right, bottom-left as the marker reads; ``side`` defaults to ``size``."""
        h = 0.5 * (self.size if side is None else side)
        local = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
        return self.p_link_marker + local @ self.R_link_marker.T


@dataclass(frozen=True)
class MarkerLayout:
    path: Path
    dictionary: str
    link: str
    quiet_zone: int
    mesh: Path  # absolute: the meshes' common stem
    markers: tuple[Marker, ...]

    @property
    def cells(self) -> int:
        """Cells on a side of a marker's black square: its bits and a one-cell border each side."""
        return DICTIONARIES[self.dictionary] + 2

    @property
    def quad_scale(self) -> float:
        """The drawn square's side over the black square's (the quiet zone around it)."""
        return (self.cells + 2 * self.quiet_zone) / self.cells

    def by_id(self) -> dict[int, Marker]:
        return {m.id: m for m in self.markers}


def layout_path(value: str, config_dir: str | Path | None) -> Path:
    """A layout file a config names: absolute, else relative to the config, else to the project
    root; ConfigError (key ``markers``) when none exists."""
    from components.robots.model import PROJECT_ROOT

    path = Path(value)
    candidates = [path] if path.is_absolute() else [Path(config_dir or ".") / path, PROJECT_ROOT / path]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise ConfigError("markers", f"marker layout {value!r} not found (looked in: {', '.join(map(str, candidates))})")


def read_layout(path: str | Path, key: str = "markers") -> MarkerLayout:
    """The layout in a YAML file; ConfigError naming ``key`` (then the field inside the file)."""
    path = Path(path)
    try:
        raw: Any = yaml.safe_load(path.read_text())
    except OSError as e:
        raise ConfigError(key, f"cannot read the marker layout {path}: {e.strerror}") from None
    except yaml.YAMLError as e:
        raise ConfigError(key, f"{path} is not YAML: {e}") from None
    try:
        data = LAYOUT.convert(raw, "")
    except Problems as e:
        raise ConfigError(f"{key}", f"{path}: {'; '.join(str(p) for p in e.problems)}") from None
    except ConfigError as e:
        raise ConfigError(key, f"{path}: {e}") from None
    markers = []
    for i, m in enumerate(data["markers"]):
        where = f"{path}: markers[{i}]"
        if m["id"] >= DICTIONARY_SIZES[data["dictionary"]]:
            raise ConfigError(
                key,
                f"{where}.id: {data['dictionary']} has ids 0 to "
                f"{DICTIONARY_SIZES[data['dictionary']] - 1}, got {m['id']}",
            )
        norm = float(np.linalg.norm(m["orientation"]))
        if not abs(norm - 1.0) < 1e-6:
            raise ConfigError(key, f"{where}.orientation: expected a unit quaternion, got norm {norm:.9g}")
        markers.append(Marker(m["id"], m["size"], m["position"], quat_to_matrix(m["orientation"] / norm)))
    ids = [m.id for m in markers]
    repeated = sorted({i for i in ids if ids.count(i) > 1})
    if repeated:
        raise ConfigError(key, f"{path}: marker id {repeated[0]} listed twice (each id once: it names the marker)")
    return MarkerLayout(
        path.resolve(),
        data["dictionary"],
        data["link"],
        data["quiet_zone"],
        (path.parent / data["mesh"]).resolve(),
        tuple(markers),
    )
