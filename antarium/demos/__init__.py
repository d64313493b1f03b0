"""What `antarium demo` runs: the served embedded default rig, and the virtual ant in the closed loop."""
