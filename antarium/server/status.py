"""What a rig reports: its state (the reply to every command that changes it) and its status (once a second on the
bus and on `status`): frame statistics, telemetry, the locomotion source, the trial log and the alarms an operator
must see."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

#: a renderer that failed within this many seconds (loop clock) is an alarm: the dome keeps its last frame
RENDER_ALARM_S = 2.0
#: rows handed to the trial-log writer and not confirmed written for longer than this are an alarm (s, wall clock;
#: a batch takes milliseconds: this is a writer that stopped answering, a hung disk)
LOG_STALL_ALARM_S = 2.0

if TYPE_CHECKING:
    from antarium.server.frame_loop import FrameLoop
    from antarium.server.server import Server


def loop_state(loop: FrameLoop) -> dict[str, Any]:
    """Pose (heading in degrees), scene rotation, loop mode, tether and gains of the frame loop now."""
    p = loop.pose
    return {"pose": {"x": p.x, "y": p.y, "z": p.z, "heading_deg": math.degrees(p.heading)},
            "scene_rotation_deg": math.degrees(loop.scene_rotation), "closed_loop": loop.closed_loop,
            "tether": loop.tether, "gains": {"translation": loop.gain_translation, "rotation": loop.gain_rotation}}


def rig_status(server: Server) -> dict[str, Any]:
    """Frame rate, late frames, latency percentiles, distributor telemetry, trial and log state, and "alarms": one
    line for each thing an operator must act on."""
    loop = server.loop
    out: dict[str, Any] = {"rig": server.rig_name, "t": server.clock.now(), "trial": server.trial_name,
                           "trial_started": server.trial_started, "scene": server.scene_name,
                           "led_stream_every_frames": server.config.monitor.leds_every_frames, "alarms": []}
    alarms = out["alarms"]
    if server.loop_error is not None:
        alarms.append(f"frame loop stopped: {_describe(server.loop_error)}")
    if loop is not None:
        out.update(loop.stats())
        out.update(loop_state(loop))
        if not loop.link_ok:
            alarms.append("dome link down: " + (loop.last_link_error or "no telemetry"))
        if not loop.locomotion_connected:
            alarms.append("locomotion source disconnected: pose held")
        if "render" in loop.last_fault and out["t"] - loop.last_fault["render"][0] <= RENDER_ALARM_S:
            alarms.append(f"renderer failing, the dome keeps its last frame: {loop.faults['render']} render errors, "
                          f"the last: {loop.last_fault['render'][1]}")
    renderer = server.renderer
    if renderer is not None and hasattr(renderer, "far_layer_status"):
        out["far_layer"] = renderer.far_layer_status()
        if out["far_layer"]["error"]:
            alarms.append("far layer stopped, every frame drawn in full: " + out["far_layer"]["error"])
    if server.source is not None:
        try:
            out["locomotion"] = server.source.status()
        except Exception as exc:  # noqa: BLE001 - the frame loop counts it as a locomotion fault
            out["locomotion"] = {"connected": False, "error": _describe(exc)}
    if loop is not None and server.link is not None:
        out["telemetry"] = loop.telemetry  # polled by the loop's thread (the link is not shared)
        if out["telemetry"].get("mismatch"):  # panels missing, wrong panel firmware, a capability lacking
            alarms.append(out["telemetry"]["mismatch"])
    if server.emulator is not None:
        out["emulator_running"] = server.emulator.running
        if not out["emulator_running"]:
            alarms.append(f"the dome emulator process is not running ({_exit_status(server.emulator.exitcode)})")
    log = server.trial_log  # read once: trial_stop may end the trial in another thread
    if log is not None:
        from antarium.trial_log import CLOSE_TIMEOUT_S, MAX_WRITER_RESTARTS

        out["log"] = log.status()
        if out["log"]["error"]:
            alarms.append("TRIAL LOG NOT WRITTEN: " + out["log"]["error"])
        if out["log"]["restarts"]:  # for the rest of the trial; each restart is echoed (its count is in the key)
            alarms.append(f"TRIAL LOG WRITER RESTARTED, {len(out['log']['restarts'])} OF {MAX_WRITER_RESTARTS}: "
                          f"{out['log']['restarts'][-1]}")
        if out["log"]["unconfirmed_s"] > LOG_STALL_ALARM_S:
            alarms.append(f"TRIAL LOG WRITER NOT ANSWERING: rows handed over {out['log']['unconfirmed_s']:.1f} s ago "
                          f"are not confirmed written (a hung disk?); ending the trial waits for it at most "
                          f"{CLOSE_TIMEOUT_S:g} s, then kills it and counts them lost")
    return out


def _describe(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def _exit_status(code: int | None) -> str:
    """How a child process ended, from its exit code (-N: killed by signal N; None: stopped, released)."""
    if code is None:  # stopped by the server
        return "stopped"
    if code < 0:
        import signal

        try:
            name = f" ({signal.Signals(-code).name})"
        except ValueError:
            name = ""
        return f"exit status {code}: killed by signal {-code}{name}"
    return f"exit status {code}"
