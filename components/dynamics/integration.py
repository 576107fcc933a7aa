"""The manifold RK4 step of an OrbitalWorld's bodies, with joint stops, mimic joints and the grasp's weld.

Engine-neutral: a body (components/dynamics/bodies.py) gives its state, forward dynamics and
inverse mass matrix in the world's coordinates; the stage arithmetic is compiled in
:mod:`components.dynamics.manifold_rk4`. A stage state is q0 (+) xi with velocities v; the base
rotation moves as R = exp(xi_w) R0 at world angular velocity omega, so d(xi_w)/dt =
J_l(xi_w)^-1 omega, every other coordinate has d(xi)/dt = v.

Joint stops (rk4): a joint found past a limit has its outward rate cancelled by a joint-space
impulse and rests on the stop until its acceleration points back inside; mimic joints: each
stage's accelerations projected onto the constraint. Both act through joint-space forces, internal
to the body: its momentum is unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

import numpy as np

from components.constants import R_EARTH
from components.dynamics import link_forces
from components.dynamics.bodies import Body
from components.dynamics.capture import Grasp


class SteppedWorld(Protocol):
    """What a step reads of its world (an OrbitalWorld): read-only, so a dict of bodies and an
    array orbit point qualify."""

    @property
    def bodies(self) -> Mapping[str, Body]: ...
    @property
    def integrator(self) -> str: ...  # "rk4" or "dart"
    @property
    def mu(self) -> float: ...  # m^3/s^2
    @property
    def orbit_point(self) -> object: ...  # the reference orbit's state at the stage (None before the first)
    @property
    def env_now(self) -> bool: ...  # the environment's forces act
    @property
    def joint_limits(self) -> bool: ...
    @property
    def grasp(self) -> Grasp | None: ...


def compile_kernels(world: SteppedWorld) -> None:
    """Compile the numba kernels a step calls (or load them from numba's on-disk cache), now.

    A cold compile takes seconds (~6 s on one idle core): done inside step 0 it counted against
    ``run.step_timeout``; here, at construction (the component's instantiate), it counts against
    ``run.start_timeout``. The calls pass the argument types the steps pass (the same
    expressions), so no step compiles another signature; the machine code is the one a first step
    would have compiled: the numbers do not change. The bodies' states are kept: the environment
    calls only fill per-link scratch arrays that every later use fills again first, and the rk4
    kernels get zeros and return new arrays."""
    R, V = np.array([R_EARTH + 400e3, 0.0, 0.0]), np.zeros(3)  # any point off the Earth's centre
    link_forces.propagate_reference(R, V, 0.5, world.mu)
    for body in world.bodies.values():
        state = body.positions().copy(), body.velocities().copy()
        body.environment_wrenches(R, V)
        if body.has_srp:
            body.srp_wrenches(R, V)
        if world.integrator == "rk4":
            zeros = np.zeros(body.ndofs)
            body.set_state(zeros, zeros)
            body.begin_step()
            for stage in (1, 2, 3):
                body.next_stage(stage, 0.5, zeros)
                body.forward_dynamics((np.concatenate([R, V]), 0.5))
            body.finish_step(1.0, zeros)
            body.forward_dynamics(None)
            body.rk4_step(1.0, (np.concatenate([R, V]), 0.5))
            body.rk4_step(1.0, None)
            try:
                body.inverse_mass()  # (limit stops, mimic joints, a grasp)
            except np.linalg.LinAlgError:
                pass  # singular at zero q (a massless link a joint moves, warned at check): compiled at first use
            body.point_jacobian(body.link_names[0], zeros[:3])
            body.point_bias(body.link_names[0], zeros[:3])
        body.set_state(*state)


def acceleration(world: SteppedWorld, body: Body, s: float) -> np.ndarray:
    """Accelerations at the body's current state, torques and (when it applies) the environment
    at s seconds after the orbit inputs; mimic joints and limit stops held."""
    a = body.forward_dynamics((world.orbit_point, s) if world.env_now else None)
    if body.mimic:
        a = hold_mimic(body, a)
    if body.stops.size:
        a = hold_stops(body, a)
    return a


def hold_mimic(body: Body, a: np.ndarray) -> np.ndarray:
    """Accelerations that keep the mimic constraints (J a = 0; J is constant, so J qd stays 0
    too): the joint-space constraint force M^-1 J^T lambda, internal to the body."""
    Minv = body.inverse_mass()
    J = body.mimic_J
    MJ = Minv @ J.T
    return a - MJ @ np.linalg.solve(J @ MJ, J @ a)


def hold_stops(body: Body, a: np.ndarray) -> np.ndarray:
    """Joints resting on a limit stop: a joint-space constraint torque (internal, momentum-free)
    cancels their outward acceleration; a stop that would have to pull lets go."""
    Minv = body.inverse_mass()
    dofs, sides = body.stops, body.stop_sides
    keep = np.ones(dofs.size, dtype=bool)
    for _ in range(dofs.size):
        S = dofs[keep]
        if S.size == 0:
            return a
        torque = np.linalg.solve(Minv[np.ix_(S, S)], -a[S])
        pulling = sides[keep] * torque > 0.0
        if not np.any(pulling):
            return a + Minv[:, S] @ torque
        keep[np.flatnonzero(keep)[pulling]] = False
    return a


def joint_stops(body: Body) -> None:
    """Inelastic joint stops, after a step. A joint found past a limit has its outward rate
    cancelled by a joint-space impulse and rests on the stop (``hold_stops``) until its
    acceleration points back inside. The joint stays past the limit by at most one step's travel
    (positions are not projected, which would change the momentum)."""
    q = body.positions()
    over, under = q >= body.upper, q <= body.lower
    hit = over | under
    if not hit.any():  # the common case, quickly
        if body.stops.size:
            body.stops, body.stop_sides = np.zeros(0, dtype=int), np.zeros(0)
        return
    stops = np.flatnonzero(hit)
    body.stops, body.stop_sides = stops, np.where(over[stops], 1.0, -1.0)
    v = body.velocities()
    outward = stops[body.stop_sides * v[stops] > 0.0]
    if outward.size:
        Minv = body.inverse_mass()
        impulse = np.linalg.solve(Minv[np.ix_(outward, outward)], -v[outward])
        body.set_velocities(v + Minv[:, outward] @ impulse)


def rk4(world: SteppedWorld, body: Body, h: float, s: float) -> None:
    """One RK4 step of h seconds of one body, from s seconds after the orbit inputs."""
    if not body.mimic and not body.stops.size:  # nothing acts between the stages: the body steps itself
        body.rk4_step(h, (world.orbit_point, s) if world.env_now else None)
    else:
        rk4_held(world, body, h, s)
    if world.joint_limits and body.limited:
        joint_stops(body)


def rk4_held(world: SteppedWorld, body: Body, h: float, s: float) -> None:
    """``rk4`` with each stage's accelerations held to the mimic joints and limit stops."""
    body.begin_step()
    a = acceleration(world, body, s)  # at (q0, v0), the current state
    body.next_stage(1, 0.5 * h, a)
    a = acceleration(world, body, s + 0.5 * h)
    body.next_stage(2, 0.5 * h, a)
    a = acceleration(world, body, s + 0.5 * h)
    body.next_stage(3, h, a)
    body.finish_step(h, acceleration(world, body, s + h))


def rk4_welded(world: SteppedWorld, h: float, s: float) -> None:
    """One RK4 step of every body, stage by stage, with the grasp's weld wrench in each stage's
    accelerations (the welded pair is one assembly; the others step as in ``rk4``)."""
    grasp = world.grasp
    assert grasp is not None, "a welded step needs the closed grasp"
    bodies = list(world.bodies.values())
    chaser, target = grasp.ee.body, grasp.grasp.body

    def accelerations(t: float) -> dict:
        a = {b.name: acceleration(world, b, t) for b in bodies}
        a[chaser.name], a[target.name] = grasp.constrain(a[chaser.name], a[target.name], h)
        return a

    for b in bodies:
        b.begin_step()
    a = accelerations(s)
    for stage, c, t in ((1, 0.5 * h, s + 0.5 * h), (2, 0.5 * h, s + 0.5 * h), (3, h, s + h)):
        for b in bodies:
            b.next_stage(stage, c, a[b.name])
        a = accelerations(t)
    for b in bodies:
        b.finish_step(h, a[b.name])
    stopped = False
    if world.joint_limits:
        for b in bodies:
            if b.limited:
                joint_stops(b)
                stopped = stopped or b.stops.size > 0
    if stopped:
        grasp.project()  # a stop's impulse moved one side of the weld: the other follows, momentum kept
