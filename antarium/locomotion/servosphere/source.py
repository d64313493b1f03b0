"""The `servosphere` locomotion source: the control loop (camera -> tracker -> PD -> rotors) and, as `BallSample`s,
the ball rotation the firmware reports from its step counts (the omniwheel contact model, `kinematics`), so the
dome follows the free ant's walk.

One `ServosphereLoop.step()` per camera frame. On a `SimulatedClock` the source runs the frames due in `read()`
(faster than real time, reproducible); otherwise a thread of its own runs them, paced by the camera. Faults (bits
of `FAULTS`) stop the ball (rates ramp to 0 at the acceleration limit), are counted and logged; the loop goes on.
"""

from __future__ import annotations

import inspect
import math
import threading
import time
from collections import deque
from typing import Any

import numpy as np

from antarium.core.clock import Clock, MonotonicClock, SimulatedClock
from antarium.locomotion import BallSample, BufferedSource
from antarium.locomotion.servosphere import open_camera, open_motor_link
from antarium.locomotion.servosphere import protocol as p
from antarium.locomotion.servosphere.controller import Controller, ControllerConfig
from antarium.locomotion.servosphere.kinematics import RotorGeometry, StepperLimits
from antarium.locomotion.servosphere.tracker import Calibration, Tracker, calibrate, frame_problem

#: host-side fault names; bit i of a log row's `faults` is FAULTS[i]
FAULTS = ("no_ant", "two_blobs", "link_timeout", "link_garbled", "stall", "watchdog", "firmware_bad_message",
          "firmware_reset", "ant_at_edge", "bad_frame")
_BIT = {name: 1 << i for i, name in enumerate(FAULTS)}
#: a reply whose step counts moved more than max_rate * (its clock's advance + RESET_MARGIN_S) + 2 steps since the
#: previous one, or whose clock went back, comes from a firmware that restarted (counters and clock from 0)
RESET_MARGIN_S = 0.002
#: ... and so does a reply whose clock went forward more than the host time since the previous reply (the camera's
#: clock: the frame times `_replies` gets) + RESET_CLOCK_MARGIN_S: a restart after the u32 us clock passed 2^31
#: (35.8 min of run) looks like a step forward of up to 2^31 us. The margin holds how long a reply can wait to be
#: read (a frame or a few) and the two clocks' drift over the longest step the u32 clock tells (2^31 us at 100 ppm:
#: 0.21 s); a restart within the margin of the clock's wrap is left to the counts' test
RESET_CLOCK_MARGIN_S = 0.5
_STALLS = p.FAULT_STALL_1 | p.FAULT_STALL_2 | p.FAULT_STALL_3
#: the dome loop's tether -> the counter_rotate it needs (with counter_rotate the ball's yaw is the ant's turning)
_COUNTER_ROTATE = {"free_yaw": False, "fixed": True}
#: consecutive frames the camera may give unusable (none, or not uint8 (H, W): `tracker.frame_problem`) before the
#: loop ends with an error; each is a `bad_frame` fault (ball ramped to 0). 350 is 0.5 s at 700 frames/s
MAX_BAD_FRAMES = 350
#: the ant's walk (which end is its head) is judged from its displacement over the last WALK_WINDOW_S, once at
#: least WALK_MIN_S of it is known
WALK_WINDOW_S, WALK_MIN_S = 0.08, 0.05


class ServosphereLoop:
    """camera (`grab() -> (t, frame)`), link (`MotorLink`), tracker, controller; `step()` runs one frame and returns
    (new BallSamples, log row in `SERVOSPHERE_DTYPE` order). link_timeout_s: longest wait for a reply before the
    line counts as lost; stall_hold_s: how long the ball stays stopped after a stall before the loop retries.
    The fault bits of replies to commands sent before the last ClearFaults are ignored (that cleared them), until
    the reply to the clear or to a later command arrives: from then on every reply's faults count."""

    def __init__(self, camera, link, tracker: Tracker, controller: Controller, link_timeout_s: float = 0.02,
                 stall_hold_s: float = 0.1) -> None:
        self.camera, self.link, self.tracker, self.controller = camera, link, tracker, controller
        self.link_timeout_s, self.stall_hold_s = float(link_timeout_s), float(stall_hold_s)
        self.geometry = controller.config.geometry
        self.rad_per_step = controller.config.limits.rad_per_step
        self.frame = 0
        self.fault_counts = dict.fromkeys(FAULTS, 0)
        self._t_prev: float | None = None
        self._xy_prev: tuple[float, float] | None = None
        self._walk: deque[tuple[float, float, float]] = deque()  # (t, walk x, walk y mm), the last WALK_WINDOW_S
        self._walk_xy = (0.0, 0.0)  # the ant's walk over the ball's surface, integrated (mm, dome frame)
        self._last_reply_t: float | None = None
        self._link_errors = 0
        self._steps: np.ndarray | None = None
        self._t_dev: float | None = None
        self._t_us: int | None = None  # the newest reply's raw firmware clock (us, wraps at 2^32)
        self.max_rate = controller.config.limits.max_rate
        self._stall_since: float | None = None
        self._clear_seq: int | None = None  # seq of the last ClearFaults sent
        self._sample_seq = 0
        self._bad_frames = 0  # unusable frames since the last good one
        self.last_faults = 0

    def step(self) -> tuple[list[BallSample], tuple]:
        t, image = self.camera.grab()
        dt = t - self._t_prev if self._t_prev is not None else 1.0 / self.camera.frame_rate
        self._t_prev = t
        det = self.tracker.update(image, self._walk_mm_s())
        self._bad_frames = self._bad_frames + 1 if det.fault == "bad_frame" else 0
        if self._bad_frames >= MAX_BAD_FRAMES:
            raise RuntimeError(f"the camera gave no usable frame in the last {self._bad_frames} "
                               f"({frame_problem(image)}); allowed: uint8 (H, W) monochrome frames")
        samples, fw_faults, reset = self._replies(t)
        faults = _BIT[det.fault] if det.fault else 0
        if reset:
            faults |= _BIT["firmware_reset"]
        if self._last_reply_t is None:
            self._last_reply_t = t  # the first reply is due one round trip after the first command
        if t - self._last_reply_t > self.link_timeout_s:
            faults |= _BIT["link_timeout"]
        errors = sum(self.link.errors.values())
        if errors != self._link_errors:
            self._link_errors = errors
            faults |= _BIT["link_garbled"]
        faults |= self._firmware_faults(fw_faults, t)
        stop = faults & (_BIT["no_ant"] | _BIT["two_blobs"] | _BIT["ant_at_edge"] | _BIT["bad_frame"]
                         | _BIT["link_timeout"] | _BIT["stall"])
        error = None if stop else (det.x_mm, det.y_mm)
        omega_before = self.controller.omega  # what was asked for over the frame that just ended
        # the yaw is only counter-rotated on a heading the walk confirmed: a guess held at 0
        rates = self.controller.update(error, det.heading if det.heading_confident else math.nan, dt)
        if self._stall_since is not None:
            self.link.stop()
            rates = np.zeros(3)  # what Stop sends: every target 0
        else:
            self.link.send_rates(rates)
        for name, bit in _BIT.items():
            if faults & bit:
                self.fault_counts[name] += 1
        self.last_faults = faults
        self.frame += 1
        omega = self.controller.omega
        steps = self._steps if self._steps is not None else np.zeros(3, np.int64)
        row = (t, self.frame, det.x_mm, det.y_mm, det.orientation, det.heading, *omega, *rates, *steps, faults)
        xy = None if det.fault else (det.x_mm, det.y_mm)
        if xy is None:
            self._walk.clear()  # a gap: the walk restarts with the next good frame
        else:
            if self._xy_prev is not None and self._walk:
                # the ant's walk over the surface = its motion in the camera minus the apex surface's motion
                # (omega_y R, -omega_x R) dt for the ball rotation asked for over this frame
                r_mm = self.geometry.sphere_radius * 1000.0
                self._walk_xy = (self._walk_xy[0] + xy[0] - self._xy_prev[0] - omega_before[1] * r_mm * dt,
                                 self._walk_xy[1] + xy[1] - self._xy_prev[1] + omega_before[0] * r_mm * dt)
            self._walk.append((t, *self._walk_xy))
            while t - self._walk[0][0] > WALK_WINDOW_S:
                self._walk.popleft()
        self._xy_prev = xy
        return samples, row

    def _walk_mm_s(self) -> tuple[float, float] | None:
        """The ant's mean walk over the ball's surface (mm/s, dome frame) over the last `WALK_WINDOW_S` (None
        before `WALK_MIN_S` of it): one frame's velocity at 700 Hz is mostly tracking noise."""
        if len(self._walk) < 2 or self._walk[-1][0] - self._walk[0][0] < WALK_MIN_S:
            return None
        (t0, x0, y0), (t1, x1, y1) = self._walk[0], self._walk[-1]
        return (x1 - x0) / (t1 - t0), (y1 - y0) / (t1 - t0)

    def _replies(self, t: float) -> tuple[list[BallSample], int, bool]:
        samples = []
        faults = None
        reset = False
        for status, steps in self.link.poll():
            t_last, self._last_reply_t = self._last_reply_t, t  # the host times of the previous reply, this one
            cleared = False
            if self._clear_seq is not None:
                if (status.seq - self._clear_seq) % 65536 >= 32768:
                    cleared = True  # a reply to a command sent before the ClearFaults
                else:
                    self._clear_seq = None  # the clear's reply (or a later one) came: every later reply counts
            faults = 0 if cleared else status.faults
            t_dev = status.t_us * 1e-6
            if self._t_dev is not None:
                dt_us = (status.t_us - self._t_us) % 2 ** 32
                jump = np.abs(steps - self._steps).max()
                if (dt_us >= 2 ** 31 or dt_us * 1e-6 > t - t_last + RESET_CLOCK_MARGIN_S
                        or jump > self.max_rate * (dt_us * 1e-6 + RESET_MARGIN_S) + 2):
                    # the firmware restarted (its clock went back or ran ahead of the host's, or the counts jumped
                    # further than the rotors can turn): no rotation from this reply; counts and clock go on from it
                    reset = True
                    self._steps, self._t_us = steps, status.t_us
                    continue
                t_dev = self._t_dev + dt_us * 1e-6
            if self._steps is not None:
                rotation = self.geometry.sphere_omega((steps - self._steps) * self.rad_per_step)
                self._sample_seq += 1
                samples.append(BallSample(t, self._sample_seq, tuple(float(v) for v in rotation), t_dev,
                                          0.0 if status.faults & _STALLS else 1.0))
            self._steps, self._t_dev, self._t_us = steps, t_dev, status.t_us
        return samples, faults if faults is not None else 0, reset

    def _firmware_faults(self, fw: int, t: float) -> int:
        """Fault bits from the firmware's; a stall stops the ball for `stall_hold_s` (the stall bit set on every
        frame that sends Stop), then faults are cleared."""
        out = 0
        if fw & _STALLS:
            out |= _BIT["stall"]
            if self._stall_since is None:
                self._stall_since = t
        if self._stall_since is not None and t - self._stall_since >= self.stall_hold_s:
            self._clear_faults()
            self._stall_since = None
        if self._stall_since is not None:
            out |= _BIT["stall"]
        if fw & p.FAULT_WATCHDOG:
            out |= _BIT["watchdog"]
        if fw & p.FAULT_BAD_MESSAGE:
            out |= _BIT["firmware_bad_message"]
        if fw & (p.FAULT_WATCHDOG | p.FAULT_BAD_MESSAGE) and not fw & _STALLS:
            self._clear_faults()  # the ball is commanded again from this frame on
        return out

    def _clear_faults(self) -> None:
        self._clear_seq = self.link.clear_faults()


class ServosphereSource(BufferedSource):
    """Locomotion source `servosphere`. camera, link: back-end names (`simulated`, or `opencv` / `serial`);
    simulation: keyword arguments of `rig.SimulatedRig` (both back-ends `simulated`); port, baudrate: the serial
    line; camera_index; calibration: {apex_px = [x, y], mm_per_px, rotation_deg} or {image = "path.png",
    disc_diameter_mm}; kp, kd, counter_rotate; threshold (grey level), area_mm2 [min, max];
    rotors: {azimuth_deg, elevation_deg, wheel_radius, sphere_radius}; steppers: {steps_per_rev, max_rate,
    max_accel}. ball_radius (m): the dome loop's (`antarium serve` and `antarium servosphere --config` pass
    `[loop] ball_radius_m`); it is the sphere's radius unless `rotors` sets one, and must then be equal. `tether`: the
    loop's too (`[loop] tether`): free_yaw without counter_rotate, or fixed with it (the ball's yaw is then the
    ant's turning)."""

    def __init__(self, camera: str = "simulated", link: str = "simulated", simulation: dict | None = None,
                 port: str | None = None, baudrate: int | None = None, camera_index: int | str | None = None,
                 calibration: dict | None = None, kp: float = 1.25, kd: float = 0.005, counter_rotate: bool = False,
                 threshold: int = 120, area_mm2: tuple[float, float] = (5.0, 60.0), rotors: dict | None = None,
                 steppers: dict | None = None, clock: Clock | None = None, tether: str = "free_yaw",
                 ball_radius: float | None = None) -> None:
        super().__init__()
        if not isinstance(tether, str) or _COUNTER_ROTATE.get(tether) is not bool(counter_rotate):
            raise ValueError(f"servosphere tether {tether!r} with counter_rotate {str(bool(counter_rotate)).lower()}; "
                             "allowed: tether 'free_yaw' without counter_rotate, or 'fixed' with it")
        self.clock = clock or MonotonicClock()
        rotors = {k: (tuple(v) if isinstance(v, list) else v)
                  for k, v in _table("rotors", rotors, RotorGeometry).items()}
        if ball_radius is not None:
            if not math.isclose(rotors.setdefault("sphere_radius", ball_radius), ball_radius):
                raise ValueError(f"servosphere rotors sphere_radius {rotors['sphere_radius']} m differs from the "
                                 f"loop's ball_radius {ball_radius} m; allowed: one value ([loop] ball_radius_m)")
        geometry = RotorGeometry(**rotors)
        limits = StepperLimits(**_table("steppers", steppers, StepperLimits))
        self.rig = None
        if "simulated" in (camera, link):
            if (camera, link) != ("simulated", "simulated"):
                raise ValueError(f"servosphere camera {camera!r} with link {link!r}: the simulated rig needs both "
                                 "simulated; allowed: both 'simulated', or a real camera with a real link")
            real_only = [name for name, value in (("calibration", calibration), ("port", port),
                                                  ("baudrate", baudrate), ("camera_index", camera_index))
                         if value is not None]
            if real_only:
                raise ValueError(f"servosphere option {real_only[0]} is for a real rig; the simulated rig calibrates "
                                 "itself and has no port: allowed with it: simulation, kp, kd, counter_rotate, "
                                 "threshold, area_mm2, rotors, steppers, tether")
            from antarium.locomotion.servosphere.rig import SimulatedRig

            simulation = _table("simulation", simulation, SimulatedRig, taken=("clock", "geometry", "limits"))
            self.rig = SimulatedRig(self.clock, geometry=geometry, limits=limits, **simulation)
            cam = open_camera("simulated", rig=self.rig)
            motor = open_motor_link("simulated", rig=self.rig)
            cal = calibrate(self.rig.calibration_image())  # the calibration path a real rig takes
        else:
            if simulation is not None:
                raise ValueError("servosphere simulation options are for the simulated rig (camera and link "
                                 f"'simulated'), not camera {camera!r} with link {link!r}; allowed with a real rig: "
                                 "port, baudrate, camera_index, calibration")
            if link == "serial" and not port:
                raise ValueError("servosphere link 'serial' needs [locomotion] port: the firmware's serial device "
                                 "(e.g. '/dev/ttyACM0') or a pyserial URL")
            cam = open_camera(camera, index=0 if camera_index is None else camera_index, clock=self.clock)
            motor = open_motor_link(link, url=port, baudrate=1_000_000 if baudrate is None else baudrate)
            cal = _calibration(calibration)
        self.calibration = cal
        tracker = Tracker(cal, threshold=threshold, area_mm2=tuple(area_mm2))
        controller = Controller(ControllerConfig(kp=kp, kd=kd, counter_rotate=counter_rotate, geometry=geometry,
                                                 limits=limits))
        self.loop = ServosphereLoop(cam, motor, tracker, controller)
        self.tether = tether
        self._log = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._catch_up = isinstance(self.clock, SimulatedClock)
        self._closed = False
        self.step_s = 0.0  # wall time spent in steps (s), for the status line and the benchmark
        self.error: str | None = None  # what ended the loop (a device error), None while it runs

    def use_log(self, log) -> None:
        """The trial log that gets a `servosphere` row per camera frame (None: no log)."""
        self._log = log

    def _run_step(self) -> None:
        t0 = time.perf_counter()
        samples, row = self.loop.step()
        self.step_s += time.perf_counter() - t0
        for s in samples:
            self._push(s)
        log = self._log
        if log is not None:
            log.add_servosphere(row)

    def start(self) -> None:
        if self._catch_up or self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="servosphere", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._run_step()
        except Exception as exc:  # noqa: BLE001 - a device error ends the loop; status() reports it
            self.fail(exc)

    def fail(self, exc: BaseException) -> None:
        """The loop stopped on `exc` (a serial or camera error): record it for `status()` (connected false, the
        error) and try to send Stop, so that the firmware ramps the rotors to 0 rather than waiting for its
        watchdog."""
        self.error = f"{type(exc).__name__}: {exc}"
        try:
            self.loop.link.stop()
        except Exception:  # noqa: BLE001, S110 - the line is already broken; the watchdog stops the rotors
            pass

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        if not self._closed:  # the firmware ramps the rotors to 0; then the port and the camera are released
            self._closed = True
            for release in (self.loop.link.stop, self.loop.link.close, self.loop.camera.close):
                try:
                    release()
                except Exception:  # noqa: BLE001 - after a device error: release what can be released
                    if self.error is None:
                        raise

    def read(self) -> list[BallSample]:
        if self._catch_up:
            cam = self.loop.camera
            while cam.next_t <= self.clock.now() + 1e-12:
                self._run_step()
        return super().read()

    def status(self) -> dict[str, Any]:
        loop = self.loop
        return {"connected": self.error is None, "error": self.error, "frames": loop.frame,
                "faults": dict(loop.fault_counts),
                "faults_now": [name for name, bit in _BIT.items() if loop.last_faults & bit],
                "link": {"sent": loop.link.sent, "received": loop.link.received, "errors": loop.link.errors,
                         "stalled": loop.link.stalled},
                "tracker_faults": dict(loop.tracker.faults)}


def _table(name: str, cfg: dict | None, factory, taken: tuple[str, ...] = ()) -> dict:
    """`[locomotion] name = {...}` ({} for None), checked against the keyword parameters of `factory` less those the
    source sets itself (`taken`); ValueError naming the first unknown key and the allowed ones."""
    allowed = sorted(set(inspect.signature(factory).parameters) - set(taken))
    if cfg is None:
        return {}
    if not isinstance(cfg, dict):
        raise ValueError(f"servosphere {name} must be a table {{key = value, ...}}, got {cfg!r}; allowed keys: "
                         f"{', '.join(allowed)}")
    unknown = sorted(set(cfg) - set(allowed))
    if unknown:
        raise ValueError(f"servosphere {name} has no option {unknown[0]!r}; allowed: {', '.join(allowed)}")
    return cfg


#: the two forms of `[locomotion] calibration`: its key that picks the form -> (required keys, optional keys)
_CALIBRATION_FORMS = {"apex_px": (("apex_px", "mm_per_px"), ("rotation_deg",)),
                      "image": (("image",), ("disc_diameter_mm", "rotation_deg"))}


def _calibration(cfg: dict | None) -> Calibration:
    """The camera calibration from `[locomotion] calibration`: {apex_px = [x, y] (pixels), mm_per_px,
    rotation_deg} or {image = "path.png", disc_diameter_mm, rotation_deg}; ValueError naming a missing or unknown
    key and the allowed ones."""
    forms = " or ".join("{" + ", ".join(req + tuple(f"[{k}]" for k in opt)) + "}"
                        for req, opt in _CALIBRATION_FORMS.values())
    if not cfg or not isinstance(cfg, dict):
        raise ValueError(f"a real servosphere needs [locomotion] calibration = {forms}")
    required, optional = _CALIBRATION_FORMS["image" if "image" in cfg else "apex_px"]
    unknown = sorted(set(cfg) - set(required) - set(optional))
    if unknown:
        raise ValueError(f"servosphere calibration has unknown key {unknown[0]!r}; allowed: "
                         f"{', '.join(sorted(required + optional))}")
    missing = [k for k in required if k not in cfg]
    if missing:
        raise ValueError(f"servosphere calibration needs {missing[0]}; allowed: {forms}")
    rotation_deg = cfg.get("rotation_deg", 0.0)
    if "image" in cfg:
        import cv2

        image = cv2.imread(str(cfg["image"]), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise ValueError(f"servosphere calibration image {cfg['image']!r} cannot be read")
        return calibrate(image, cfg.get("disc_diameter_mm", 10.0), rotation_deg)
    apex = cfg["apex_px"]
    return Calibration(tuple(apex) if isinstance(apex, list) else apex, cfg["mm_per_px"], rotation_deg)
