"""Sim-vs-real for the gripper (docs/realgap.md): the tendon protocol in simulation, logs of
tip distances, their replay and the calibration of the tendon map."""
