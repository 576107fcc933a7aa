"""Sensor components: truth in, measurement out, with declared units, their own rate and seeded
noise that replays bit for bit (:mod:`components.sensors.components`; the shared noise models,
the seeded stream and the latency buffer are in :mod:`components.noise`).

- ``sensor.imu``: angular rate and specific force, body axes, + bias (constant or a random walk)
  + white noise.
- ``sensor.force_torque``: a wrench (force, torque), sensor axes, + bias + white noise.
- ``sensor.relative_pose``: the target frame's pose in the sensor frame (p, q_sensor_target) +
  position and small-angle rotation noise, delayed by a latency, with the time it was taken.
"""
