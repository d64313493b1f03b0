"""Benchmarks run by `antarium bench TARGET` (registered in `antarium.commands.bench.TARGETS`)."""
