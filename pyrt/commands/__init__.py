"""Command interpreters of the robots (the gripper's CMD: and monitor, the manipulator's object commands)."""
