"""pyrt-arm: a two-joint planar arm on pyrt, built only from pyrt's public API.

The station is :data:`pyrt_arm.station.ARM` (``pyrt arm``, ``pyrt board-sim arm``);
see ``README.md`` and pyrt's ``docs/writing-a-robot.md``.
"""
