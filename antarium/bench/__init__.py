"""Benchmarks run by `antarium bench TARGET` (one module per target)."""
