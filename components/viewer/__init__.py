"""The ``viewer.rerun`` observer: Zenorbit runs in Rerun, live or replayed.

- ``scene``: ``SceneLogger`` turns rows of recorded signals into Rerun log calls and lays them
  out (blueprint): each component type draws its part through its ``view`` (a ``View``: the
  dynamics' robots, the controllers' paths and plots, the orbit), the rest are plain signals.
  No bus, no I/O.
- ``robot``: URDF visuals and forward kinematics for batches of rows.
- ``sinks``: spawn (desktop viewer), web (viewer on localhost), save (.rrd); Rerun analytics off.
- ``observer``: the process the orchestrator starts for ``run --view`` (bus -> ``SceneLogger``).
- ``replay``: ``orchestrator view DIR`` (a recording -> ``SceneLogger``).
"""
