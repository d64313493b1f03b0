"""`antarium bench loop`: the whole server loop against `antarium emulate` over loopback UDP.

Runs the embedded default rig (default habitat, scripted walker in closed loop, bus on loopback, a trial
log being recorded) — or the rig config named by `$ANTARIUM_RIG_CONFIG` — for `--seconds` (default 30;
the goal is stated for 600) or `--frames`, then reads the recorded per-frame table and reports achieved
frame rate against target, late and skipped frames, closed-loop latency p50/p99/max and per-stage times,
as ratios to the dome's needs (190 frames/s, 5.3 ms frame period). The first second (warm-up) is excluded from
runs longer than 2 s (`warmup_excluded` says whether it was); the far layer's frame counts and the link outages
are counted over the same frames, what the table does not have (rejected frames, GPU busy passes, far layers
built) over the whole run, and the report says which.

With `--load-every S`, `--displace-every S`, `--edit-every S` and `--sky-every S` a script thread sends the rig's
scene again (`load_scene`), a virtual displacement (`set_pose` 0.5 m away and back), an object move (`scene_edit`)
or a move of the sun (`sky`, 60° and back) on that schedule, as an experiment script would; the report then lists
each kind's reply times and the late frames from its sending to 1 s after its reply.

With `--machine-probe`, a stall probe runs on every CPU beside it (`antarium.bench.jitter.StallProbes`, real-time
above the loop; each stays on its CPU when the server's CPU placement moves our processes, and says where it ran):
the report then says how often the machine itself stopped each CPU, and how many late frames overlap such a stall
on the loop's own CPU (the machine's) and how many do not (the loop's own). Only the loop's CPU counts (`[loop]
cpu`; every CPU when the loop has none of its own): the frame's work runs in the loop's thread, and what else
runs there (scene preparation beside the loop) runs on that CPU too. When a probe is not real-time (`[loop]
realtime_priority = 0`, or refused), its late wake-ups include our own load: the split is then unknown (null).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from antarium.config import RigConfig

import numpy as np

from antarium.bench import progress, write_json
from antarium.bench.gpu_clocks import GpuClocks
from antarium.bench.gpu_clocks import describe as describe_clocks

WARMUP_S = 1.0


def _pct(values: np.ndarray) -> dict[str, float] | None:
    values = values[np.isfinite(values)]
    if not len(values):
        return None
    p50, p99 = np.percentile(values, [50, 99])
    return {"p50_ms": 1e3 * float(p50), "p99_ms": 1e3 * float(p99), "max_ms": 1e3 * float(values.max())}


def summarise(frames: dict[str, np.ndarray], rate_hz: float,
              stalls: dict[int, tuple[bool, np.ndarray]] | None = None,
              final_stats: dict[str, Any] | None = None, loop_cpus: set[int] | None = None) -> dict[str, Any]:
    """Figures from a trial log's per-frame table (see docs/logs.md), from `StallProbes.stop()`'s `stalls` when
    given (only the probes on `loop_cpus` count; None: all, the loop having no CPU of its own), and from the
    server's `final_stats` (its whole run; the figures the table also has are counted over the kept frames)."""
    t = frames["t_start"]
    excluded = bool(len(t) and t[-1] - t[0] > 2 * WARMUP_S)
    keep = t >= t[0] + WARMUP_S if excluded else np.ones(len(t), bool)
    f = {k: v[keep] for k, v in frames.items()}
    n = int(keep.sum())
    span = float(f["t_start"][-1] - f["t_start"][0]) if n > 1 else 0.0
    achieved = (n - 1) / span if span > 0 else float("nan")
    period = 1.0 / rate_hz
    latency = _pct(f["latency"])
    return {
        "frames": n, "seconds": span, "target_rate_hz": rate_hz, "achieved_rate_hz": achieved,
        "rate_ratio": achieved / rate_hz, "late_frames": int(f["late"].sum()),
        "late_full_render": int((f["late"].astype(bool) & f["full_render"].astype(bool)).sum()),
        "full_render_frames": int(f["full_render"].sum()), "skipped_slots": int(f["skipped"].sum()),
        "latency": latency,
        "latency_p99_over_period": None if latency is None else latency["p99_ms"] / (1e3 * period),
        "stages": {k: _pct(f[k]) for k in ("render", "sample", "convert", "encode", "send")},
        "frame_work": _pct(f["t_sent"] - f["t_start"]),
        "pacing_error": _pct(f["pacing_error"]),
        "link_down_frames": int((f["link_ok"] == 0).sum()),
        "warmup_excluded": excluded, "warmup_s": WARMUP_S if excluded else 0.0,
        "machine": None if stalls is None else _machine_stalls(f, stalls, period, loop_cpus),
        "late_list": _late_list(frames, keep),
        **_run_counts(frames, keep, final_stats or {}),
    }


#: late frames listed one by one (the first of them), in the report and its JSON
LATE_LISTED = 20
#: of which the report prints
LATE_PRINTED = 8


def _late_list(frames: dict[str, np.ndarray], keep: np.ndarray) -> list[dict[str, float]]:
    """The first `LATE_LISTED` late frames among the kept ones: when (s after the run's first frame), their work,
    stages and pacing error (ms) and the slots skipped after them, to tell what held each one up."""
    t = frames["t_start"]
    rows = []
    for i in np.flatnonzero(frames["late"].astype(bool) & keep)[:LATE_LISTED]:
        row = {"t_s": float(t[i] - t[0]), "work_ms": 1e3 * float(frames["t_sent"][i] - t[i]),
               "pacing_ms": 1e3 * float(frames["pacing_error"][i]), "skipped": int(frames["skipped"][i])}
        row.update({f"{k}_ms": 1e3 * float(frames[k][i]) for k in ("render", "sample", "convert", "encode", "send")})
        rows.append(row)
    return rows


def _run_counts(frames: dict[str, np.ndarray], keep: np.ndarray, stats: dict[str, Any]) -> dict[str, Any]:
    """Link outages and the far layer's frame counts over the kept frames (from the table); rejected frames, GPU busy
    passes and far layers built over the whole run (the server's counters: the table has no such column), named in
    `whole_run`."""
    ok = frames["link_ok"].astype(bool)
    began = np.zeros(len(ok), dtype=bool)
    began[1:] = ok[:-1] & ~ok[1:]  # a frame whose link was down after one whose link was up: an outage began
    out: dict[str, Any] = {"link_outages": int((began & keep).sum()),
                           "link_outages_whole_run": stats.get("link_outages", 0),
                           "rejected_frames": stats.get("rejected_frames", 0),
                           "gpu_busy_passes": stats.get("gpu_busy_passes", 0),
                           "whole_run": ["rejected_frames", "gpu_busy_passes", "link_outages_whole_run"]}
    layer = stats.get("far_layer")
    if layer is not None:
        layer = dict(layer)
        if "full_render" in frames:
            full = int(frames["full_render"][keep].astype(bool).sum())
            layer.update(full_frames=full, layer_frames=int(keep.sum()) - full, frames_counted="kept frames")
        else:  # a table written before the column (format 1): the renderer's counts
            layer["frames_counted"] = "whole run"
        out["whole_run"].append("far_layer.builds")
    out["far_layer"] = layer
    return out


def _machine_stalls(f: dict[str, np.ndarray], stalls: dict[int, tuple[bool, np.ndarray]],
                    period: float, loop_cpus: set[int] | None = None) -> dict[str, Any]:
    """Per CPU, the probe's late wake-ups during the frames; and the late frames that overlap one on the loop's
    CPUs (`loop_cpus`; None: every CPU, the loop having none of its own). A frame spans from a probe period
    before its slot (the loop wakes 0.5 ms before it, and a stall may begin up to a probe period before the
    wake-up it delays) to its last datagram. With a probe that is not real-time the split is unknown (None): its
    late wake-ups include the delays our own load caused it."""
    from antarium.bench.jitter import LATENESS_EDGES_S, PROBE_PERIOD_S, overlapping

    t0, t1 = f["t_target"] - PROBE_PERIOD_S, f["t_sent"]
    span = (t0[0], t1[-1]) if len(t0) else (0.0, 0.0)
    late = f["late"].astype(bool)
    in_stall = np.zeros(len(t0), dtype=bool)
    probes = {}
    for cpu, report in sorted(stalls.items()):
        realtime, events = report[0], report[1]
        counted = loop_cpus is None or cpu in loop_cpus
        events = events[(events[:, 0] >= span[0]) & (events[:, 0] <= span[1])]
        if counted:
            in_stall |= overlapping(t0, t1, events)
        lateness = events[:, 1]
        ran_on = getattr(report, "ran_on", None)
        probes[str(cpu)] = {"realtime": realtime, "counted": counted,
                            "max_ms": 1e3 * float(lateness.max()) if len(lateness) else 0.0,
                            "late_wakeups_at_least_ms": {f"{1e3 * e:g}": int((lateness >= e).sum())
                                                         for e in LATENESS_EDGES_S},
                            "ran_on": None if ran_on is None else {str(c): n for c, n in sorted(ran_on.items())},
                            "moved": getattr(report, "moved", None)}
    not_realtime = sorted(int(c) for c, p in probes.items() if not p["realtime"])
    known = not not_realtime
    return {"probes": probes, "loop_cpus": None if loop_cpus is None else sorted(loop_cpus),
            "probes_not_realtime": not_realtime,
            "late_frames_in_stalls": int((late & in_stall).sum()) if known else None,
            "late_frames_own": int((late & ~in_stall).sum()) if known else None,
            "frames_in_stalls": int(in_stall.sum())}


def run(args: argparse.Namespace) -> int:
    from antarium.config import load_config
    from antarium.renderers.gl import gl_renderer_string
    from antarium.renderers.gpu_path import default_path

    seconds = 30.0 if args.seconds is None and args.frames is None else args.seconds
    paths = getattr(args, "path", None) or [None]
    for path in paths:
        config = load_config(os.environ.get("ANTARIUM_RIG_CONFIG") or None)
        if path is not None:
            config.render.path = path
        gl = gl_renderer_string()
        chosen = config.render.path
        used = default_path(gl) if chosen == "auto" else chosen
        print(f"GL renderer: {gl}; per-LED path: {used}{' (auto)' if chosen == 'auto' else ''}")
        json_out = args.json_out
        if json_out and len(paths) > 1:  # one file per path: loop.json -> loop-gpu.json, loop-cpu.json
            root, ext = os.path.splitext(json_out)
            json_out = f"{root}-{path}{ext}"
        if _run_one(args, config, seconds, {"gl_renderer": gl, "path": used}, json_out):
            raise KeyboardInterrupt  # no further path, no further run of `bench monitor`
    return 0


def _run_one(args: argparse.Namespace, config: RigConfig, seconds: float | None, device: dict[str, str],
             json_out: str | None) -> bool:
    """One run of the loop on `config`: its report printed, and written to `json_out` when given. True when Ctrl-C
    ended it after frames had run: the report is then over those frames. Ctrl-C before any frame raises
    KeyboardInterrupt."""
    from antarium.bus import free_tcp_endpoint
    from antarium.server import Server
    from antarium.trial_log import read_table

    with tempfile.TemporaryDirectory(prefix="antarium-bench-loop-") as tmp:
        config.log.dir = tmp
        if config.bus.enabled and config.bus.listen == ["tcp/127.0.0.1:7447"]:
            config.bus.listen = [free_tcp_endpoint()]  # never collide with a running `antarium serve`
        server = Server(config, record="bench-loop", echo=lambda line: None)
        probes = _start_probes(config.loop.realtime_priority) if getattr(args, "machine_probe", False) \
            else None
        script = ScriptedCommands(server, config.render.scene,
                                  {kind: getattr(args, option, None) for kind, option in SCRIPTED.items()})
        length = " or ".join(t for t in (seconds and f"{seconds:g} s", args.frames and f"{args.frames} frames") if t)
        watch = ServerWatch(server, getattr(args, "on_frames_end", None),
                            lambda: progress("loop", f"frames running for {length}"
                                             + (", whichever ends first" if " or " in length else "")))
        clocks = GpuClocks().start() if device["path"] == "gpu" else None
        interrupted = False
        try:
            server.run(seconds=seconds, frames=args.frames)
        except KeyboardInterrupt:  # Ctrl-C: the server has closed its log; the frames run so far are reported
            interrupted = True
        finally:
            watch.join()
            stalls = probes.stop() if probes is not None else None
            script.stop()
            gpu_clocks = clocks.stop() if clocks is not None else None
        if interrupted and not server.trial_paths:
            raise KeyboardInterrupt  # before the recording began: nothing measured
        frames = read_table(server.trial_paths[0], "frames")
        if interrupted and len(frames["t_start"]) < 2:
            raise KeyboardInterrupt  # fewer than two frames: no figure
        result = summarise(frames, config.loop.rate_hz, stalls, server.final_stats, watch.loop_cpus)
        result["commands"] = script.summary(frames)
        result["device"] = {**device, "gpu_clocks": gpu_clocks}
        result["config"] = {"render": config.render.model_dump(), "loop_rate_hz": config.loop.rate_hz,
                            "keep_gpu_busy": config.loop.keep_gpu_busy,
                            "link": config.link.interface, "locomotion": config.locomotion.source}
        result["interrupted"] = interrupted
    if interrupted:
        print(f"loop bench INTERRUPTED (Ctrl-C): the figures below are over the {result['frames']} frames run before")
    _print(result)
    if json_out:
        write_json(json_out, "loop", result)
        print(f"  figures written to {json_out}")
    return interrupted


class ServerWatch:
    """A thread beside `server.run`: once the frames are about to run, which CPUs the frame loop has (`loop_cpus`:
    {its own CPU}, or None when it has none of its own, so that it may run on any); when they end (the server
    begins to stop), `on_frames_end()` if given (`bench monitor` ends the page's measuring there). Just before the
    frames, `on_frames_start()` if given."""

    def __init__(self, server, on_frames_end=None, on_frames_start=None) -> None:
        import threading

        self.server, self.on_frames_end, self.on_frames_start = server, on_frames_end, on_frames_start
        self.loop_cpus: set[int] | None = None
        self._thread = threading.Thread(target=self._run, name="bench-watch", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        server = self.server
        if server.wait_ready(None):
            isolation = server.placement._isolation  # set before the frames, None without a CPU of its own
            self.loop_cpus = None if isolation is None else {isolation.cpu}
            if self.on_frames_start is not None:
                self.on_frames_start()
        server._stopping.wait()
        if self.on_frames_end is not None:
            self.on_frames_end()

    def join(self) -> None:
        self.server._stopping.set()  # set already once the server has stopped (and should it not have started)
        self._thread.join(30.0)


#: after a scripted command's reply, its late frames are counted for this long (s)
AFTER_REPLY_S = 1.0


#: command the script sends -> the option (`args` attribute) giving the seconds between two of them
SCRIPTED = {"load_scene": "load_every", "set_pose": "displace_every", "scene_edit": "edit_every",
            "sky": "sky_every"}


class ScriptedCommands:
    """A thread sending commands to `server` on a schedule (`every`: command -> seconds between them; None:
    never), and recording (kind, sent, replied, error) for each on the server's clock."""

    def __init__(self, server, scene, every: dict[str, float | None]) -> None:
        import threading

        self.server, self.scene = server, scene
        self.every = {k: v for k, v in every.items() if v is not None}
        for kind, seconds in self.every.items():
            if not seconds > 0:
                raise ValueError(f"--{SCRIPTED[kind].replace('_', '-')} must be a positive number of seconds, "
                                 f"got {seconds:g}")
        self.records: list[tuple[str, float, float, str]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-script", daemon=True) if self.every else None
        if self._thread is not None:
            self._thread.start()

    def _params(self, kind: str, n: int) -> dict:
        if kind == "load_scene":
            return {"scene": self.scene}
        if kind == "set_pose":
            pose = self.server.loop.pose
            return {"x": pose.x + (0.5 if n % 2 == 0 else -0.5), "y": pose.y}
        if kind == "sky":
            sky = self.server.renderer.scene.sky
            azimuth = math.degrees(sky.sun_azimuth) if sky is not None else 0.0  # no sky: the server refuses it
            return {"sun_azimuth_deg": (azimuth + (60.0 if n % 2 == 0 else -60.0) + 180.0) % 360.0 - 180.0}
        scene = self.server.renderer.scene
        name = next(iter(scene.objects))
        x, y, z = (float(c) for c in scene.objects[name].position)
        return {"op": "move_object", "args": {"name": name, "position": [x + (0.2 if n % 2 == 0 else -0.2), y, z]}}

    def _run(self) -> None:
        if not self.server.wait_ready(None):
            return
        clock = self.server.clock
        t0 = clock.now()
        due = {kind: t0 + every for kind, every in self.every.items()}
        count = dict.fromkeys(self.every, 0)
        while not self._stop.is_set():
            kind = min(due, key=due.get)
            if self._stop.wait(max(0.0, due[kind] - clock.now())):
                return
            sent, error = clock.now(), ""
            try:
                self.server.command(kind, self._params(kind, count[kind]))
            except (ValueError, RuntimeError, OSError, StopIteration) as exc:
                error = str(exc) or type(exc).__name__
            self.records.append((kind, sent, clock.now(), error))
            count[kind] += 1
            due[kind] += self.every[kind]

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(10.0)

    def summary(self, frames: dict[str, np.ndarray]) -> dict[str, Any]:
        """Per kind: how many were sent, refused, their reply times, and the late frames (and those drawn in full: no
        far layer for them) around them."""
        out: dict[str, Any] = {}
        t, late = frames["t_start"], frames["late"].astype(bool)
        full = frames["full_render"].astype(bool)
        end = t[-1] if len(t) else -np.inf
        for kind in self.every:
            done = [r for r in self.records if r[0] == kind]
            rows = [r for r in done if not (r[3] and r[2] > end)]  # not those the run's end cut short
            replies = np.array([r[2] - r[1] for r in rows])
            around = np.zeros(len(t), dtype=bool)
            for _, sent, replied, _ in rows:
                around |= (t >= sent) & (t <= replied + AFTER_REPLY_S)
            out[kind] = {"sent": len(rows), "cut_by_the_end": len(done) - len(rows),
                         "errors": [r[3] for r in rows if r[3]][:3],
                         "reply": _pct(replies) if len(rows) else None,
                         "late_frames_around": int((late & around).sum()), "frames_around": int(around.sum()),
                         "full_frames_around": int((full & around).sum()),
                         "times_s": [[sent - t[0], replied - t[0]] for _, sent, replied, _ in rows] if len(t) else []}
        return out


def _start_probes(loop_priority: int):
    """A stall probe on every CPU this process may use, ten real-time priorities above the loop (ordinary when
    the loop is)."""
    from antarium.bench.jitter import StallProbes
    from antarium.core import realtime

    if not realtime.supported():
        raise SystemExit("antarium bench loop: --machine-probe needs Linux (CPU affinity and /proc)")
    return StallProbes(sorted(os.sched_getaffinity(0)), min(loop_priority + 10, 99) if loop_priority else 0)


def _fmt(p: dict | None) -> str:
    return "n/a" if p is None else f"p50 {p['p50_ms']:.2f}  p99 {p['p99_ms']:.2f}  max {p['max_ms']:.2f} ms"


def _print(r: dict[str, Any]) -> None:
    period_ms = 1e3 / r["target_rate_hz"]
    cut = f"first {r['warmup_s']:g} s excluded" if r["warmup_excluded"] else "no warm-up excluded: a run of 2 s or less"
    print(f"loop bench: {r['frames']} frames over {r['seconds']:.1f} s ({cut}), "
          f"scene {r['config']['render']['scene']!r}, face size {r['config']['render']['face_size_px'] or 'default'}")
    print(f"  frame rate      {r['achieved_rate_hz']:.1f} / {r['target_rate_hz']:.0f} Hz = {r['rate_ratio']:.3f} x "
          f"target")
    print(f"  late frames     {r['late_frames']} ({r['late_full_render']} of them drawn in full)   skipped slots "
          f"{r['skipped_slots']}   link outages {r['link_outages']}   rejected frames {r['rejected_frames']} "
          f"(whole run)")
    layer = r.get("far_layer")
    if layer and layer["mode"] != "off":
        error = f", ERROR {layer['error']}" if layer["error"] else ""
        counted = "" if layer.get("frames_counted") == "kept frames" else " (whole run)"
        print(f"  far layer       {layer['mode']}: {layer['layer_frames']} frames with it, "
              f"{layer['full_frames']} in full (start-up, edits, eye jumps){counted}, {layer['builds']} layers "
              f"built (whole run){error}")
    for line in describe_clocks(r["device"]["gpu_clocks"]):
        print(f"  {line}")
    busy = r["config"]["keep_gpu_busy"]
    if r["gpu_busy_passes"] or busy is True:
        print(f"  GPU kept busy   {r['gpu_busy_passes']} busy passes between frames, whole run ([loop] "
              f"keep_gpu_busy = {json.dumps(busy)})")
    ratio = r["latency_p99_over_period"]
    print(f"  latency         {_fmt(r['latency'])}"
          + ("" if ratio is None else f"   (p99 = {ratio:.2f} x the {period_ms:.2f} ms frame period)"))
    print(f"  frame work      {_fmt(r['frame_work'])}")
    for stage, p in r["stages"].items():
        print(f"    {stage:<12}  {_fmt(p)}")
    print(f"  pacing error    {_fmt(r['pacing_error'])}")
    for kind, c in (r.get("commands") or {}).items():
        errors = f"; ERRORS: {' | '.join(c['errors'])}" if c["errors"] else ""
        errors += f"; {c['cut_by_the_end']} more cut short by the run's end" if c["cut_by_the_end"] else ""
        print(f"  {kind:<14}  {c['sent']} sent, reply {_fmt(c['reply'])}; {c['late_frames_around']} late "
              f"({c['full_frames_around']} drawn in full) of the {c['frames_around']} frames from sending to "
              f"{AFTER_REPLY_S:g} s after the reply{errors}")
    listed = r.get("late_list", [])
    for row in listed[:LATE_PRINTED]:
        near = [f"{kind} sent {row['t_s'] - sent:.2f} s and replied {row['t_s'] - replied:.2f} s before"
                for kind, c in (r.get("commands") or {}).items() for sent, replied in c.get("times_s", [])
                if 0 <= row["t_s"] - sent <= replied - sent + AFTER_REPLY_S]
        stages = ", ".join(f"{k} {row[f'{k}_ms']:.2f}" for k in ("render", "sample", "convert", "encode", "send"))
        print(f"  late frame      at {row['t_s']:.3f} s: work {row['work_ms']:.2f} ms ({stages}), pacing error "
              f"{row['pacing_ms']:.2f} ms, {row['skipped']} slot(s) skipped after it"
              + (f"; {'; '.join(near)}" if near else ""))
    if r["late_frames"] > LATE_PRINTED:
        print(f"  late frame      {r['late_frames'] - LATE_PRINTED} more; the first {LATE_LISTED} in the JSON's "
              "late_list")
    m = r.get("machine")
    if m is not None:
        for cpu, p in m["probes"].items():
            counts = ", ".join(f">= {k} ms: {v}" for k, v in p["late_wakeups_at_least_ms"].items())
            kind = "" if p["realtime"] else " (probe not real-time: it measures our load too)"
            elsewhere = {c: n for c, n in (p.get("ran_on") or {}).items() if c != cpu}
            if elsewhere:
                where = ", ".join(f"{n} on {'another CPU' if c == '-1' else f'CPU {c}'}" for c, n in elsewhere.items())
                kind += (f"; moved off CPU {cpu} {p['moved']} times and pinned back: {where} "
                         f"of its {sum(p['ran_on'].values())} wake-ups, not counted")
            kind += "" if p["counted"] else "; not the loop's CPU, not counted below"
            print(f"  machine, CPU {cpu}  a probe woken late {counts}; max {p['max_ms']:.2f} ms{kind}")
        where = ("any CPU (the loop has none of its own)" if m["loop_cpus"] is None
                 else "the loop's CPU " + ", ".join(map(str, m["loop_cpus"])))
        if m["late_frames_in_stalls"] is None:
            print(f"  late frames     the machine's and the loop's own: unknown, the probe(s) on CPU "
                  f"{', '.join(map(str, m['probes_not_realtime']))} not real-time, their late wake-ups include our "
                  f"own load; {m['frames_in_stalls']} frames overlap a probe's late wake-up on {where}")
        else:
            print(f"  late frames     {m['late_frames_in_stalls']} overlap a machine stall on {where} (the "
                  f"machine's), {m['late_frames_own']} do not (the loop's own); {m['frames_in_stalls']} frames "
                  f"overlap one in all")
