"""Recordings in other formats: rosbag2 with MCAP storage (:mod:`orchestrator.export.rosbag2`)."""
