"""The physics behind the simulated boards.

Reads actuator registers, writes sensor registers; fault injection.
"""
