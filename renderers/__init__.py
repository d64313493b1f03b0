"""Off-screen rendering: cube maps of a 3D scene sampled per LED."""
