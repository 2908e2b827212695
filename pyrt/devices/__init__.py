"""Levels 2-3: Motor, Encoder, Loadcell and the gripper's jaw drive and sensors; calibrations from registers to physical units."""
