"""The ``arm`` station: registered as ``arm`` in the entry-point group ``pyrt.stations``.

The station (its components, commands, servo and trajectory tasks and register-level
boards) is built on pyrt's public station API on top of :mod:`pyrt_arm.kinematics`,
:mod:`pyrt_arm.plant` and :mod:`pyrt_arm.servo`.
"""

from __future__ import annotations

# Wired in phase 2, once pyrt's public station API has landed: ARM becomes the
# station factory (the entry point pyrt_arm.station:ARM). Until then the entry point
# loads as None, which pyrt lists as a station that cannot be loaded.
ARM = None
