"""Assembling a runnable station: databases, boards, physics, devices, robots and tasks on one loop."""
