"""Level 1: register-level boards and their simulated implementations.

8031 RAM image and ports, DAC, ADC, counter and stepper channels.
"""
