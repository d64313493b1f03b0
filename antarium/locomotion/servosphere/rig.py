"""A simulated servosphere: ball with inertia on three omniwheels, a walking ant, the camera's image and the
serial line's latency, all on the injected clock (a `SimulatedClock` runs it faster than real time).

Physics (sub-steps of `substep_s`): the firmware emulator ramps the steppers; the ball's angular velocity relaxes
with time constant `ball_tau_s` toward what the wheels impose times (1 - `slip`): the omniwheel contact model
(`kinematics`' docstring; each wheel drives the ball only along its own drive direction), solved here on its own,
not the paper's Eq. 4; the ant walks on the ball's surface (speed, spurts of turning, or a waypoint path:
`antarium.locomotion.scripted`'s walker) and is carried by it. Positions are on the ball's top in the dome frame
(mm in the camera, metres in the walker).
"""

from __future__ import annotations

import math
import random
from collections import deque

import cv2
import numpy as np

from antarium.core.clock import Clock, SimulatedClock
from antarium.locomotion.scripted import ScriptedSource
from antarium.locomotion.servosphere.firmware import FirmwareEmulator
from antarium.locomotion.servosphere.kinematics import RotorGeometry, StepperLimits
from antarium.locomotion.servosphere.link import MotorLink
from antarium.locomotion.servosphere.tracker import Calibration


class SimulatedPort:
    """The serial line in front of the firmware emulator: each write reaches it `latency_s` later (or is dropped
    with `drop_prob`, or has one byte flipped with `garble_prob`), and its replies come back as late."""

    def __init__(self, rig: SimulatedRig, latency_s: float, drop_prob: float, garble_prob: float, seed: int) -> None:
        self.rig = rig
        self.latency_s, self.drop_prob, self.garble_prob = latency_s, drop_prob, garble_prob
        self._rng = random.Random(seed)
        self._to_firmware: deque[tuple[float, bytes]] = deque()
        self._to_host: deque[tuple[float, bytes]] = deque()
        self.closed = False

    def _mangle(self, data: bytes) -> bytes | None:
        if self._rng.random() < self.drop_prob:
            return None
        if self._rng.random() < self.garble_prob:
            i = self._rng.randrange(len(data))
            data = data[:i] + bytes([data[i] ^ (1 << self._rng.randrange(8))]) + data[i + 1:]
        return data

    def write(self, data: bytes) -> None:
        if self.closed:
            raise RuntimeError("servosphere simulated port is closed")
        data = self._mangle(data)
        if data is not None:
            self._to_firmware.append((self.rig.t + self.latency_s, data))

    def deliver(self, t: float) -> None:
        """Hand the firmware what reached it by time `t`; queue its replies."""
        while self._to_firmware and self._to_firmware[0][0] <= t:
            t_arrive, data = self._to_firmware.popleft()
            reply = self.rig.firmware.receive(data, t_arrive)
            reply = self._mangle(reply) if reply else None
            if reply:
                self._to_host.append((t_arrive + self.latency_s, reply))

    def read(self) -> bytes:
        """Replies that reached the host by the rig's time (the time of the camera's newest frame)."""
        out = b""
        while self._to_host and self._to_host[0][0] <= self.rig.t:
            out += self._to_host.popleft()[1]
        return out

    def close(self) -> None:
        self.closed = True


class SimulatedCamera:
    """The top-down camera: `grab()` waits on the rig's clock for the next frame (`frame_rate` frames/s, `next_t`),
    runs the rig until then and renders it; returns (t, uint8 (H, W) frame)."""

    def __init__(self, rig: SimulatedRig) -> None:
        self.rig = rig
        self.frame_rate = rig.frame_rate
        self.next_t = rig.clock.now()

    def grab(self) -> tuple[float, np.ndarray]:
        t = self.next_t
        self.next_t += 1.0 / self.frame_rate
        self.rig.clock.sleep_until(t)
        self.rig.advance(t)
        return t, self.rig.render()

    def close(self) -> None:
        pass


class SimulatedRig:
    """Everything physical of a servosphere, simulated. Knobs for tests: `ant_visible`, `distractor_mm`
    (a second ant-sized blob at (x, y) mm, or None), `firmware.stalled[i]`, `port.drop_prob`/`garble_prob`.

    speed (m/s), meander (rad/s s.d. of turn rate, redrawn every spurt_s), pause_fraction (share of spurts
    standing still: the ant stops and starts at once), path [(x, y), ...] m: the ant's walk.
    slip: fraction of the wheels' drive lost (0..0.5). latency_s: one way, serial line + USB.
    """

    def __init__(self, clock: Clock | None = None, *, speed: float = 0.05, meander: float = 2.0, spurt_s: float = 0.5,
                 pause_fraction: float = 0.0, path: list | None = None, seed: int = 0, slip: float = 0.0,
                 ball_tau_s: float = 0.005,
                 latency_s: float = 0.001, drop_prob: float = 0.0, garble_prob: float = 0.0,
                 frame_rate: float = 700.0, size: tuple[int, int] = (640, 480), mm_per_px: float = 0.06,
                 apex_px: tuple[float, float] = (322.0, 236.5), noise_sd: float = 4.0, blur_px: float = 3.0,
                 ant_length_mm: float = 8.0, ant_width_mm: float = 2.5, substep_s: float = 0.0005,
                 geometry: RotorGeometry | None = None, limits: StepperLimits | None = None) -> None:
        if not 0.0 <= slip <= 0.5:
            raise ValueError(f"servosphere rig slip must be in [0, 0.5], got {slip!r}")
        if not 1.0 <= frame_rate <= 5000.0:
            raise ValueError(f"servosphere rig frame_rate must be in [1, 5000] frames/s, got {frame_rate!r}")
        self.clock = clock or SimulatedClock()
        self.geometry = geometry or RotorGeometry()
        self.limits = limits or StepperLimits()
        self.frame_rate = float(frame_rate)
        self.slip, self.ball_tau_s, self.substep_s = float(slip), float(ball_tau_s), float(substep_s)
        # the ball's contact physics, solved here rather than taken from the host's kinematics: omniwheel i
        # imposes the ball's surface speed along its drive direction only, R_s (omega . a_i) = R_w M_i
        g = self.geometry
        self._wheels_to_ball = np.linalg.inv(g.rmat.T) * (g.wheel_radius / g.sphere_radius)
        self.t = self.clock.now()
        self.firmware = FirmwareEmulator(self.limits, t0=self.t)
        self.port = SimulatedPort(self, latency_s, drop_prob, garble_prob, seed + 1)
        self.walker = ScriptedSource(speed=speed, meander=meander, spurt_s=spurt_s, pause_fraction=pause_fraction,
                                     path=path, seed=seed,
                                     rate_hz=1.0 / self.substep_s, ball_radius=self.geometry.sphere_radius)
        self._k = 0
        self.omega = np.zeros(3)  # ball angular velocity, rad/s
        self.ball_rotation = np.zeros(3)  # integral of omega, rad
        self.ant_xy = np.zeros(2)  # metres from the apex
        self.ant_heading = 0.0  # rad, dome frame
        self.true_path = np.zeros(2)  # metres walked on the ball's surface, integrated in the dome frame
        self.walked = 0.0  # metres
        self.ant_visible = True
        self.distractor_mm: tuple[float, float] | None = None
        # camera
        self.width, self.height = size
        self.calibration = Calibration(apex_px, mm_per_px)
        self.ant_length_mm, self.ant_width_mm, self.blur_px = ant_length_mm, ant_width_mm, blur_px
        rng = np.random.default_rng(seed)
        self._background = [np.clip(200 + rng.normal(0, noise_sd, (self.height, self.width)), 0, 255)
                            .astype(np.uint8) for _ in range(4)]
        self._frame_k = 0

    # -- physics ---------------------------------------------------------------------------------------
    def advance(self, t: float) -> None:
        """Run the rig until time `t` (s) in sub-steps."""
        while self.t < t - 1e-12:
            t_next = min(t, self.t + self.substep_s)
            self.port.deliver(t_next)
            self.firmware.advance(t_next)
            self._physics(t_next - self.t)
            self.t = t_next

    def _physics(self, dt: float) -> None:
        wheel = self.firmware.rate * self.limits.rad_per_step
        drive = (1.0 - self.slip) * self._wheels_to_ball @ wheel
        previous = self.omega
        self.omega = drive + (previous - drive) * math.exp(-dt / self.ball_tau_s)
        mean_omega = 0.5 * (previous + self.omega)
        self.ball_rotation += mean_omega * dt
        # the ant's own walk, from the walker's fixed-rate grid (dt == substep_s except at the end of a call)
        self.walker.dt = dt
        self._k += 1
        dx, dy, _ = self.walker._step(self._k * self.substep_s)
        self.true_path += (dx, dy)
        self.walked += math.hypot(dx, dy)
        r = self.geometry.sphere_radius
        x, y = self.ant_xy
        z = math.sqrt(max(r * r - x * x - y * y, 0.0))
        wx, wy, wz = mean_omega
        carried = np.array([wy * z - wz * y, wz * x - wx * z]) * dt  # (omega x p)_xy
        self.ant_xy += (dx, dy) + carried
        self.walker._heading += wz * dt  # the ball's yaw turns the ant standing on it
        self.ant_heading = self.walker._heading

    # -- camera ----------------------------------------------------------------------------------------
    def render(self) -> np.ndarray:
        """The camera's frame now: uint8 (height, width), dark blurred ant(s) on the bright ball, sensor noise."""
        frame = self._background[self._frame_k % len(self._background)].copy()
        self._frame_k += 1
        if self.ant_visible:
            self._draw_ant(frame, *(self.ant_xy * 1000.0), self.ant_heading)
        if self.distractor_mm is not None:
            self._draw_ant(frame, *self.distractor_mm, 0.5)
        return frame

    def _draw_ant(self, frame: np.ndarray, x_mm: float, y_mm: float, heading: float) -> None:
        cal = self.calibration
        px, py = cal.to_px(x_mm, y_mm)
        half = int(self.ant_length_mm / cal.mm_per_px * 0.6 + 3 * self.blur_px) + 2
        x0, y0 = int(px) - half, int(py) - half
        x1, y1 = x0 + 2 * half, y0 + 2 * half
        if x1 <= 0 or y1 <= 0 or x0 >= self.width or y0 >= self.height:
            return
        mask = np.zeros((2 * half, 2 * half), np.uint8)
        shift = 4
        axes = (int(self.ant_length_mm / cal.mm_per_px / 2 * 16), int(self.ant_width_mm / cal.mm_per_px / 2 * 16))
        centre = (int(round((px - x0) * 16)), int(round((py - y0) * 16)))
        cv2.ellipse(mask, centre, axes, -math.degrees(heading), 0, 360, 255, -1, cv2.LINE_AA, shift)
        alpha = cv2.GaussianBlur(mask.astype(np.float32) * (1.0 / 255.0), (0, 0), self.blur_px)  # 3x faster than u8
        cx0, cy0, cx1, cy1 = max(x0, 0), max(y0, 0), min(x1, self.width), min(y1, self.height)
        roi = frame[cy0:cy1, cx0:cx1]
        a = alpha[cy0 - y0:cy1 - y0, cx0 - x0:cx1 - x0]
        roi[:] = (roi * (1.0 - a) + 40.0 * a).astype(np.uint8)

    def calibration_image(self, disc_diameter_mm: float = 10.0) -> np.ndarray:
        """What the camera sees of a dark calibration disc (`disc_diameter_mm`) stuck on the ball's apex."""
        frame = self._background[0].copy()
        cal = self.calibration
        cx, cy = cal.to_px(0.0, 0.0)
        radius = disc_diameter_mm / cal.mm_per_px / 2
        cv2.circle(frame, (int(round(cx * 16)), int(round(cy * 16))), int(round(radius * 16)), 30, -1,
                   cv2.LINE_AA, 4)
        return frame

    # -- back-ends -------------------------------------------------------------------------------------
    def motor_link(self) -> MotorLink:
        return MotorLink(self.port)

    def camera(self) -> SimulatedCamera:
        return SimulatedCamera(self)


def open_simulated_link(rig: SimulatedRig, **_) -> MotorLink:
    """The `simulated` motor-link back-end: the rig's firmware emulator behind its simulated serial line."""
    return rig.motor_link()


def open_simulated_camera(rig: SimulatedRig, **_) -> SimulatedCamera:
    """The `simulated` camera back-end: the rig's rendered frames."""
    return rig.camera()
