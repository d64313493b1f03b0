"""The stimulus server: one rig = frame loop + locomotion source + renderer + dome link + bus + trial logs.

`Server(config).run()` runs the frame loop in the calling thread (the renderer's GL context lives in the
thread that renders) until `stop()` (a signal handler, a bus command from another thread, or `until`).
Commands arrive on zenoh threads as queries, are validated (`antarium.server.commands`), and are executed in the
loop's thread between frames; the reply carries the result or the error. See `docs/bus.md`.

Everything the server drives can be injected (clock, source, renderer factory, link), so tests and the
virtual ant run it without hardware; by default it is built from the rig config (`antarium.config`).
"""

from __future__ import annotations

import datetime as _dt
import gc
import json
import math
import queue
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from antarium import bus
from antarium.core.clock import Clock, MonotonicClock
from antarium.server.commands import COMMANDS, CommandError, _brief, _shown, parse_command, slow_command
from antarium.server.emulator_process import EmulatorProcess
from antarium.server.frame_loop import FrameLoop, FrameRecord, LoopClosed
from antarium.server.placement import LoopPlacement
from antarium.server.status import loop_state, rig_status

if TYPE_CHECKING:
    from antarium.config import RenderSection, RigConfig

#: events that are also printed on stderr: an operator must notice them
ALARM_EVENTS = ("link_outage", "locomotion_lost", "log_error", "frame_rejected", "render_error", "server_failed")
#: printed on stderr too: the end of an alarm event's trouble (stderr's last word is not the outage)
RECOVERY_EVENTS = ("link_back", "locomotion_back")
COMMAND_TIMEOUT_S = 60.0
#: how long a starting server asks the bus whether another server serves its rig name (s; answered at once on
#: loopback, measured)
TWIN_CHECK_S = 0.5
#: how long a scene load waits for the loop to run one slice of its meshes' upload before leaving the rest to
#: the swap itself (s)
UPLOAD_STEP_WAIT_S = 1.0


class ServerError(RuntimeError):
    """The server cannot start as configured (the message says what to change), or its frame loop stopped on an
    error (`stop()` of a server run by `start_thread`)."""


#: servers running with the garbage collector's objects frozen (`Server.run`); the last one to stop unfreezes
_frozen = 0
_frozen_lock = threading.Lock()


def _freeze_gc() -> None:
    """Move every object there is now out of the cyclic garbage collector's way (`gc.freeze`)."""
    global _frozen
    with _frozen_lock:
        gc.collect()
        gc.freeze()
        _frozen += 1


def _unfreeze_gc() -> None:
    """Undo `_freeze_gc` once no server runs any more: a stopped server's objects can then be collected."""
    global _frozen
    with _frozen_lock:
        _frozen -= 1
        if _frozen == 0:
            gc.unfreeze()


def default_renderer_factory(render_cfg: RenderSection, clock: Clock | None = None):
    """The renderer from `[render]` (built in the thread that will render; the scene is loaded after)."""
    from antarium.geometry import load_dome
    from antarium.renderers import Renderer

    return Renderer(load_dome(), face_size=render_cfg.face_size_px or None, clock=clock,
                    far_layer=render_cfg.far_layer, near_radius=render_cfg.near_radius_m,
                    far_layer_error_deg=render_cfg.far_layer_error_deg,
                    path=None if render_cfg.path == "auto" else render_cfg.path)


class Server:
    """config: a resolved rig config (`antarium.config.load_config`). Injectable: clock, source,
    renderer_factory (called in the loop's thread; None for a pose-only rig), link (None: from `[link]`, which
    also sets the panels' brightness and dot correction; a link given here is the caller's to configure; False:
    no dome), session (an open zenoh session; None: from `[bus]` if enabled); record: a trial name
    to record from the first frame (also `[log] record = true`)."""

    def __init__(self, config: RigConfig, *, clock: Clock | None = None, source=None,
                 renderer_factory: Callable | None | bool = True, link=None, session=None,
                 record: str | None = None, echo: Callable[[str], None] | None = None) -> None:
        from antarium.trial_log import check_log_dir, prepare_writer

        self.config = config
        self.rig_name = bus.check_rig_name(config.rig.name)
        self.clock = clock or MonotonicClock()
        self.echo = echo or (lambda line: print(line, file=sys.stderr, flush=True))
        self.log_dir = check_log_dir(config.log.dir)
        prepare_writer()  # the first trial then starts at once
        self._renderer_factory = default_renderer_factory if renderer_factory is True else renderer_factory
        self.source = source if source is not None else self._open_source()
        self.emulator: EmulatorProcess | None = None
        self._link_arg = link
        self.link = None
        self.session = session
        self._own_session = session is None
        self.renderer = None
        self.loop: FrameLoop | None = None
        self.trial_log = None
        self.trial_name: str | None = None
        #: the running trial's start ("t": s on the loop's clock, its trial_started event's `monotonic`) and
        #: "metadata", in the status for clients that subscribed after it started (the monitor); None without one
        self.trial_started: dict[str, Any] | None = None
        #: the scene edits and sky changes made since the scene was loaded ({"command", "request"}, in order)
        self._scene_edits: list[dict[str, Any]] = []
        self.scene_name: str | None = None
        self._scene_digest = ""
        self.record = record
        self.trial_paths: list[Path] = []
        self.final_stats: dict[str, Any] = {}
        self.placement = LoopPlacement(config.loop, self.echo)
        self.final_frame = None  # the last LED frame sent, kept after the loop stopped
        self._entities: list = []
        self._pose_pub = self._stats_pub = None
        self._leds_pub = self.monitor = None  # antarium.monitor: LED stream publisher, monitor process
        self._ready = threading.Event()
        self._stopping = threading.Event()
        #: held while the start-up turns into running (`_ready`), is cancelled, or the shutdown begins (re-entrant: a
        #: signal handler may run `cancel_start` in the thread that holds it)
        self._start_lock = threading.RLock()
        self._shut_down = False  # `_shutdown` has begun: it runs once
        self._command_log_lock = threading.Lock()  # orders the commands table's rows by their time
        self._in_flight = 0  # bus queries being answered (zenoh's threads): the shutdown waits for them
        self._in_flight_done = threading.Condition()
        self._slow_queries: queue.SimpleQueue = queue.SimpleQueue()  # for `_answer_slow_queries` (None: end)
        self._slow_worker: threading.Thread | None = None
        self._queries_ended = False  # `_await_queries` ran: no worker starts any more
        self._thread: threading.Thread | None = None
        self._status_thread: threading.Thread | None = None
        self._start_error: BaseException | None = None
        self.loop_error: BaseException | None = None  # what ended the frame loop (None: it ended as asked)
        self._loop_error_raised = False
        self._gc_frozen = False
        self._alarms_echoed: set[str] = set()
        self._last_log_error: str | None = None
        self._trial_lock = threading.Lock()
        self._loop_thread: threading.Thread | None = None

    # -- building --------------------------------------------------------------------------------------
    def _open_source(self):
        from antarium.locomotion import open_source
        from antarium.server.config_check import source_options

        name = self.config.locomotion.source
        try:
            return open_source(name, **source_options(self.config, clock=self.clock))
        except TypeError as exc:
            raise ServerError(f"[locomotion] options do not fit source {name!r}: {exc}") from None

    def _open_link(self):
        if self._link_arg is False:
            return None
        if self._link_arg is not None:
            return self._link_arg
        from antarium.firmware_proto.link import open_link

        cfg = self.config.link
        if cfg.interface == "virtual":
            return open_link("virtual", clock=self.clock)
        host, port = cfg.host, cfg.port
        if cfg.spawn_emulator:
            # real-time as hardware would answer, but below the frame loop and its helper: never holds them off
            priority = self.config.loop.realtime_priority
            self.emulator = EmulatorProcess(host, port, realtime_priority=max(1, priority - 2) if priority else 0)
            self.emulator.start()
            port = self.emulator.port
        return open_link("udp", host=host, port=port)  # a port, 1..65535, without an emulator: config.LinkSection

    def _open_bus(self) -> None:
        if self.session is None:
            if not self.config.bus.enabled:
                return
            self.session = bus.open_session(self.config.bus, role="server")
            if self.config.bus.access_control:
                for line in bus.acl_missing_interfaces(self.config.bus.access_control):
                    self.echo(f"antarium serve: {line}")
        s = self.session
        self._refuse_a_twin(s)
        self._pose_pub = s.declare_publisher(bus.pose_key(self.rig_name), express=True)
        self._stats_pub = s.declare_publisher(bus.stats_key(self.rig_name), express=True)
        self._entities += [self._pose_pub, self._stats_pub,
                           s.declare_queryable(bus.rig_key(self.rig_name, "cmd", "*"), self._on_query),
                           s.liveliness().declare_token(bus.alive_key(self.rig_name))]
        from antarium.monitor.process import open_led_stream, start_monitor

        self._leds_pub = open_led_stream(s, self.rig_name, self.config, report=self.echo)
        self.monitor = start_monitor(self.config)
        if self.monitor is not None:  # its address once it listens, or why it stopped (a port in use)
            self.monitor.report(self.echo)

    def _refuse_a_twin(self, session) -> None:
        """ServerError when another server already serves this rig name on the bus (its liveliness token answers):
        both would run every command and interleave their poses on one stream, and a client could not tell."""
        others = [reply for reply in session.liveliness().get(bus.alive_key(self.rig_name), timeout=TWIN_CHECK_S)
                  if reply.ok is not None]
        if others:
            raise ServerError(f"another antarium server already serves rig {self.rig_name!r} on this bus "
                              f"([bus] listen {self.config.bus.listen}, connect {self.config.bus.connect}): stop "
                              "it, or give this rig another [rig] name")

    # -- bus traffic -----------------------------------------------------------------------------------
    def _on_query(self, query) -> None:
        """A command query (zenoh thread): JSON in, JSON reply or an error reply naming what was wrong. Counted in
        flight until it is answered, so that the shutdown does not end (and the interpreter exit) under it.

        zenoh runs a queryable's callbacks one after another: a command that takes long (`slow_command`: a scene
        load, an edit, the sky; seconds) is handed to one worker thread that answers such commands in the order
        they came, so that every other client's command (status, pose, trials) is answered meanwhile."""
        with self._in_flight_done:
            self._in_flight += 1
        if slow_command(str(query.key_expr).rsplit("/", 1)[-1]):
            with self._in_flight_done:  # (the condition's lock also guards the worker's start and its end)
                handed = not self._queries_ended  # one zenoh hands over after the shutdown is answered here
                if handed:
                    if self._slow_worker is None:
                        self._slow_worker = threading.Thread(target=self._answer_slow_queries,
                                                             name="slow-commands", daemon=True)
                        self._slow_worker.start()
                    self._slow_queries.put(query)
            if handed:
                return
        try:
            self._answer(query)
        finally:
            self._query_answered()

    def _answer_slow_queries(self) -> None:
        """The slow commands' worker: answers each query it is handed, then drops it (its final reply goes then),
        until it is handed None (the shutdown, once no query is in flight)."""
        while (query := self._slow_queries.get()) is not None:
            try:
                with query:
                    self._answer(query)
            except Exception as exc:  # noqa: BLE001 - a bus error (a reply to a client gone) ends no other command
                self.echo(f"antarium serve: answering a command failed on the bus: {exc}")
            finally:
                self._query_answered()

    def _query_answered(self) -> None:
        with self._in_flight_done:
            self._in_flight -= 1
            self._in_flight_done.notify_all()

    def _await_queries(self) -> None:
        """Wait (at most COMMAND_TIMEOUT_S) until no bus query is being answered; RuntimeError naming how many are
        still running after that. Called once the queryable is undeclared: no new query comes."""
        with self._in_flight_done:
            self._queries_ended = True
            if self._slow_worker is not None:  # it ends once the queries handed to it are answered
                self._slow_queries.put(None)
                self._slow_worker = None
            if not self._in_flight_done.wait_for(lambda: self._in_flight == 0, COMMAND_TIMEOUT_S):
                raise RuntimeError(f"{self._in_flight} bus command(s) still running after {COMMAND_TIMEOUT_S:g} s")

    def _answer(self, query) -> None:
        name = str(query.key_expr).rsplit("/", 1)[-1]
        raw = query.payload.to_bytes() if query.payload is not None else b""
        try:
            params = json.loads(raw) if raw.strip() else {}
        except (ValueError, RecursionError) as exc:  # (UnicodeDecodeError is a ValueError)
            why = ("nested too deeply" if isinstance(exc, RecursionError) else str(exc)
                   if isinstance(exc, json.JSONDecodeError | UnicodeDecodeError) else "a number too long to read")
            message = f"{name}: the payload must be a JSON object of parameters; it is not JSON ({why})"
            text = raw.decode(errors="replace")
            self._log_command(name, {"payload": text if len(text) <= 200 else text[:200] + "..."},
                              {"error": message}, False)
            query.reply_err(json.dumps({"error": message}))
            return
        try:
            result = self.command(name, params)
        except (CommandError, ValueError, RuntimeError, OSError) as exc:
            query.reply_err(json.dumps({"error": str(exc)}))
            return
        except Exception as exc:  # any refusal is an error reply (RigError), never a timeout  # noqa: BLE001
            query.reply_err(json.dumps({"error": f"{name}: {type(exc).__name__}: {exc}"}))
            return
        query.reply(query.key_expr, json.dumps({"ok": True, "result": result}, default=_json_default))

    def _publish_event(self, t: float, kind: str, data: dict) -> None:
        if kind in ("locomotion_lost", "locomotion_back"):
            self.echo(f"antarium serve: {kind}: {self._locomotion_line(kind, data)}")
        elif kind in ALARM_EVENTS or kind in RECOVERY_EVENTS:
            self.echo(f"antarium serve: {kind}: {json.dumps(data, default=_json_default)}")
        if self.session is not None:
            try:
                self.session.put(bus.events_key(self.rig_name),
                                 json.dumps({"t": t, "kind": kind, "data": data}, default=_json_default))
            except Exception as exc:  # zenoh errors must never stop the frame loop  # noqa: BLE001
                self.echo(f"antarium serve: publishing event {kind} failed: {exc}")

    def _locomotion_line(self, kind: str, data: dict) -> str:
        """A locomotion_lost / locomotion_back event for the operator: the source, where it reads from, its error and
        what to check (the source's `lost_hint`); the event itself, with the source's whole status, is on the bus."""
        status = data.get("status") or {}
        where = status.get("device") or status.get("address") or status.get("path")
        where = " ".join(str(part) for part in where) if isinstance(where, list) else where
        name = f"{status.get('source') or self.config.locomotion.source}" + (f" {where}" if where else "")
        losses = f"losses so far: {data.get('losses')}"
        if kind == "locomotion_back":
            return f"{name} delivers again ({losses})"
        error = status.get("last_error") or status.get("error")
        hint = getattr(self.source, "lost_hint", str)()  # a source not built on LocomotionSource has none
        return (f"{name} delivers nothing{f' ({error})' if error else ''}; the pose is held ({losses})"
                + (f"; {hint}" if hint else ""))

    def _on_frame(self, rec: FrameRecord) -> None:
        loop_cfg = self.config.loop
        try:
            if self._pose_pub is not None and rec.frame % loop_cfg.pose_every_frames == 0:
                self._pose_pub.put(bus.encode_pose(rec.frame, rec.t_start, rec.pose, rec.scene_rotation,
                                                   rec.closed_loop, rec.fixed_tether))
            if self._stats_pub is not None and rec.frame % loop_cfg.stats_every_frames == 0:
                self._stats_pub.put(bus.encode_stats(rec.frame, self.loop.late_frames, rec.t_start, rec.latency,
                                                     _stages(rec.render, rec.sample, rec.convert),
                                                     rec.sample, rec.encode, rec.send, rec.pacing_error))
            if self._leds_pub is not None:
                self._leds_pub.offer(rec.frame, rec.t_start, self.loop.last_frame)
        except Exception as exc:  # the bus must never stop the stimulus  # noqa: BLE001
            self.loop.fault("bus", rec.t_sent, exc)

    def _status_loop(self) -> None:
        """Once a second: place new threads and processes, publish the status. Both run in the frame loop's idle
        time (`FrameLoop.when_idle`), so that they never take the GIL from a frame; this thread runs what the
        loop has not run within a second (a loop blocked, e.g. by a scene load)."""
        while not self._stopping.wait(1.0):
            for task in (self.placement.place_threads, self._publish_status):
                claim = threading.Lock()  # whoever takes it runs the task: the loop's idle time or this thread

                def once(task=task, claim=claim) -> None:
                    if claim.acquire(blocking=False):
                        try:
                            task()
                        except Exception as exc:  # the status thread must outlive any one failure  # noqa: BLE001
                            self.echo(f"antarium serve: {task.__name__.strip('_')} failed: {exc}")

                try:
                    self.loop.when_idle(once).result(1.0)
                except LoopClosed:  # the server shuts down
                    return
                except TimeoutError:
                    if self._stopping.is_set():  # the loop ended: nothing to place or publish any more
                        return
                    once()

    def _publish_status(self) -> None:
        status = self.status()
        self._echo_alarms(status["alarms"])
        if self.session is not None:
            self.session.put(bus.status_key(self.rig_name), json.dumps(status, default=_json_default))

    def _echo_alarms(self, alarms: list[str]) -> None:
        """Print each status alarm on stderr when it appears, and when it has cleared (not while stopping: what
        the shutdown stops is no alarm)."""
        if self._stopping.is_set():
            return
        now = {_alarm_key(a): a for a in alarms}
        for key in self._alarms_echoed - now.keys():
            self.echo(f"antarium serve: alarm cleared: {key}")
        for key in now.keys() - self._alarms_echoed:
            self.echo(f"antarium serve: ALARM: {now[key]}")
        self._alarms_echoed = set(now)

    def status(self) -> dict[str, Any]:
        """`antarium.server.status.rig_status`; a trial-log error seen for the first time also goes out as an event."""
        out = rig_status(self)
        error = out.get("log", {}).get("error")
        if error and error != self._last_log_error and self.loop is not None:
            self._last_log_error = error
            self.loop.call_soon(self.loop.event, "log_error", error=error)
        return out

    # -- commands --------------------------------------------------------------------------------------
    def command(self, name: str, params: Any = None) -> Any:
        """Validate and execute one command (any thread); returns its result or raises with the reason."""
        try:
            checked = parse_command(name, params)
        except CommandError as exc:
            self._log_command(name, params, {"error": str(exc)}, False)
            raise
        command = COMMANDS[name]
        if not command.in_loop:
            try:
                return command.handler(self, checked)
            except (CommandError, ValueError, RuntimeError, OSError) as exc:
                self._log_command(name, params, {"error": str(exc)}, False)
                raise
        if self.loop is None or not self._loop_running():
            raise RuntimeError(f"{name}: the server is not running")
        if command.prepare is not None:
            try:
                checked["prepared"] = self.placement.beside_loop(command.prepare, self, checked)
            except LoopClosed:
                raise RuntimeError(f"{name}: the server is stopping; the command was not run") from None
            except (CommandError, ValueError, RuntimeError, OSError) as exc:
                self._log_command(name, params, {"error": str(exc)}, False)
                raise
            if not self._loop_running():  # stopped meanwhile: what was prepared is never shown
                _release(checked["prepared"])
                raise RuntimeError(f"{name}: the server is not running")
        future = self.loop.call_soon(self._apply, name, checked, params)
        try:
            return future.result(COMMAND_TIMEOUT_S)
        except LoopClosed:  # queued after the loop's last frame (a timed run ending): never waits for one
            _release(checked.get("prepared"))
            raise RuntimeError(f"{name}: the server is stopping; the command was not run") from None
        except TimeoutError:
            if future.cancel():
                _release(checked.get("prepared"))
            raise RuntimeError(f"{name}: the frame loop did not run the command within {COMMAND_TIMEOUT_S} s") \
                from None

    def _apply(self, name: str, p: dict[str, Any], request: Any) -> Any:
        """Run a checked command in the loop's thread; log it with its outcome."""
        try:
            result = COMMANDS[name].handler(self, p)
        except (CommandError, ValueError, RuntimeError, OSError) as exc:
            self._log_command(name, request, {"error": str(exc)}, False)
            raise
        result = self.state() if result is None else result
        if COMMANDS[name].edits_scene:
            self._scene_edits.append({"command": name, "request": request})
        self._log_command(name, request, {"result": result}, True)
        return result

    def _log_command(self, name, request, reply, ok, *, last: bool = False) -> None:
        """A row in the running trial's commands table; never raises, so that a command's own error always reaches
        its caller: a name or request the table cannot hold (a NUL in the name) is logged as its ascii(). Commands
        come from several threads: the time is read under the lock that appends the rows, so that the table's `t`
        never steps back. `last`: the trial's last row (trial_stop); no command is logged into the trial after it."""
        with self._command_log_lock:
            log = self.trial_log
            if log is None:
                return
            t = self.clock.now()
            try:
                log.add_command(t, name, request, reply, ok)
            except (ValueError, TypeError, RecursionError):
                log.add_command(t, ascii(name), ascii(request), ascii(reply), ok)
            if last:
                self.trial_log, self.trial_name, self.trial_started = None, None, None

    def state(self) -> dict[str, Any]:
        """What a command replies: pose, scene rotation, loop mode, gains, scene and trial."""
        return {**loop_state(self.loop), "scene": self.scene_name, "trial": self.trial_name}

    def require_renderer(self, what: str):
        """The renderer, or RuntimeError naming `what` needed it (a pose-only rig has none)."""
        if self.renderer is None:
            raise RuntimeError(f"{what}: this rig has no renderer (pose-only)")
        return self.renderer

    def prepare_scene(self, scene: str | dict):
        """The work of loading `scene` while frames go on: parsing, buffers, far field and far layer (in the scene's
        own process), then the meshes' upload a slice per frame in the loop's idle time, then a far layer fresh
        at the eye; None for a renderer that cannot prepare (it then loads in `load_scene`)."""
        renderer = self.require_renderer("load_scene")
        if not hasattr(renderer, "prepare_scene"):
            return None
        loop = self.loop
        try:
            prepared = renderer.prepare_scene(scene, pose=lambda: loop.pose)
        except (OSError, ValueError, RuntimeError, KeyError, TypeError, ArithmeticError) as exc:
            raise self._scene_failed(scene, exc) from None
        try:
            while not loop.when_idle(renderer.upload_step, prepared).result(UPLOAD_STEP_WAIT_S):
                pass
        except TimeoutError:  # the loop is held up or stopped: `load_scene` uploads what is left
            pass
        except LoopClosed:  # the server shuts down: the scene is never shown
            prepared.release()
            raise
        except Exception as exc:  # the GL driver refused the upload: nothing of the scene is kept
            prepared.release()
            raise self._scene_failed(scene, exc) from None
        renderer.await_layer(prepared, lambda: loop.pose)  # the eye walked on meanwhile
        return prepared

    def load_scene(self, scene: str | dict, prepared=None) -> None:
        """Load a scene (name, file path or spec; `prepared` by `prepare_scene`: only swapped in here) into the
        renderer; on failure the previous scene stays."""
        renderer = self.require_renderer("load_scene")
        digest = _scene_sha256(scene)
        try:
            if prepared is None:
                renderer.set_scene(scene)
            else:  # the old scene's GL objects are released one per frame, in the loop's idle time
                renderer.set_scene(prepared, retire=True)
                for _ in range(renderer.retired):
                    self.loop.when_idle(renderer.release_retired)
        except (OSError, ValueError, RuntimeError, KeyError, TypeError, ArithmeticError) as exc:
            raise self._scene_failed(scene, exc) from None
        self.scene_name = scene if isinstance(scene, str) else json.dumps(scene, sort_keys=True)
        self._scene_digest = digest
        self._scene_edits = []
        self.loop.renderer_changed()
        log = self.trial_log  # read once: trial_stop may end the trial in another thread
        if log is not None:
            log.add_scene(self.clock.now(), self.scene_name, digest)
        self.loop.event("scene_loaded", scene=scene, sha256=digest)

    def _scene_failed(self, scene: str | dict, exc: BaseException) -> RuntimeError:
        kept = "no scene was loaded before" if self.scene_name is None else \
            f"the current scene {self.scene_name!r} stays on the dome"
        return RuntimeError(f"load_scene: scene {_shown(scene)} failed to load ({_brief(str(exc))}); {kept}")

    def trial_start(self, name: str, metadata: dict, folder: str = "") -> dict[str, Any]:
        """Open the trial log `<folder or [log] dir>/<rig>_<time>_<name>.h5` and have the frame loop write into it;
        reply {"path": its absolute path}. A trial that cannot start (the loop does not take its log within
        COMMAND_TIMEOUT_S, the server is stopping) leaves no file and no trial: the reply and the state agree."""
        from antarium.trial_log import LogError, TrialLog, check_log_dir, log_path

        with self._trial_lock:
            if self._shut_down:
                raise RuntimeError("trial_start: the server is stopping; no trial was started")
            if self.trial_log is not None:
                raise RuntimeError(f"trial_start: trial {self.trial_name!r} is running; stop it first")
            try:
                json.dumps(metadata)
            except (TypeError, ValueError) as exc:
                raise CommandError(f"trial_start: metadata must be JSON-serialisable: {exc}") from None
            if folder and not Path(folder).is_absolute():
                raise CommandError(f"trial_start: parameter 'folder' must be an absolute path, got {_shown(folder)}")
            try:
                path = log_path(check_log_dir(folder or self.log_dir), self.rig_name, name)  # made again if removed
                log = TrialLog(path, self.config.to_toml_dict(), name, metadata, flush_s=self.config.log.flush_s,
                               clock=self.clock.now)
            except LogError as exc:
                raise RuntimeError(f"trial_start: {exc}") from None
            if self.scene_name is not None:
                log.add_scene(self.clock.now(), self.scene_name, self._scene_digest)
            if self.loop is None:  # not started: the loop is built with this log
                self.trial_log, self.trial_name = log, name
            else:
                try:
                    self._in_loop("trial_start", "no trial was started", self._attach_log, log, name, metadata)
                except BaseException as exc:  # nothing of the trial is kept: no file, the state as it was
                    log.close()
                    path.unlink(missing_ok=True)
                    if isinstance(exc, LoopClosed):
                        raise RuntimeError("trial_start: the server is stopping; no trial was started") from None
                    raise
            self.trial_paths.append(path)
            self._last_log_error = None
            self._log_command("trial_start", {"name": name, "metadata": metadata}, {"path": str(path)}, True)
            return {"path": str(path)}

    def _loop_running(self) -> bool:
        """True when frames run in another thread (commands must then go through `call_soon`)."""
        return (self._ready.is_set() and not self._stopping.is_set() and self._start_error is None
                and threading.current_thread() is not self._loop_thread)

    def _in_loop(self, what: str, kept: str, fn: Callable, *args: Any) -> None:
        """`fn(*args)` in the frame loop's thread (here when no frames run in another thread). RuntimeError "`what`:
        ...; `kept`" when the loop has not run it within COMMAND_TIMEOUT_S (it then never does); LoopClosed when
        the loop has run its last frame."""
        if not self._loop_running():
            fn(*args)
            return
        future = self.loop.call_soon(fn, *args)
        try:
            future.result(COMMAND_TIMEOUT_S)
        except TimeoutError:
            if future.cancel():
                raise RuntimeError(f"{what}: the frame loop did not take it within {COMMAND_TIMEOUT_S:g} s (held up); "
                                   f"{kept}") from None
            future.result()  # the loop has just begun it: a moment

    def _attach_log(self, log, name: str, metadata: dict) -> None:
        """The loop writes into `log` from its next frame, and the trial runs (loop's thread)."""
        self.loop.log = log
        if hasattr(self.source, "use_log"):  # a source with a table of its own (servosphere)
            try:
                self.source.use_log(log)
            except BaseException:
                self.loop.log = None
                raise
        self.trial_log, self.trial_name = log, name
        anchor = self._clock_anchor()
        self.trial_started = {"t": anchor["monotonic"], "metadata": metadata}
        self.loop.event("trial_started", name=name, metadata=metadata, path=str(log.path), state=self._start_state(),
                        **anchor)

    def _start_state(self) -> dict[str, Any]:
        """What the dome shows as a trial starts (loop's thread), for its log: the loop's pose, scene rotation, mode,
        tether and gains, the scene, its edits and sky changes since it was loaded (the commands' requests, in
        order), the brightness (None without a renderer) and the polariser angles held (55 x 9 deg; None: they
        follow the sky)."""
        held = self.loop.polariser_override
        return {**loop_state(self.loop), "scene": self.scene_name, "scene_changes": list(self._scene_edits),
                "brightness": getattr(self.renderer, "brightness", None),
                "polarisers_deg": None if held is None else np.degrees(held).tolist()}

    def _clock_anchor(self) -> dict[str, Any]:
        """`utc` (ISO 8601) and `monotonic` (s, on the loop's clock, the tables' clock) read at the same instant."""
        monotonic, utc = self.clock.now(), _dt.datetime.now(_dt.UTC)
        return {"utc": utc.isoformat(), "monotonic": monotonic}

    def trial_stop(self, path: str | None = None) -> dict[str, Any]:
        """Stop the running trial; with `path`, only when it is the one recording into that log (RuntimeError naming
        the running one otherwise, nothing stopped: a script's trial block never stops another script's trial)."""
        if self._stopping_elsewhere():  # detaching the log from here could lose the loop's last frame
            return self._trial_closed_by_shutdown(path)
        with self._trial_lock:  # checked and stopped under one lock: no trial starts between the two
            if self.trial_log is None:
                raise RuntimeError("trial_stop: no trial is running")
            _check_trial_path(self.trial_log, self.trial_name, path)
            return self._close_trial()

    def _close_trial(self) -> dict[str, Any]:
        """End the running trial (holding `_trial_lock`): the loop stops writing into its log, the trial_stop row is
        its last (the trial ends with it: a command arriving while the log closes is not logged into it, never
        counted lost), and the log is closed (at most trial_log.CLOSE_TIMEOUT_S)."""
        log = self.trial_log
        if self.loop is not None:
            try:
                self._in_loop("trial_stop", f"trial {self.trial_name!r} goes on", self._detach_log)
            except LoopClosed:  # the loop has run its last frame: nothing writes into the log any more
                self._detach_log()
        self._log_command("trial_stop", {}, {"path": str(log.path)}, True, last=True)
        log.close()
        return {"path": str(log.path), **log.status()}

    def _end_trial(self) -> None:
        """The shutdown's end of the running trial, if any: after a trial_start in flight has ended (none starts
        once the shutdown has begun)."""
        with self._trial_lock:
            if self.trial_log is not None:
                self._close_trial()

    def _remove_frameless_logs(self) -> None:
        """No frame ran (a start-up that failed or was stopped): the trial logs opened for it hold none and are
        removed, so that none is taken for a recording."""
        for path in self.trial_paths:
            path.unlink(missing_ok=True)
            self.echo(f"antarium serve: no frame ran: removed the empty trial log {path}")
        self.trial_paths = []

    def _stopping_elsewhere(self) -> bool:
        """The server is stopping while its frame loop's thread, not this one, may still be in its last frame."""
        t = self._loop_thread
        return self._stopping.is_set() and t is not None and t is not threading.current_thread() and t.is_alive()

    def _trial_closed_by_shutdown(self, path: str | None = None) -> dict[str, Any]:
        """trial_stop while the server stops: its shutdown closes the trial after the loop's last frame; wait for
        that (at most COMMAND_TIMEOUT_S) and reply as trial_stop does."""
        log, name = self.trial_log, self.trial_name
        if log is None:
            raise RuntimeError("trial_stop: no trial is running")
        _check_trial_path(log, name, path)
        deadline = time.monotonic() + COMMAND_TIMEOUT_S
        while self.trial_log is log and self._loop_thread.is_alive() and time.monotonic() < deadline:
            time.sleep(0.005)
        # the shutdown holds `_trial_lock` until the log is closed
        if self.trial_log is log or not self._trial_lock.acquire(timeout=max(0.0, deadline - time.monotonic())):
            raise RuntimeError(f"trial_stop: the server is stopping and has not closed trial {name!r} "
                               f"within {COMMAND_TIMEOUT_S:g} s; it closes it when the last frame is done")
        self._trial_lock.release()
        return {"path": str(log.path), **log.status()}

    def _detach_log(self) -> None:
        self.loop.event("trial_stopped", name=self.trial_name, path=str(self.trial_log.path), **self._clock_anchor())
        self.loop.log = None
        if hasattr(self.source, "use_log"):
            self.source.use_log(None)

    # -- running ---------------------------------------------------------------------------------------
    def run(self, until: float | None = None, frames: int | None = None, seconds: float | None = None) -> int:
        """Build the renderer here, start the bus and run frames until `stop()`, the clock reads `until`,
        `frames` frames ran, or `seconds` passed since the first frame. Returns the number of frames run; whatever
        ends it (a start-up that failed or was cancelled, see `cancel_start`), everything is closed when it returns
        or raises."""
        self._loop_thread = threading.current_thread()
        try:
            loop_cfg = self.config.loop
            self.placement.before_building()
            self.link = self._open_link()
            if self.link is not None and self._link_arg is None:  # a link of its own: the panels' current settings
                # from [link], which the link holds and sends again to a distributor that reboots
                from antarium.firmware_proto.config import read_dot_correction

                self.link.send_config(dot_correction=read_dot_correction(self.config.link.dot_correction),
                                      brightness=self.config.link.brightness_percent)
            self.renderer = self._renderer_factory(self.config.render, self.clock) if self._renderer_factory \
                else None
            self.loop = FrameLoop.from_config(
                loop_cfg, clock=self.clock, source=self.source, renderer=self.renderer, link=self.link,
                log=self.trial_log, on_frame=self._on_frame, on_event=self._publish_event,
                link_bps=self.config.link.speed_mbit_s * 1e6)
            if self.renderer is not None:
                self.load_scene(self.config.render.scene)
                if hasattr(self.renderer, "wait_far_layer") and not self.renderer.wait_far_layer(self.loop.pose):
                    self.echo("antarium serve: the far layer is not ready; the first frames are drawn in full")
            self._open_bus()
            if self.source is not None:
                if self.session is not None and hasattr(self.source, "use_session"):
                    self.source.use_session(self.session)  # a bus source shares the server's session
                self.source.start()
            if (self.record or self.config.log.record) and self.trial_log is None:
                self.trial_start(self.record or "recording", {})
            # Everything long-lived exists now (renderer, scene, link, bus): move it out of the garbage collector's
            # way, so that a collection during the experiment scans only what frames allocate — a full collection
            # over these object graphs would stall a frame for milliseconds.
            _freeze_gc()
            self._gc_frozen = True
            self._status_thread = threading.Thread(target=self._status_loop, name="status", daemon=True)
            self._status_thread.start()
            self.placement.before_frames()
            with self._start_lock:  # from here on `cancel_start` leaves the stopping to `stop()`
                self._ready.set()
                cancelled = self._stopping.is_set()
        except BaseException as exc:
            self._start_error = exc
            self._ready.set()
            self._shutdown()
            raise
        self.loop.event("server_started", rig=self.rig_name)
        if cancelled:  # stopped while starting (`cancel_start`, `stop()`): no frame runs
            self.loop.stop()
        if seconds is not None:
            end = self.clock.now() + seconds
            until = end if until is None else min(until, end)
        try:
            return self.loop.run(until=until, frames=frames)
        except Exception as exc:
            self._loop_failed(exc)
            raise
        finally:
            self._shutdown()

    def _loop_failed(self, exc: Exception) -> None:
        """The frame loop ended on an error (a link that raises, an incompatible distributor): say so on stderr,
        as a `server_failed` event (into the trial log before it closes) and as a status alarm."""
        self.loop_error = exc
        try:
            self.loop.event("server_failed", error=f"{type(exc).__name__}: {exc}", frames=self.loop.frame)
        except Exception as failure:  # noqa: BLE001 - the log is closed after all the same
            self.echo(f"antarium serve: server_failed: {type(exc).__name__}: {exc} (not logged: {failure})")
        self._alarms_echoed.add("frame loop stopped")  # printed just now, as the event
        try:
            self._publish_status()  # the last status, with the alarm (the status thread ends now)
        except Exception:  # noqa: BLE001 - said on stderr already
            pass

    def cancel_start(self) -> bool:
        """Stop a start-up in progress before its first frame (thread-safe; also in a signal handler in the thread
        that runs `run()`). True when the server was starting (not yet running frames, not failed, not stopped):
        `run()` then runs no frame and closes what it had built, at the latest when it would have begun running
        frames; a signal handler may interrupt it sooner by raising KeyboardInterrupt (`close()` then closes what
        was open). False otherwise: a running server is stopped with `stop()`."""
        with self._start_lock:
            if self._ready.is_set() or self._shut_down:
                return False
            self._stopping.set()
            return True

    def close(self) -> None:
        """Stop the server and close everything it opened; safe twice, and after `run()`, which closes it all itself
        when it returns or raises. For a start-up interrupted where `run()` could not close what it had opened
        (a KeyboardInterrupt from a signal handler after `cancel_start`, arriving before `run()` or between its
        steps). A server that runs in another thread is only stopped (`stop()`), its own thread closes it."""
        self.stop()
        if self._loop_thread in (None, threading.current_thread()):
            self._shutdown()

    def wait_ready(self, timeout_s: float | None = None) -> bool:
        """Block until the first frame is about to run (or starting failed); False on timeout."""
        return self._ready.wait(timeout_s) and self._start_error is None

    def start_thread(self, timeout_s: float = 60.0) -> Server:
        """Run the server in a thread of its own; returns when it runs (or raises why it could not start: not
        running within `timeout_s`, what was starting is stopped first, waiting up to 30 s for it).
        A server starts once: a second call raises ServerError (`with Server(...).start_thread():` is fine)."""
        if self._thread is not None:
            raise ServerError(f"server {self.rig_name!r} was started already; a server starts once (start_thread() or "
                              "`with Server(...)`), stop() ends it")
        self._thread = threading.Thread(target=self._run_quietly, name=f"antarium-server {self.rig_name}", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s):
            try:  # no server left starting, and then running, behind the caller's back
                self.stop()
            except ServerError:
                pass
            stopped = "stopped it" if not self._thread.is_alive() else "it is still stopping"
            raise ServerError(f"the server did not start within {timeout_s} s; {stopped}")
        if self._start_error is not None:
            raise ServerError(f"the server could not start: {self._start_error}") from self._start_error
        return self

    def _run_quietly(self) -> None:
        try:
            self.run()
        except BaseException as exc:  # reported by start_thread  # noqa: BLE001
            self._start_error = self._start_error or exc

    def stop(self, timeout_s: float = 30.0) -> None:
        """Stop the frame loop (thread-safe); with a server thread, wait until everything is closed. A server thread
        whose frame loop had ended on an error (see `loop_error`: it was printed, logged as `server_failed` and
        is a status alarm) makes the first `stop()` raise it as a ServerError, as `run()` would have."""
        self._stopping.set()
        if self.loop is not None:
            self.loop.stop()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
            error = self.loop_error
            if error is not None and not self._loop_error_raised and not self._thread.is_alive():
                self._loop_error_raised = True
                raise ServerError(f"the frame loop stopped: {type(error).__name__}: {error}") from error

    def _shutdown(self) -> None:
        """Close everything, each step on its own: one that fails (a device gone) is printed and the others still
        run; the emulator is always stopped and the loop's placement always undone. Runs once: later calls return
        at once. The loop's calls queued meanwhile (a command that came after its last frame) fail at once."""
        with self._start_lock:
            if self._shut_down:
                return
            self._shut_down = True
        self._stopping.set()
        step = self._shutdown_step
        if self.loop is not None:
            self.loop.refuse_calls("the server is stopping")
            step("keeping the final statistics", self._keep_final_stats)
        step("closing the trial log", self._end_trial)
        if (self.loop is None or self.loop.frame == 0) and self.loop_error is None:
            step("removing the trial logs of a start-up that ran no frame", self._remove_frameless_logs)
        for part in (self.monitor, self._leds_pub):
            if part is not None:
                step(f"closing {type(part).__name__}", part.close)
        for entity in reversed(self._entities):
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 - a closed session has undeclared them already
                pass
        self._entities = []
        step("waiting for the bus commands being answered", self._await_queries)
        if self._own_session and self.session is not None:
            step("closing the bus session", self.session.close)
            self.session = None
        if self.source is not None:
            step("stopping the locomotion source", self.source.stop)
        if self.link is not None and self._link_arg is None:
            step("closing the dome link", self.link.close)
        if self.emulator is not None:
            step("stopping the dome emulator", self.emulator.stop)
        release = getattr(self.renderer, "release", None)
        if release is not None:
            step("releasing the renderer", release)
        step("undoing the loop's CPU placement", self._unpin)
        if self._gc_frozen:
            self._gc_frozen = False
            _unfreeze_gc()

    def _shutdown_step(self, what: str, fn: Callable[[], Any]) -> None:
        try:
            fn()
        except Exception as exc:  # noqa: BLE001 - the steps after it must run all the same
            self.echo(f"antarium serve: {what} failed: {type(exc).__name__}: {exc}")

    def _keep_final_stats(self) -> None:
        self.final_stats = self.loop.stats()
        if self.renderer is not None and hasattr(self.renderer, "far_layer_status"):
            self.final_stats["far_layer"] = self.renderer.far_layer_status()
        if self.loop.last_frame is not None:
            self.final_frame = self.loop.last_frame.copy()

    def _unpin(self) -> None:
        """Undo the loop's placement (a script goes on running); the status thread places threads until it ends."""
        if self._status_thread is not None and self._status_thread is not threading.current_thread():
            self._status_thread.join(2.0)
        self.placement.release()

    def __enter__(self) -> Server:
        return self if self._thread is not None else self.start_thread()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _check_trial_path(log, name: str | None, path: str | None) -> None:
    """RuntimeError, nothing stopped, when `path` is given and is not the running trial's log (`log`, trial `name`)."""
    if path is not None and str(log.path) != path:
        raise RuntimeError(f"trial_stop: the trial of log {_brief(path)!r} is not running (stopped by another "
                           f"client?); the running trial {name!r} ({log.path}) was not stopped")


def _alarm_key(alarm: str) -> str:
    """What an alarm is about, without its changing details ("dome link down: no telemetry for 0.63 s")."""
    return alarm.split(":", 1)[0].split(" (", 1)[0]


def _release(prepared) -> None:
    """Free what a command's prepare step made (a prepared scene's far-layer process) when it is not shown."""
    release = getattr(prepared, "release", None)
    if release is not None:
        release()


def _stages(*seconds: float) -> float:
    """The time of the stages that ran (NaN ones did not): their sum, NaN when none ran (a rig without renderer)."""
    ran = [v for v in seconds if v == v]
    return sum(ran) if ran else math.nan


def _scene_sha256(scene: str | dict) -> str:
    """SHA-256 of the scene's file(s) (a path, or the spec's 'scene'/'path'/'panorama' files); "" for built-ins."""
    from antarium.trial_log import file_sha256

    paths = [scene] if isinstance(scene, str) else [scene.get(k) for k in ("scene", "path", "panorama", "uv")]
    digests = [file_sha256(p) for p in paths if isinstance(p, str) and Path(p).is_file()]
    return ",".join(digests)


def _json_default(value: Any) -> Any:

    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return str(value)
