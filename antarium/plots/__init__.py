"""Every picture the project writes: matplotlib (Agg) figures and LED maps, one module per subject."""
