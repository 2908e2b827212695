"""Level 1: register-level boards (8031 RAM image and ports, DAC, ADC, counter and stepper channels) and their simulated implementations."""
