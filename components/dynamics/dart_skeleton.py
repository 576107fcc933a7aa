"""A URDF as DART's skeleton on a free-floating base: loaded, and DART's C++ warnings turned into notes."""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from components.dynamics.bodies import BodySpec, ModelError
from components.robots.urdf import UrdfModel, dart_urdf_text


def load_skeleton(spec: BodySpec, model: UrdfModel, locked, dart):
    """The body's skeleton (no gravity, no self-collision; its root a FreeJoint, else ModelError)
    and the notes on what DART warned of: the links without mass that a joint moves."""
    loader = dart.utils.DartLoader()
    options = dart.utils.DartLoader.Options()
    options.mDefaultRootJointType = dart.utils.DartLoader.RootJointType.FLOATING
    frames = model.frame_links()
    if any(not link.has_inertial and link.name not in frames for link in model.links):
        massless = dart.dynamics.Inertia()  # links without <inertial>: 0 kg, as in URDF
        massless.setMass(0.0)  # (DART's default is 1 kg; it warns on 0)
        massless.setMoment(np.zeros((3, 3)))
        options.mDefaultInertia = massless
    loader.setOptions(options)
    uri = dart.common.Uri.createFromPath(str(Path(spec.urdf).resolve()))
    with _captured_stderr() as said:  # DART's C++ warnings: one note instead of raw lines
        skel = loader.parseSkeletonString(dart_urdf_text(model, locked), uri)
    notes = _engine_notes(model, said.text)
    if skel is None:
        raise ModelError(f"{spec.name}.urdf", f"DART could not load {spec.urdf}")
    skel.setName(spec.name)
    skel.setGravity(np.zeros(3))
    skel.disableSelfCollisionCheck()
    if skel.getRootJoint().getType() != "FreeJoint":
        raise ModelError(
            f"{spec.name}.urdf", f"expected a free-floating base, DART made a {skel.getRootJoint().getType()}"
        )
    return skel, notes


def _engine_notes(model: UrdfModel, said: str) -> list[str]:
    """A note on the massless links DART warned of (``said``); its other warnings go to stderr."""
    # a massless link a fixed joint holds is harmless (it only adds a frame): no warning of it
    held = {j.child for j in model.joints if j.type == "fixed"}
    massless = [
        name for name in re.findall(r"zero mass \[[^\]]*\] is set to BodyNode \[([^\]]+)\]", said) if name not in held
    ]
    other = [line for line in said.splitlines() if line.strip() and "zero mass" not in line]
    if other:
        print("\n".join(other), file=sys.stderr)
    return (
        [
            f"{len(massless)} link(s) without mass that a joint moves, as the URDF gives them "
            f"(no <inertial>): {', '.join(massless)}; DART warns of them"
        ]
        if massless
        else []
    )


class _Said:
    text = ""


@contextlib.contextmanager
def _captured_stderr():
    """What C++ writes to file descriptor 2 meanwhile, as ``.text`` after the block."""
    said = _Said()
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            said.text = re.sub(r"\x1b\[[0-9;]*m", "", sink.read().decode(errors="replace"))
