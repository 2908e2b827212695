"""Kinematic chains."""
