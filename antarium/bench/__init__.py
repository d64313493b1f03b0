"""Benchmarks (`antarium bench TARGET`), each reported as ratios to the dome's needs (`antarium.core.rates`).

Every module here has `run(args) -> int`; `TARGETS` maps a benchmark's name to it (imported when run).
"""

#: benchmark name -> "module:function"; the function takes the parsed args and returns an exit code.
TARGETS: dict[str, str] = {
    "loop": "antarium.bench.loop:run",
    "ant": "antarium.bench.ant:run",
    "trackball": "antarium.bench.trackball:run",
    "protocol": "antarium.bench.protocol:run",
    "render": "antarium.bench.render:run",
    "jitter": "antarium.bench.jitter:run",
    "servosphere": "antarium.bench.servosphere:run",
    "monitor": "antarium.bench.monitor:run",
    "experiment": "antarium.bench.experiment:run",
}
