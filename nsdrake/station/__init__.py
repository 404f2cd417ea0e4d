"""The simulated station: the arm's plant and its model files, the plate on its force
sensor, compliant contact, the contact monitor, the torque hold, gear friction and belt
drives, and its Meshcat visualizers. Builds on :mod:`nsdrake.control` (the arm model and
obstacle geometry); knows nothing of scenarios or reports."""
