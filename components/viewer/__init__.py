"""The ``viewer.rerun`` observer: Zenorbit runs in Rerun, live or replayed.

- ``scene``: ``SceneLogger`` turns rows of recorded signals into Rerun log calls (robots by
  Pinocchio forward kinematics, end-effector paths, orbit and LVLH, the paper's plots) and
  lays them out (blueprint). No bus, no I/O.
- ``robot``: URDF visuals and forward kinematics for batches of rows.
- ``sinks``: spawn (desktop viewer), web (viewer on localhost), save (.rrd); Rerun analytics off.
- ``observer``: the process the orchestrator starts for ``run --view`` (bus -> ``SceneLogger``).
- ``replay``: ``orchestrator view DIR`` (a recording -> ``SceneLogger``).
"""
