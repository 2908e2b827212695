"""Levels 2-3: Motor, Encoder, Loadcell and the gripper's jaw drive and sensors.

Calibrations from registers to physical units.
"""
