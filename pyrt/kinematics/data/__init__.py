"""Data files of pyrt.kinematics: the packaged robot descriptions (puma560.urdf)."""
