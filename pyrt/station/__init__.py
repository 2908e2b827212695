"""Assembling a runnable station: boards, physics, devices, robots and tasks on one loop."""
