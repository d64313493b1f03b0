"""Wire formats of the dome, the distributor and panel emulator, LED-driver and actuator models."""
