"""Devices: the simulated plants (and, later, serial and CAN drivers)."""
