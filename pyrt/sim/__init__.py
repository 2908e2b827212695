"""The physics behind the simulated boards: reads actuator registers, writes sensor registers; fault injection."""
