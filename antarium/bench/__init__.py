"""Benchmarks run by `antarium bench` (see `antarium.commands.bench.TARGETS`)."""
