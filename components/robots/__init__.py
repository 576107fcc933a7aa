"""Robot models shared by the dynamics, the controllers and the viewer, without a physics engine:
URDF reading (:mod:`components.robots.urdf`) and what the components make of a URDF in their
configs (:mod:`components.robots.model`: paths, bodies, joint units)."""
