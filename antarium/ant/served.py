"""The virtual ant on a served rig: `antarium serve` runs the rig in real time exactly as for a real ant, and the
ant's process stands in for the dome and the insect.

    antarium serve --config ant_rig.toml                                  # renders, sends frames over UDP
    antarium ant serve ant.npz --config ant_rig.toml --out run/   # the ant (model from `antarium ant learn`)

The ant's process hosts the dome: the distributor and its 55 panels (the `antarium.firmware_proto` emulator) listen
on `[link] host:port`, where the server sends its LED frames (`spawn_emulator = false`), and the ant's eye reads
what those panels show. Its legs turn the ball of an emulated USB trackball read by the real driver
(`TrackballLegs`), which publishes every sample on the rig's bus as a trackball on another computer does; the
server reads them with its "bus" locomotion source. Pose, displacements and trials go through the experiment-script
API (`antarium.Rig`), so the server logs the trial as a real one.

`served_ant(model, config)` yields a `VirtualAnt` whose loop is the served rig's (`ServedLoop`): `learning_walk`
and `follow_route` run on it unchanged, in real time (`MonotonicClock`).
"""

from __future__ import annotations

import contextlib
import json
import math
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from antarium.ant.agent import VirtualAnt
from antarium.ant.eye import Eye, EyeParams
from antarium.ant.locomotion import TrackballLegs
from antarium.ant.metrics import json_text
from antarium.core.clock import Clock, MonotonicClock
from antarium.core.pose import Pose

if TYPE_CHECKING:
    from antarium.config import RigConfig


def served_config(config: str | Path | dict[str, Any] | RigConfig) -> RigConfig:
    """The resolved rig config (TOML path or parsed table), checked for a served virtual ant: the server sends its
    frames to the ant's dome and reads the ant's ball from the bus."""
    from antarium.config import RigConfig, load_config, resolve

    cfg = config if isinstance(config, RigConfig) else resolve(config) if isinstance(config, dict) \
        else load_config(config)
    link = cfg.link
    problems = []
    if link.interface != "udp" or link.spawn_emulator:  # (a udp port 0 needs the emulator: config.LinkSection)
        problems.append('[link] must be interface = "udp", spawn_emulator = false and a port (the ant\'s dome '
                        f'listens there), got {link.model_dump()}')
    if cfg.locomotion.source != "bus":
        problems.append(f'[locomotion] source must be "bus" (the ant\'s trackball publishes there), got '
                        f'{cfg.locomotion.source!r}')
    if not cfg.bus.enabled:
        problems.append("[bus] enabled must be true")
    if problems:
        raise ValueError("rig config not fit for a served virtual ant: " + "; ".join(problems))
    return cfg


#: how often `DomeHost.settle` sends its HELLO again while no answer came (s)
SETTLE_RESEND_S = 0.25


class DomeHost:
    """The dome the server drives, in this process: the emulated distributor and panels answering datagrams on UDP
    `host:port` in a thread (`antarium.firmware_proto.server.serve`); `led_values()` is what its panels show."""

    def __init__(self, host: str, port: int) -> None:
        from antarium.firmware_proto.emulator import Emulator

        self.emulator = Emulator()
        self.counters = self.emulator.counters
        self.host, self.port = host, port
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._probe: socket.socket | None = None
        self._tag = 0

    def handle_datagram(self, payload) -> list[bytes]:
        with self._lock:
            return self.emulator.handle_datagram(payload)

    def stats(self) -> dict:
        with self._lock:
            return self.emulator.stats()

    def led_values(self):
        """(20350, 2) uint16: the LEDs the dome shows now (a whole latched frame, never a half-received one)."""
        with self._lock:
            return self.emulator.led_values()

    def _serve(self) -> None:
        from antarium.firmware_proto.server import serve

        try:
            serve(self, self.host, self.port, stop=self._stop, ready=lambda address: self._ready.set())
        except BaseException as exc:  # reported by start  # noqa: BLE001
            self._error = exc
            self._ready.set()

    def start(self, timeout_s: float = 5.0) -> None:
        self._thread = threading.Thread(target=self._serve, name="ant-dome", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s) or self._error is not None:
            self.stop()
            raise RuntimeError(f"the virtual ant's dome cannot listen on udp://{self.host}:{self.port}: "
                               f"{self._error or 'timed out'}")
        self._probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._probe.connect((self.host, self.port))

    def settle(self, timeout_s: float) -> None:
        """Wait until the dome has handled every datagram that reached it before this call: it answers the HELLO
        sent here only after them (one socket, read in order). The HELLO goes again every `SETTLE_RESEND_S` until
        answered: on a loaded machine the dome's socket overflows with the server's frames and drops it (a reply to
        any of them says the same). Raises RuntimeError after `timeout_s`."""
        from antarium.firmware_proto.control import encode_hello
        from antarium.firmware_proto.errors import ProtocolError
        from antarium.firmware_proto.replies import decode_reply
        from antarium.firmware_proto.udp import MAX_DATAGRAM

        self._tag = (self._tag + 1) % 256
        hello = encode_hello(self._tag)
        deadline = time.monotonic() + timeout_s
        resend = 0.0
        while (now := time.monotonic()) < deadline:
            if now >= resend:
                self._probe.send(hello)
                resend = now + SETTLE_RESEND_S
            self._probe.settimeout(max(1e-3, min(deadline, resend) - now))
            try:
                reply = decode_reply(self._probe.recv(MAX_DATAGRAM))
            except (TimeoutError, ProtocolError):
                continue
            if reply.tag == self._tag:
                return
        raise RuntimeError(f"the virtual ant's dome on udp://{self.host}:{self.port} did not answer in {timeout_s} s")

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        if self._probe is not None:
            self._probe.close()


class ServedLoop:
    """The served rig's frame loop as the virtual ant sees it (the interface `VirtualAnt` uses of a `FrameLoop`).

    `step()` waits for the next frame slot on `clock`, lets the ant's trackball driver read (and publish) every
    report due, then waits (bounded, `timeout_s`) for the pose of a frame the server began after that and, with
    `settle` (`DomeHost.settle`), until the ant's dome shows that frame;
    `set_pose` is the rig's `set_pose` command; `event` keeps the ant's events (`events`), each with where the ant
    was (`x`, `y` m, `heading` rad: world, as `VirtualAnt` says) and the server's frame of that pose (`frame`, the
    trial log's frame number), and hands them to `on_event`.
    """

    def __init__(self, rig, legs: TrackballLegs, clock: Clock, rate_hz: float, tether: str, pose_every: int = 1,
                 timeout_s: float = 10.0, on_event: Callable[[float, str, dict], None] | None = None,
                 settle: Callable[[float], None] | None = None) -> None:
        self.rig, self.legs, self.clock = rig, legs, clock
        self.settle = settle
        self.source = legs.source
        self.tether = tether
        self.period = 1.0 / rate_hz
        self.pose_every = int(pose_every)
        self.timeout_s = float(timeout_s)
        self.on_event = on_event
        self.renderer = None  # the server renders
        self.frame = 0
        self.pose_frame = -1  # the server's frame number of `pose` (-1: not from the stream)
        self.events: list[dict[str, Any]] = []
        self._next_t: float | None = None
        rig.tether(tether)
        rig.closed_loop(True)
        self.pose = rig.pose(self.timeout_s)

    def step(self) -> None:
        now = self.clock.now()
        self._next_t = now if self._next_t is None else max(self._next_t + self.period, now)
        self.clock.sleep_until(self._next_t)
        self.source.read()  # every report due has been read and published; the server integrates the samples
        self.pose = self._next_pose()
        if self.settle is not None:  # the server sent that frame before its pose: the dome shows it once settled
            self.settle(self.timeout_s)
        self.frame += 1

    def _next_pose(self) -> Pose:
        """The pose of a frame the server began after now: two stream updates later."""
        first = self.rig.latest()
        need = (first.frame if first is not None else -1) + 2 * self.pose_every
        deadline = time.monotonic() + self.timeout_s
        while True:
            latest = self.rig.latest()
            if latest is None:  # none yet, or the server went away: `pose` raises RigError at once in that case
                self.rig.pose(max(0.0, deadline - time.monotonic()))
            elif latest.frame >= need:
                self.pose_frame = latest.frame
                return latest.pose
            if time.monotonic() > deadline:
                raise RuntimeError(f"the served rig {self.rig.name!r} sent no new pose for {self.timeout_s} s; "
                                   "is `antarium serve` still running?")
            time.sleep(0.0005)

    def set_pose(self, pose: Pose) -> None:
        self.rig.set_pose(pose.x, pose.y, math.degrees(pose.heading), pose.z)
        self.pose, self.pose_frame = pose, -1

    def event(self, kind: str, **data: Any) -> None:
        t = self.clock.now()
        heading = math.remainder(self.pose.heading + self.legs.yaw, math.tau)
        data = {"x": self.pose.x, "y": self.pose.y, "heading": heading, "frame": self.pose_frame, **data}
        self.events.append({"t": t, "kind": kind, **data})
        if self.on_event is not None:
            self.on_event(t, kind, data)


@contextlib.contextmanager
def served_ant(model, config: str | Path | dict[str, Any], eye_params: EyeParams | None = None,
               frames_per_decision: int = 1, timeout_s: float = 30.0) -> Iterator[VirtualAnt]:
    """A `VirtualAnt` with `model` on the rig that `antarium serve --config <config>` serves (see the module
    docstring; `served_config` says what the config needs). Waits up to `timeout_s` for the server."""
    from antarium import bus
    from antarium.client import Rig
    from antarium.geometry import load_dome
    from antarium.locomotion import wire
    from antarium.locomotion.trackball.config import TrackballConfig

    cfg = served_config(config)
    eye = Eye.from_dome(load_dome(), eye_params)
    if eye.params.n_pn != model.n_pn:
        raise ValueError(f"the model expects {model.n_pn} PNs but the eye gives {eye.params.n_pn}")
    name, loop_cfg = cfg.rig.name, cfg.loop
    clock = MonotonicClock()
    with contextlib.ExitStack() as stack:
        dome = DomeHost(cfg.link.host, cfg.link.port)
        dome.start()
        stack.callback(dome.stop)
        session = stack.enter_context(bus.open_session(cfg.bus, role="client"))
        rig = stack.enter_context(Rig(name, config=cfg, session=session, timeout_s=timeout_s))
        _wait_for_link(rig, timeout_s)
        publisher = bus.locomotion_publisher(session, name)
        stack.callback(publisher.undeclare)
        events = bus.events_key(name)
        trackball = cfg.section("trackball") or TrackballConfig(ball_radius=loop_cfg.ball_radius_m, sample_rate_hz=950)
        legs = TrackballLegs(loop_cfg.tether, trackball=trackball, clock=clock, step_s=1.0 / loop_cfg.rate_hz,
                             on_sample=lambda s: publisher.put(wire.encode(s)),
                             on_event=lambda e: session.put(events, json.dumps(e)))
        legs.start()
        stack.callback(legs.stop)

        def publish(t: float, kind: str, data: dict) -> None:
            session.put(events, json.dumps({"t": t, "kind": kind, "data": data}, default=float))

        loop = ServedLoop(rig, legs, clock, loop_cfg.rate_hz, loop_cfg.tether, loop_cfg.pose_every_frames,
                          timeout_s, on_event=publish, settle=dome.settle)
        yield VirtualAnt(eye, model, loop, legs, dome.led_values, frames_per_decision)


def _wait_for_link(rig, timeout_s: float) -> None:
    """Wait until the server's loop has heard the ant's dome answer (its status says the link is up), so that the
    ant walks, and its trials are logged, only while the server knows its frames arrive."""
    from antarium.client import RigError

    deadline = time.monotonic() + timeout_s
    while not (status := rig.status()).get("link_ok"):
        if time.monotonic() >= deadline:
            alarms = "; ".join(status.get("alarms", [])) or "no alarm"
            raise RigError(f"the server of rig {rig.name!r} has not heard the ant's dome in {timeout_s:g} s ({alarms})")
        time.sleep(0.02)


def run_served(model_file: str | Path, config: str | Path | dict[str, Any], out: str | Path,
               start_offset: tuple[float, float] = (0.0, 0.0), max_decisions: int | None = None,
               trial: str = "virtual_ant", echo: Callable[[str], None] = print,
               timeout_s: float = 30.0) -> dict[str, Any]:
    """Release the ant of `model_file` (written by `antarium ant learn`) at the start of its route on the served rig
    and let it follow the route in real time, inside a trial that the server logs. Writes `<out>/served.json`
    (summary, the ant's decisions with its pose and the server's frame number) and `<out>/served_paths.png`; returns
    the summary. A run stopped early (Ctrl-C, the server gone) still writes `served.json`: the decisions so far and,
    under `summary`, why it stopped (`stopped`) and the trial log (`trial_log`, None if it had not started).
    `out` is made once the server has answered (within `timeout_s`, s): a rig that never answers leaves nothing."""
    from dataclasses import asdict

    from antarium.ant.agent import follow_route
    from antarium.ant.routes import Route
    from antarium.ant.storage import load_route_model
    from antarium.plots.ant import plot_paths, scene_top_view
    from antarium.renderers import build_scene

    model, eye_params, stored = load_route_model(model_file)
    if stored is None:
        raise ValueError(f"{model_file}: the model file holds no route to follow")
    route = Route(stored)
    cfg = served_config(config)
    out = Path(out)
    step = getattr(model.params, "step", None) or model.params.k_v  # metres per decision at most
    limit = max_decisions or int(math.ceil(3.0 * route.length / step)) + 10
    with served_ant(model, cfg, eye_params, timeout_s=timeout_s) as ant:
        out.mkdir(parents=True, exist_ok=True)
        log = None
        try:
            with ant.loop.rig.trial(trial, model=model.kind, route=route.points.tolist()) as log:
                t0 = time.monotonic()
                result = follow_route(ant, route, limit, 0.1, start_offset=start_offset)
                seconds = time.monotonic() - t0
        except BaseException as exc:  # Ctrl-C, the server gone: the ant's decisions so far are kept, then re-raised
            stopped = "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else str(exc) or type(exc).__name__
            (out / "served.json").write_text(json_text({"summary": {"stopped": stopped, "trial_log": log},
                                                        "events": ant.loop.events}))
            raise
        events = ant.loop.events
    summary = {**asdict(result.summary), "trial_log": log, "seconds": seconds,
               "decisions_per_s": result.summary.decisions / seconds}
    (out / "served.json").write_text(json_text({"summary": summary, "events": events}))
    picture = plot_paths(out / "served_paths.png", route, {f"{model.kind} (served rig)": result.track},
                         title="virtual ant on the served rig", top=scene_top_view(build_scene(cfg.render.scene)))
    echo(f"virtual ant on rig {cfg.rig.name!r}: {'arrived' if summary['arrived'] else 'did not arrive'} after "
         f"{summary['decisions']} decisions in {seconds:.1f} s ({summary['decisions_per_s']:.1f} decisions/s); "
         f"lateral error median {100 * summary['lateral_median']:.1f} cm\n  trial log (server): {log}\n"
         f"  summary: {out / 'served.json'}\n  picture: {picture}")
    return summary
