"""Benchmarks (`antarium bench TARGET`), each reported as ratios to the dome's needs (`antarium.core.rates`).

Every module here has `run(args) -> int`; `TARGETS` maps a benchmark's name to it (imported when run), `OPTIONS`
says which of `antarium bench`'s options it takes and what each means there. Each writes its --json file with
`write_json`, so that every file has the same "run" table and is strict JSON.
"""

from __future__ import annotations

import datetime
import os
import platform
import sys
from typing import Any

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

#: benchmark name -> the options it takes (`--json` aside, which every one takes) -> what the option means there
#: ("": the option's own meaning, its help text). `antarium bench` refuses the others, and builds each option's help
#: from this table.
OPTIONS: dict[str, dict[str, str]] = {
    "loop": {"--seconds": "run for S seconds (default 30)", "--frames": "run N frames (with --seconds: whichever "
             "ends first)", "--path": "", "--machine-probe": "", "--load-every": "", "--displace-every": "",
             "--edit-every": "", "--sky-every": ""},
    "monitor": {"--seconds": "each of the three loop runs, S seconds (default 30)",
                "--frames": "each of the three loop runs, N frames", "--browser-idle": ""},
    "jitter": {"--seconds": "measure S seconds of frame slots (default 30)",
               "--frames": "measure N frame slots (with --seconds: whichever ends first)", "--work-ms": ""},
    "render": {"--frames": "N frames per workload (default 300)", "--path": ""},
    "protocol": {"--seconds": "S seconds for each encode and decode figure (default 2)",
                 "--frames": "N frames sent over loopback at 190/s (default 950)"},
    "servosphere": {"--seconds": "S simulated seconds of the closed loop (default 20)",
                    "--frames": "N frames for the tracker's figure (default 5000)"},
    "ant": {"--seconds": "S seconds for each figure (default 2)",
            "--frames": "N random LED frames, cycled through and learned by the perfect-memory model (default 20)"},
    "trackball": {"--seconds": "S seconds for each of the two driver runs (default 2)",
                  "--frames": "N FicTrac lines parsed (default 100,000)"},
    "experiment": {"--seconds": "NOT seconds: the route length in metres (default 2)",
                   "--frames": "NOT frames: the number of runs (default 6)"},
}


def progress(bench: str, text: str) -> None:
    """One progress line of benchmark `bench` on stderr, at once (the report on stdout stays clean)."""
    print(f"bench {bench}: {text} ...", file=sys.stderr, flush=True)


def write_json(path: str | os.PathLike, bench: str, result: dict[str, Any]) -> None:
    """Write benchmark `bench`'s `result` (a dict of its figures) to `path` as strict JSON (NaN and inf as null),
    with a "run" table beside the figures: the bench's name, the antarium version, the host's name, platform and
    CPU count, and the time it finished (UTC, ISO 8601). An existing file is overwritten."""
    from antarium import __version__
    from antarium.ant.metrics import json_text

    run = {"bench": bench, "antarium": __version__, "host": platform.node(), "platform": platform.platform(),
           "cpus": os.cpu_count(),
           "finished_utc": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")}
    with open(path, "w") as fh:
        fh.write(json_text({"run": run, **result}))
