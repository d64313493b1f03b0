"""The `servosphere` locomotion source: the control loop (camera -> tracker -> PD -> rotors) and, as `BallSample`s,
the ball rotation the firmware reports from its step counts (Eq. 4), so the dome follows the free ant's walk.

One `ServosphereLoop.step()` per camera frame. On a `SimulatedClock` the source runs the frames due in `read()`
(faster than real time, reproducible); otherwise a thread of its own runs them, paced by the camera. Faults (bits
of `FAULTS`) stop the ball (rates ramp to 0 at the acceleration limit), are counted and logged; the loop goes on.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import numpy as np

from antarium.core.clock import Clock, MonotonicClock, SimulatedClock
from antarium.locomotion import BallSample, BufferedSource
from antarium.locomotion.servosphere import open_camera, open_motor_link
from antarium.locomotion.servosphere import protocol as p
from antarium.locomotion.servosphere.controller import Controller, ControllerConfig
from antarium.locomotion.servosphere.kinematics import RotorGeometry, StepperLimits
from antarium.locomotion.servosphere.tracker import Calibration, Tracker, calibrate

#: host-side fault names; bit i of a log row's `faults` is FAULTS[i]
FAULTS = ("no_ant", "two_blobs", "link_timeout", "link_garbled", "stall", "watchdog", "firmware_bad_message")
_BIT = {name: 1 << i for i, name in enumerate(FAULTS)}
_STALLS = p.FAULT_STALL_1 | p.FAULT_STALL_2 | p.FAULT_STALL_3
#: the dome loop's tether -> the counter_rotate it needs (with counter_rotate the ball's yaw is the ant's turning)
_COUNTER_ROTATE = {"free_yaw": False, "fixed": True}


class ServosphereLoop:
    """camera (`grab() -> (t, frame)`), link (`MotorLink`), tracker, controller; `step()` runs one frame and returns
    (new BallSamples, log row in `SERVOSPHERE_DTYPE` order). link_timeout_s: longest wait for a reply before the
    line counts as lost; stall_hold_s: how long the ball stays stopped after a stall before the loop retries.
    The fault bits of replies to commands sent before the last ClearFaults are ignored: that cleared them."""

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
        self._cam_mm_s: tuple[float, float] | None = None
        self._last_reply_t: float | None = None
        self._link_errors = 0
        self._steps: np.ndarray | None = None
        self._t_dev: float | None = None
        self._stall_since: float | None = None
        self._clear_seq: int | None = None  # seq of the last ClearFaults sent
        self._sample_seq = 0
        self.last_faults = 0

    def step(self) -> tuple[list[BallSample], tuple]:
        t, image = self.camera.grab()
        dt = t - self._t_prev if self._t_prev is not None else 1.0 / self.camera.frame_rate
        self._t_prev = t
        det = self.tracker.update(image, self._walk_mm_s())
        samples, fw_faults = self._replies(t)
        faults = _BIT[det.fault] if det.fault else 0
        if self._last_reply_t is None:
            self._last_reply_t = t  # the first reply is due one round trip after the first command
        if t - self._last_reply_t > self.link_timeout_s:
            faults |= _BIT["link_timeout"]
        errors = sum(self.link.errors.values())
        if errors != self._link_errors:
            self._link_errors = errors
            faults |= _BIT["link_garbled"]
        faults |= self._firmware_faults(fw_faults, t)
        stop = faults & (_BIT["no_ant"] | _BIT["two_blobs"] | _BIT["link_timeout"] | _BIT["stall"])
        error = None if stop else (det.x_mm, det.y_mm)
        rates = self.controller.update(error, det.heading, dt)
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
        self._cam_mm_s = ((xy[0] - self._xy_prev[0]) / dt, (xy[1] - self._xy_prev[1]) / dt) \
            if xy is not None and self._xy_prev is not None and dt > 0 else None
        self._xy_prev = xy
        return samples, row

    def _walk_mm_s(self) -> tuple[float, float] | None:
        """The ant's walk over the ball's surface (mm/s, dome frame): its velocity in the camera over the last
        frame minus the apex surface's velocity (omega_y R, -omega_x R) for the ball rotation asked for."""
        if self._cam_mm_s is None:
            return None
        wx, wy, _ = self.controller.omega
        r_mm = self.geometry.sphere_radius * 1000.0
        return self._cam_mm_s[0] - wy * r_mm, self._cam_mm_s[1] + wx * r_mm

    def _replies(self, t: float) -> tuple[list[BallSample], int]:
        samples = []
        faults = None
        for status, steps in self.link.poll():
            self._last_reply_t = t
            cleared = self._clear_seq is not None and (status.seq - self._clear_seq) % 65536 >= 32768
            faults = 0 if cleared else status.faults
            t_dev = status.t_us * 1e-6
            if self._t_dev is not None:
                t_dev = self._t_dev + ((status.t_us - round(self._t_dev * 1e6)) % 2 ** 32) * 1e-6
            if self._steps is not None:
                rotation = self.geometry.sphere_omega((steps - self._steps) * self.rad_per_step)
                self._sample_seq += 1
                samples.append(BallSample(t, self._sample_seq, tuple(float(v) for v in rotation), t_dev,
                                          0.0 if status.faults & _STALLS else 1.0))
            self._steps, self._t_dev = steps, t_dev
        return samples, faults if faults is not None else 0

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
                 port: str = "", baudrate: int = 1_000_000, camera_index: int | str = 0,
                 calibration: dict | None = None, kp: float = 1.25, kd: float = 0.005, counter_rotate: bool = False,
                 threshold: int = 120, area_mm2: tuple[float, float] = (5.0, 60.0), rotors: dict | None = None,
                 steppers: dict | None = None, clock: Clock | None = None, tether: str = "free_yaw",
                 ball_radius: float | None = None) -> None:
        super().__init__()
        if not isinstance(tether, str) or _COUNTER_ROTATE.get(tether) is not bool(counter_rotate):
            raise ValueError(f"servosphere tether {tether!r} with counter_rotate {str(bool(counter_rotate)).lower()}; "
                             "allowed: tether 'free_yaw' without counter_rotate, or 'fixed' with it")
        self.clock = clock or MonotonicClock()
        rotors = {k: (tuple(v) if isinstance(v, list) else v) for k, v in (rotors or {}).items()}
        if ball_radius is not None:
            if not math.isclose(rotors.setdefault("sphere_radius", ball_radius), ball_radius):
                raise ValueError(f"servosphere rotors sphere_radius {rotors['sphere_radius']} m differs from the "
                                 f"loop's ball_radius {ball_radius} m; allowed: one value ([loop] ball_radius_m)")
        geometry = RotorGeometry(**rotors)
        limits = StepperLimits(**(steppers or {}))
        self.rig = None
        if "simulated" in (camera, link):
            if (camera, link) != ("simulated", "simulated"):
                raise ValueError(f"servosphere camera {camera!r} with link {link!r}: the simulated rig needs both "
                                 "simulated; allowed: both 'simulated', or a real camera with a real link")
            from antarium.locomotion.servosphere.rig import SimulatedRig

            self.rig = SimulatedRig(self.clock, geometry=geometry, limits=limits, **(simulation or {}))
            cam = open_camera("simulated", rig=self.rig)
            motor = open_motor_link("simulated", rig=self.rig)
            cal = calibrate(self.rig.calibration_image())  # the calibration path a real rig takes
        else:
            cam = open_camera(camera, index=camera_index, clock=self.clock)
            motor = open_motor_link(link, url=port, baudrate=baudrate)
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
        while not self._stop.is_set():
            self._run_step()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        if not self._closed:  # the firmware ramps the rotors to 0; then the port and the camera are released
            self._closed = True
            self.loop.link.stop()
            self.loop.link.close()
            self.loop.camera.close()

    def read(self) -> list[BallSample]:
        if self._catch_up:
            cam = self.loop.camera
            while cam.next_t <= self.clock.now() + 1e-12:
                self._run_step()
        return super().read()

    def status(self) -> dict[str, Any]:
        loop = self.loop
        return {"connected": True, "frames": loop.frame, "faults": dict(loop.fault_counts),
                "faults_now": [name for name, bit in _BIT.items() if loop.last_faults & bit],
                "link": {"sent": loop.link.sent, "received": loop.link.received, "errors": loop.link.errors},
                "tracker_faults": dict(loop.tracker.faults)}


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
