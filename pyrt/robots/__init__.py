"""Level 4+: the gripper controller and the manipulator's Axis, AV and PolyAxis."""
