"""The experiment-script API: drive a running `antarium serve` over the bus, synchronously.

    import antarium

    with antarium.Rig("rig1") as rig:
        rig.load_scene("familiar.glb")
        rig.closed_loop(True)
        with rig.trial("familiar-1", ant=7, colony="M. croslandi"):
            rig.wait(30)
            rig.rotate_scene(90)
            rig.wait(30)
        print(rig.pose())

Every method waits for the server's reply; an error reply raises `RigError` carrying the server's message
(the rig's state is then unchanged). No reply in time raises `RigTimeout` (a RigError): the command may have run
all the same (a slow scene load), so read `status()` before sending it again. Angles are in degrees here (the
script's edge), metres for positions.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from antarium import bus
from antarium.core.clock import MonotonicClock
from antarium.core.numbers import as_real, check_number
from antarium.core.pose import Pose

#: the longest `Rig.wait` (s): a day; anything longer is a typo
WAIT_MAX_S = 86_400.0


class RigError(RuntimeError):
    """The server refused a command (its message says why), or no server answered."""


class RigTimeout(RigError):
    """No reply to a command within the Rig's timeout: the server may still have run it (check `status()`)."""


def _plain(value: Any) -> Any:
    """numpy scalars and arrays as plain numbers and lists (for JSON, and for messages: `-5.0`, not
    `np.float64(-5.0)`); anything else is not a command parameter (TypeError)."""
    tolist = getattr(value, "tolist", None)
    if tolist is None:
        raise TypeError(f"{type(value).__name__} is not a number, string, list or object")
    return tolist()


def _payload(command: str, params: dict[str, Any]) -> str:
    """`params` as the command's JSON payload; RigError naming the first parameter that cannot be sent (a set, a
    circular list, nesting deeper than JSON's writer goes) and what can."""
    try:
        return json.dumps(params, default=_plain)
    except (TypeError, ValueError, RecursionError):
        for name, value in params.items():
            try:
                json.dumps(value, default=_plain)
            except (TypeError, ValueError, RecursionError) as exc:
                why = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
                raise RigError(f"{command}: parameter {name!r} cannot be sent ({why}); allowed: numbers, strings, "
                               "booleans, lists and objects (numpy arrays and numbers too)") from None
        raise


@dataclass(frozen=True, slots=True)
class PoseUpdate:
    """One pose from the server's stream: frame number, server time (s), pose, scene rotation (rad), mode."""

    frame: int
    t: float
    pose: Pose
    scene_rotation: float
    closed_loop: bool
    fixed_tether: bool


def _decode_pose(payload: bytes) -> PoseUpdate:
    d = bus.decode_pose(payload)
    return PoseUpdate(d["frame"], d["t"], Pose(d["x"], d["y"], d["z"], d["heading"]), d["scene_rotation"],
                      d["closed_loop"], d["fixed_tether"])


class Rig:
    """A connection to rig `name`.

    config: a rig config (TOML path or resolved dict) whose `[bus]` section says where the server listens;
    default: the embedded default (127.0.0.1:7447). connect: endpoints to use instead, e.g.
    ["tcp/192.168.1.10:7447"]. timeout_s: how long to wait for the server and for each reply. log_dir: a folder
    for this script's trial logs (made absolute here; a path on the server's computer, so give it when the server
    runs on this one); default: the server's [log] dir.
    """

    def __init__(self, name: str = "rig1", *, config: str | Path | dict | None = None,
                 connect: list[str] | None = None, timeout_s: float = 10.0, session=None,
                 log_dir: str | Path | None = None, clock=None) -> None:
        from antarium.config import BusSection, ConfigError, RigConfig, load_config, resolve

        try:
            self.name = bus.check_rig_name(name)
        except ValueError as exc:
            raise RigError(str(exc)) from None
        if isinstance(config, RigConfig):
            cfg = config
        else:
            cfg = resolve(config) if isinstance(config, dict) else load_config(config)
        if connect is None:
            self.bus_section = cfg.bus
        else:
            if isinstance(connect, str) or not isinstance(connect, list | tuple):
                raise RigError(f"connect must be a list of endpoints, e.g. ['tcp/192.168.10.1:7447'], got "
                               f"{connect!r:.80}")
            try:  # checked as the config's own [bus] connect is
                self.bus_section = BusSection.read({**cfg.bus.model_dump(), "connect": list(connect)})
            except ConfigError as exc:
                raise RigError(f"connect: {exc}") from None
        value = as_real(timeout_s)
        if not (0 < value <= WAIT_MAX_S):  # longer overflows the waits of threading and zenoh
            raise RigError(f"timeout_s must be a positive number of seconds (at most {WAIT_MAX_S:g}), got "
                           f"{_shown(timeout_s)}")
        self.timeout_s = value
        self.log_dir = None if log_dir is None else Path(log_dir).expanduser().resolve()
        if clock is not None and not all(callable(getattr(clock, m, None)) for m in ("now", "sleep_until")):
            raise RigError(f"clock must have now() and sleep_until(t) in seconds (antarium.core.clock.Clock), got "
                           f"{type(clock).__name__}")
        #: the script's clock, for `wait` and `now` (default: wall time); a `SimulatedClock` runs a protocol's
        #: schedule without waiting for it (the dome's own frames keep the server's clock)
        self.clock = MonotonicClock(spin_s=0.0) if clock is None else clock
        self._session = session
        self._own_session = session is None
        self._latest: PoseUpdate | None = None
        self._latest_lock = threading.Lock()
        self._subs: list = []
        self._alive = threading.Event()
        self._server_lost = False  # the server's liveliness token went away since it was first seen

    # -- connection ------------------------------------------------------------------------------------
    @property
    def session(self):
        """The open zenoh session (None before `connect`): subscribe to other streams of the rig through it."""
        return self._session

    def connect(self) -> Rig:
        """Open the session and wait until the server's liveliness token is seen."""
        if self._subs:  # connected already
            return self
        if self._session is None:
            self._session = bus.open_session(self.bus_section, role="client")
        self._subs.append(self._session.declare_subscriber(bus.pose_key(self.name), self._on_pose_sample))
        self._subs.append(self._session.liveliness().declare_subscriber(
            bus.alive_key(self.name), self._on_alive, history=True))
        if not self._alive.wait(self.timeout_s):
            where = self.bus_section.connect or self.bus_section.listen
            others = self._rigs_answering()
            info = self._session.info
            reached = [str(zid) for zid in (*info.routers_zid(), *info.peers_zid())]
            self.close()
            if others:
                seen = f"servers answering there: rig {', '.join(map(repr, others))} (a misspelt name?)"
            elif reached:  # a connection, but no token seen: a router without the server, or a server's refusal
                seen = (f"this computer reached the zenoh session(s) {', '.join(reached)} there, which shows no "
                        "antarium server: the server is not running, or its bus access control ([bus] access_control) "
                        "refuses this computer")
            else:
                seen = "no other antarium server answered there either"
            raise RigError(f"no antarium server for rig {self.name!r} answered within {self.timeout_s} s "
                           f"(tried {where}); is `antarium serve` running? {seen}")
        return self

    def _rigs_answering(self, wait_s: float = 0.5) -> list[str]:
        """The names of the rigs whose servers' liveliness tokens answer on this session's bus, sorted."""
        replies = self._session.liveliness().get(bus.any_alive_key(), timeout=wait_s)
        return sorted({bus.rig_of(reply.ok.key_expr) for reply in replies if reply.ok is not None})

    def _on_alive(self, sample) -> None:
        """The server's liveliness token appeared or went away (a bus thread). Both after the first are told on
        stderr, one line each: a server that comes back is a new run, with its config's state, not the script's."""
        import zenoh

        if sample.kind == zenoh.SampleKind.PUT:
            self._alive.set()
            if self._server_lost:
                self._server_lost = False
                self._tell(f"the server of rig {self.name!r} is back: a new run, with its config's scene, pose, modes "
                           "and no trial (frame numbers start again); set again what the script had set")
        else:  # the server is gone: its last pose is no longer the rig's
            self._alive.clear()
            self._server_lost = True
            with self._latest_lock:
                self._latest = None
            self._tell(f"the server of rig {self.name!r} is gone (its liveliness token went away); commands fail "
                       "until it is back")

    @staticmethod
    def _tell(message: str) -> None:
        print(f"antarium.Rig: {message}", file=sys.stderr, flush=True)

    def _on_pose_sample(self, sample) -> None:
        try:
            update = _decode_pose(sample.payload.to_bytes())
        except bus.StreamError:
            return
        with self._latest_lock:
            self._latest = update

    def close(self) -> None:
        self._alive.clear()  # a later connect() waits for the server again
        self._server_lost = False
        with self._latest_lock:
            self._latest = None
        for sub in self._subs:
            with contextlib.suppress(Exception):
                sub.undeclare()
        self._subs = []
        if self._own_session and self._session is not None:
            self._session.close()
            self._session = None

    def __enter__(self) -> Rig:
        return self.connect()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the one request path --------------------------------------------------------------------------
    def call(self, command: str, **params: Any) -> Any:
        """Send `command` with JSON `params`; return the server's result or raise `RigError` with its message."""
        from antarium.server.commands import COMMANDS

        if not isinstance(command, str) or command not in COMMANDS:
            raise RigError(f"unknown command {_shown(command)}; allowed: {', '.join(COMMANDS)}")
        if self._session is None:
            raise RigError("the rig is not connected; use `with Rig(...) as rig:` or `rig.connect()`")
        payload = _payload(command, params)
        self._check_server(command, "the command was not sent")
        key = bus.command_key(self.name, command)
        wait_s = self.reply_s(command)
        sent = time.monotonic()
        replies = self._session.get(key, payload=payload, timeout=wait_s)
        for reply in replies:
            if reply.ok is not None:
                body = json.loads(reply.ok.payload.to_bytes())
                return body.get("result")
            raw = reply.err.payload.to_bytes()
            error = RigTimeout if raw.decode(errors="replace").strip().lower() == "timeout" else RigError
            raise error(self._error_message(command, raw))
        waited = time.monotonic() - sent
        if waited < 0.9 * wait_s:  # the bus ended the query before its time: nobody to answer, not a slow server
            raise RigError(f"{command}: no reply from rig {self.name!r}: the bus ended the query after {waited:.1f} s "
                           f"(of {wait_s:g} s) without one: refused by the bus's access control (the rig is unchanged; "
                           "this computer may not command it, status() included), or the server went away during "
                           "it (it may have run: check status() once the server is back)")
        raise RigTimeout(f"{command}: no reply from rig {self.name!r} within {wait_s:g} s "
                         "(server gone, or the command was refused by the bus's access control); it may have run: "
                         "check status() before sending it again")

    def _check_server(self, what: str, outcome: str) -> None:
        """RigError at once when the Rig is connected and its server's liveliness token went away: nobody to ask."""
        if self._subs and not self._alive.is_set():
            raise RigError(f"{what}: the server of rig {self.name!r} is gone (its liveliness token went away); "
                           f"{outcome}")

    def reply_s(self, command: str) -> float:
        """How long `call` waits for `command`'s reply (s): the Rig's `timeout_s`, or the command's own `reply_s`
        when longer (a scene load)."""
        from antarium.server.commands import COMMANDS

        return max(self.timeout_s, COMMANDS[command].reply_s or 0.0)

    def _error_message(self, command: str, raw: bytes) -> str:
        """The message of an error reply: the server's own (JSON {"error": ...}), or the bus's (zenoh's "Timeout"
        when the server did not reply in time, or another of its errors) said as what happened."""
        try:
            body = json.loads(raw)
        except ValueError:
            body = None
        if isinstance(body, dict) and isinstance(body.get("error"), str):
            return body["error"]
        text = raw.decode(errors="replace").strip()
        if text.lower() == "timeout":
            return (f"no reply from rig {self.name!r} to {command} within {self.reply_s(command):g} s (the server is "
                    "busy or stuck; it may still have run it: check status() before sending it again; raise "
                    "--timeout, or `timeout_s` of Rig, if it needs longer)")
        return f"{command}: the bus answered with an error instead of rig {self.name!r}: {text or 'no message'}"

    # -- commands --------------------------------------------------------------------------------------
    def load_scene(self, scene: str | Path | dict) -> dict:
        """Show `scene`: a built-in name ("habitat", "horizon", ...), a mesh or panorama file, or a spec
        {"scene": name, **parameters}. On failure the current scene stays on the dome."""
        return self.call("load_scene", scene=scene if isinstance(scene, dict) else str(scene))

    def closed_loop(self, on: bool = True) -> dict:
        """Closed loop (the ball moves the ant through the world) or open loop (pose under script control)."""
        return self.call("closed_loop", on=on)

    def tether(self, mode: str) -> dict:
        """"free_yaw" (ball gives translation only) or "fixed" (ball gives yaw too; the scene rotates)."""
        return self.call("tether", tether=mode)

    def gains(self, translation: float | None = None, rotation: float | None = None) -> dict:
        params = {k: v for k, v in (("translation", translation), ("rotation", rotation)) if v is not None}
        return self.call("gains", **params)

    def rotate_scene(self, deg: float) -> dict:
        """Rotate the scene instantly by `deg` degrees, counter-clockwise seen from above."""
        return self.call("rotate_scene", deg=deg)

    def set_pose(self, x: float, y: float, heading_deg: float | None = None, z: float | None = None) -> dict:
        """Virtual displacement to (x, y) metres (and heading, degrees), now."""
        params: dict[str, Any] = {"x": x, "y": y}
        if heading_deg is not None:
            params["heading_deg"] = heading_deg
        if z is not None:
            params["z"] = z
        return self.call("set_pose", **params)

    def reset_origin(self, x: float | None = None, y: float | None = None, heading_deg: float | None = None,
                     z: float | None = None) -> dict:
        """Back to the virtual origin; with x, y (m; and heading, degrees; eye height z, m) make that the new origin
        first."""
        params = {k: v for k, v in (("x", x), ("y", y), ("heading_deg", heading_deg), ("z", z)) if v is not None}
        return self.call("reset_origin", **params)

    def scene_edit(self, op: str, **args: Any) -> dict:
        """Edit the current scene: op "move_object" (name, position [m], yaw_deg), "remove_object" (name),
        "scale_channel" (channel, factor), "swap_green_blue" (swap), "set_lowpass" (cutoff_deg),
        "set_contrast" (contrast), "set_brightness" (brightness)."""
        return self.call("scene_edit", op=op, args=args)

    def sky(self, sun_azimuth_deg: float | None = None, sun_elevation_deg: float | None = None,
            dop_max: float | None = None, sun_radiance: float | None = None) -> dict:
        """Move the sun and/or change the sky's maximum degree of polarisation (scene with a sky)."""
        params = {k: v for k, v in (("sun_azimuth_deg", sun_azimuth_deg), ("sun_elevation_deg", sun_elevation_deg),
                                    ("dop_max", dop_max), ("sun_radiance", sun_radiance)) if v is not None}
        return self.call("sky", **params)

    def polarisers(self, angles_deg=None) -> dict:
        """Hold the 55 x 9 polariser e-vector angles (degrees), or None to follow the scene's sky again
        (the server checks the shape and values)."""
        return self.call("polarisers", angles_deg=angles_deg)

    def start_trial(self, name: str, **metadata: Any) -> str:
        """Start recording a trial; returns the log file's absolute path (on the server's computer)."""
        folder = {} if self.log_dir is None else {"folder": str(self.log_dir)}
        return self.call("trial_start", name=name, metadata=metadata, **folder)["path"]

    def stop_trial(self, path: str | Path | None = None) -> dict:
        """Stop the running trial; with `path` (`start_trial`'s), only that one: RigError, nothing stopped, when
        another client's trial is running instead."""
        return self.call("trial_stop", **({} if path is None else {"path": str(path)}))

    @contextlib.contextmanager
    def trial(self, name: str, **metadata: Any) -> Iterator[str]:
        """`with rig.trial("name", ant=3):` records the block in one log file (its path is yielded). Ctrl-C in the
        block stops the trial and says on stderr that its log is closed and kept, with its frames. When the block
        raises, that error is the one raised: a stop that fails too (the server gone) is told on stderr."""
        path = self.start_trial(name, **metadata)
        try:
            yield path
        except BaseException as exc:
            self._stop_after(name, path, exc)
            raise
        self.stop_trial(path)

    def _stop_after(self, name: str, path: str, exc: BaseException) -> None:
        """Stop trial `name` (log `path`), whose block raised `exc`, without hiding `exc`."""
        try:
            done = self.stop_trial(path)
        except RigError as stop:
            print(f"trial {name!r} was not stopped ({stop}); the error in its block follows", file=sys.stderr,
                  flush=True)
            return
        if isinstance(exc, KeyboardInterrupt):
            frames = done.get("rows_written", {}).get("frames", 0)
            print(f"trial {name!r} stopped by the interruption: its log {path} is closed and kept ({frames} frames)",
                  file=sys.stderr, flush=True)

    def status(self) -> dict:
        return self.call("status")

    # -- streams ---------------------------------------------------------------------------------------
    def pose(self, timeout_s: float | None = None) -> Pose:
        """The newest pose from the server's stream (waits for the first one up to `timeout_s`); RigError when the
        rig is not connected or its server is gone."""
        if self._session is None:
            raise RigError("the rig is not connected; use `with Rig(...) as rig:` or `rig.connect()`")
        wait = self.timeout_s if timeout_s is None else as_real(timeout_s)
        if not 0 <= wait < math.inf:
            raise RigError(f"pose: timeout_s must be a finite number of seconds >= 0, got {_shown(timeout_s)}")
        deadline = time.monotonic() + wait
        while True:
            with self._latest_lock:
                latest = self._latest
            if latest is not None:
                return latest.pose
            self._check_server("pose", "there is no pose")
            if time.monotonic() >= deadline:
                p = self.status()["pose"]
                return Pose(p["x"], p["y"], p["z"], math.radians(p["heading_deg"]))
            time.sleep(0.005)

    def latest(self) -> PoseUpdate | None:
        """The newest `PoseUpdate` (frame, time, pose, scene rotation), or None before the first."""
        with self._latest_lock:
            return self._latest

    def on_pose(self, callback: Callable[[PoseUpdate], None]):
        """Call `callback(PoseUpdate)` for every pose the server publishes (on a bus thread; keep it short).
        Returns the subscription; `.undeclare()` it to stop. See `_subscribe` for a callback that raises."""
        def decode(payload: bytes) -> PoseUpdate | None:
            try:
                return _decode_pose(payload)
            except bus.StreamError:
                return None

        return self._subscribe("on_pose", bus.pose_key(self.name), decode, callback)

    def on_event(self, callback: Callable[[dict], None]):
        """Call `callback({"t", "kind", "data"})` for every server event (a malformed message is skipped, never
        handed on)."""
        return self._subscribe("on_event", bus.events_key(self.name), bus.json_object, callback)

    def _subscribe(self, what: str, key: str, decode: Callable[[bytes], Any], callback: Callable[[Any], None]):
        """Subscribe `callback(decode(payload))` to `key` (payloads decoded to None are skipped). An exception of
        the callback is told on stderr, the first with its traceback, then one line every 1000th, and the
        subscription goes on (a stream of 190 poses a second must not flood the terminal)."""
        if self._session is None:
            raise RigError("the rig is not connected")
        if not callable(callback):
            raise RigError(f"{what} needs a function to call with each message, got {callback!r:.60}")
        failures = 0

        def handler(sample) -> None:
            nonlocal failures
            value = decode(sample.payload.to_bytes())
            if value is None:
                return
            try:
                callback(value)
            except Exception as exc:  # the script's bug: tell it, keep the stream going  # noqa: BLE001
                failures += 1
                if failures == 1:
                    self._tell(f"{what} callback {callback!r:.60} raised (told once, then every 1000th):\n"
                               + "".join(traceback.format_exception(exc)).rstrip())
                elif failures % 1000 == 0:
                    self._tell(f"{what} callback raised {failures} times so far, the latest: "
                               f"{type(exc).__name__}: {exc}")

        sub = self._session.declare_subscriber(key, handler)
        self._subs.append(sub)
        return sub

    def now(self) -> float:
        """Seconds on the Rig's `clock`: for a protocol's own schedule (when a phase began, how long it lasted)."""
        return self.clock.now()

    def wait(self, seconds: float) -> None:
        """Wait `seconds` on the Rig's `clock` (the dome keeps running), at most `WAIT_MAX_S` in one call."""
        value = as_real(seconds)
        shown = repr(value) if math.isfinite(value) else repr(seconds)[:60]
        if not 0 <= value <= WAIT_MAX_S:
            raise RigError(f"wait needs a number of seconds in [0, {WAIT_MAX_S:g}], got {shown}")
        self.clock.sleep_until(self.clock.now() + value)


# -- helpers for experiment scripts ----------------------------------------------------------------------
class ScriptArgumentError(ValueError):
    """An experiment script's option is out of range; the message names the option, its value and what is
    allowed (`run_script` prints it as one line, exit status 2)."""


def _shown(value: Any) -> str:
    number = as_real(value)
    return f"{number:g}" if math.isfinite(number) else repr(value)[:60]


def seconds_value(name: str, value: Any, *, zero: bool = False) -> float:
    """`value` as seconds: a finite number > 0 (>= 0 with `zero`) and at most `WAIT_MAX_S`; otherwise
    ScriptArgumentError naming `name`."""
    number = as_real(value)
    low_ok = number >= 0 if zero else number > 0
    if not (math.isfinite(number) and low_ok and number <= WAIT_MAX_S):
        what = "a number of seconds >= 0" if zero else "a positive number of seconds"
        raise ScriptArgumentError(f"{name} must be {what} (at most {WAIT_MAX_S:g}), got {_shown(value)}")
    return number


def finite_value(name: str, value: Any, low: float = -math.inf, high: float = math.inf) -> float:
    """`value` as a finite number in [low, high] (`antarium.core.numbers.check_number`); otherwise
    ScriptArgumentError naming `name`."""
    try:
        return check_number(name, value, low, high)
    except ValueError as exc:
        raise ScriptArgumentError(str(exc)) from None


def _option(attribute: str) -> str:
    return "--" + attribute.replace("_", "-")


def check_script_arguments(args, *, seconds: tuple[str, ...] = (), numbers: tuple[str, ...] = ()) -> None:
    """Check parsed options before anything is written or connected: the shared ones of `add_script_arguments`
    (--rig a valid rig name, --timeout positive seconds) when present, then the attributes named in `seconds`
    (positive seconds) and `numbers` (finite numbers). The first bad one raises ScriptArgumentError."""
    if getattr(args, "rig", None) is not None:
        try:
            bus.check_rig_name(args.rig)
        except ValueError as exc:
            raise ScriptArgumentError(f"--rig: {exc}") from None
    if hasattr(args, "timeout"):
        seconds_value("--timeout", args.timeout)
    for name in seconds:
        seconds_value(_option(name), getattr(args, name))
    for name in numbers:
        finite_value(_option(name), getattr(args, name))


def _script_errors() -> tuple[type[BaseException], ...]:
    """What `run_script` reports as one line (imported only when something went wrong)."""
    from antarium.config import ConfigError

    errors: tuple[type[BaseException], ...] = (RigError, ScriptArgumentError, ConfigError)
    import sys

    server = sys.modules.get("antarium.server.server")  # only a script that started a server can see its errors
    return errors + ((server.ServerError,) if server is not None else ())


def run_script(main: Callable[[list[str] | None], int | None], argv: list[str] | None = None) -> int:
    """The entry point of an example script: `sys.exit(run_script(main))`. Runs `main(argv)`; a refusal of the
    server or an unreachable rig (RigError), a bad option (ScriptArgumentError), a bad --config (ConfigError) and
    a server that could not start here (ServerError, --start-server) are printed as one line,
    `<script>: error: <message>`, exit status 2; Ctrl-C exits with 130. Anything else is a bug: its traceback."""
    import sys

    prog = Path(sys.argv[0]).name or "script"
    try:
        return int(main(argv) or 0)
    except Exception as exc:
        if not isinstance(exc, _script_errors()):
            raise
        print(f"{prog}: error: {exc}", file=sys.stderr, flush=True)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr, flush=True)
        return 130


def add_script_arguments(parser) -> None:
    """The options every experiment script shares: which rig, where it is, and whether to start one here."""
    parser.add_argument("--rig", default=None,
                        help="rig name (default: the [rig] name of --config; rig1 without --config)")
    parser.add_argument("--config", default=None,
                        help="rig config (TOML) telling where the server listens (default: the embedded default, "
                             "127.0.0.1:7447)")
    parser.add_argument("--start-server", action="store_true",
                        help="start the rig's server in this process first (the embedded default without --config)")
    parser.add_argument("--timeout", type=float, default=30.0,
                        help="seconds to wait for the server and for each reply (default %(default)g)")


def script_rig_name(args, config=None) -> str:
    """The rig a script talks to: --rig, else the [rig] name of --config (the embedded default's without one)."""
    if getattr(args, "rig", None):
        return args.rig
    if config is None:
        from antarium.config import load_config

        config = load_config(args.config)
    return config.rig.name


@contextlib.contextmanager
def script_rig(args, out: str | Path | None = None) -> Iterator[Rig]:
    """A connected `Rig` for parsed `add_script_arguments` options (starting the server here if asked); `out`:
    the script's output folder, where its trial logs go too (on this computer's server; see `Rig` log_dir),
    made only once the rig answers: a refused option, config or server leaves nothing behind, nor does a script
    that fails before it wrote anything there (the folder it made is removed while still empty).
    The rig is --rig, or the [rig] name of --config when --rig is not given. With --start-server the config is
    checked as `antarium serve` checks it (`check_config`: a bus port in use is one ConfigError line). A rig that
    is recording a trial is refused (ScriptArgumentError): the script's scene and loop commands would go into that
    trial before the server refused the script's own."""
    from antarium.config import load_config

    check_script_arguments(args)
    config = load_config(args.config)
    name = script_rig_name(args, config)
    server = None
    if args.start_server:
        from antarium.server import Server, ServerError
        from antarium.server.config_check import check_config

        config.rig.name = name
        server = Server(check_config(config))
        try:
            server.start_thread(timeout_s=args.timeout)
        except ServerError:
            server.stop()  # waits until the failed start-up has closed what it opened (the renderer's shared memory)
            raise
    try:
        with Rig(name, config=config, timeout_s=args.timeout, log_dir=out) as rig:
            recording = rig.status().get("trial")
            if recording is not None:
                raise ScriptArgumentError(f"rig {name!r} is recording trial {_shown(recording)}: this script would "
                                          "change its scene and loop; run it when that trial has ended (one script "
                                          "at a time on a rig)")
            made = out is not None and not Path(out).exists()
            if out is not None:
                try:
                    Path(out).mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise ScriptArgumentError(f"--out {str(out)!r}: cannot make the folder ({exc.strerror}); give "
                                              "a folder this user can write in") from None
            try:
                yield rig
            except BaseException:
                if made:  # a script that failed before writing anything leaves no empty folder behind
                    with contextlib.suppress(OSError):
                        Path(out).rmdir()
                raise
    finally:
        if server is not None:
            server.stop()
