"""The ROS 2 graph without a ROS install: DDS participants, writers of pre-built CDR, readers of
requests (cyclonedds) and the bridge that publishes the cameras. May import service and below; not viewers or record."""
