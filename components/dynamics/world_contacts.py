"""Which bodies of an :class:`~components.dynamics.world.OrbitalWorld` touch in their initial poses
(the component's check warns of them: rk4 has no contacts)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from components.rotations import quat_to_matrix

if TYPE_CHECKING:
    from components.dynamics.world import OrbitalWorld


def initial_overlaps(world: OrbitalWorld) -> list[tuple[str, str, str, str, float]]:
    """Pairs of bodies whose collision geometry overlaps in their initial poses (DART engine;
    Bullet's narrow phase): (body, link, other body, its link, penetration depth m), the
    deepest contact of each pair. rk4 has no contacts: such bodies pass through each other.
    The skeletons are posed by DART's own conversions (no kernel compiles for a check)."""
    if world.engine != "dart":
        return []
    import dartpy as dart

    from components.dynamics.dart_body import DartBody

    R_WL = quat_to_matrix(world.q_eci_lvlh)
    for body in world.bodies.values():
        spec = body.spec
        p, R = np.asarray(spec.position, dtype=float), quat_to_matrix(spec.orientation)
        if spec.frame == "lvlh":
            p, R = R_WL @ p, R_WL @ R
        T = dart.math.Isometry3()
        T.set_rotation(R)
        T.set_translation(p)
        positions = np.zeros(body.ndofs)
        positions[:6] = dart.dynamics.FreeJoint.convertToPositions(T)
        for j, k in zip(body.joints, body.dof_index):
            if k >= 0:
                positions[k] = spec.q.get(j, 0.0)
        body.set_state(positions, body.velocities())

    detector = dart.collision.BulletCollisionDetector()
    groups = {}
    for name, body in world.bodies.items():
        assert isinstance(body, DartBody)  # engine dart
        group = detector.createCollisionGroup()
        for i in range(body.skel.getNumBodyNodes()):
            group.addShapeFramesOf(body.skel.getBodyNode(i))
        groups[name] = group
    names, found = list(groups), []
    option = dart.collision.CollisionOption()
    option.enableContact, option.maxNumContacts = True, 100
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            result = dart.collision.CollisionResult()
            if not groups[a].collide(groups[b], option, result) or not result.getNumContacts():
                continue
            deepest = max(
                (result.getContact(k) for k in range(result.getNumContacts())), key=lambda c: c.penetrationDepth
            )
            found.append(
                (
                    a,
                    deepest.collisionObject1.getShapeFrame().getBodyNode().getName(),
                    b,
                    deepest.collisionObject2.getShapeFrame().getBodyNode().getName(),
                    float(deepest.penetrationDepth),
                )
            )
    return found
