"""The reference firmware's behaviour in Python (docs/servosphere.md, "Reference firmware").

The microcontroller decodes host messages with the same `protocol` code, ramps each stepper's rate toward its
target at the acceleration limit, counts the steps it makes, answers every command with a `Status`, stops all
rotors when a driver signals a stall (latched fault) and when no valid command came within `watchdog_s`.
Time is whatever the caller passes (seconds): the simulated rig passes its clock's.
"""

from __future__ import annotations

import numpy as np

from antarium.locomotion.servosphere import protocol as p
from antarium.locomotion.servosphere.kinematics import StepperLimits

_STALL_BITS = (p.FAULT_STALL_1, p.FAULT_STALL_2, p.FAULT_STALL_3)


class FirmwareEmulator:
    """Three steppers behind the wire protocol. `stalled[i]` = True makes rotor i's shaft stop (a jammed wheel):
    its driver's stall flag raises FAULT_STALL_i and the firmware ramps every rotor to 0."""

    def __init__(self, limits: StepperLimits | None = None, watchdog_s: float = 0.05, t0: float = 0.0) -> None:
        self.limits = limits or StepperLimits()
        self.watchdog_s = float(watchdog_s)
        self.t = float(t0)
        self.rate = np.zeros(3)  # steps/s the shafts turn at now
        self.target = np.zeros(3)
        self.position = np.zeros(3)  # steps made (float; the count reported is its floor)
        self.faults = 0
        self.stalled = [False, False, False]
        self.decoder = p.Decoder()
        self._bad_seen = 0
        self._last_command = float(t0)

    def advance(self, t: float) -> None:
        """Run the steppers until time `t` (s): ramp at max_accel, integrate position exactly; the watchdog stops
        them from the moment it expires (`watchdog_s` after the last valid command)."""
        if t <= self.t:
            return
        expires = self._last_command + self.watchdog_s
        if self.t < expires < t:
            self._run(expires)
        if t > expires and (self.target.any() or self.rate.any()):
            self.faults |= p.FAULT_WATCHDOG
            self.target[:] = 0.0
        self._run(t)

    def _run(self, t: float) -> None:
        """The steppers from `self.t` to `t` (s) toward the current targets."""
        dt = t - self.t
        for i, bit in enumerate(_STALL_BITS):
            if self.stalled[i] and (self.rate[i] or self.target[i]):
                self.faults |= bit
                self.rate[i] = 0.0
        if self.faults & (p.FAULT_STALL_1 | p.FAULT_STALL_2 | p.FAULT_STALL_3):
            self.target[:] = 0.0
        a = self.limits.max_accel
        diff = self.target - self.rate
        t_ramp = np.minimum(dt, np.abs(diff) / a)
        acc = np.sign(diff) * a
        self.position += self.rate * t_ramp + 0.5 * acc * t_ramp ** 2 + self.target * (dt - t_ramp)
        self.rate = np.where(t_ramp < dt, self.target, self.rate + acc * t_ramp)
        self.t = t

    def receive(self, data: bytes, t: float) -> bytes:
        """Bytes from the host arriving at time `t`; returns the reply bytes."""
        self.advance(t)
        out = b""
        messages = self.decoder.feed(data)
        bad = sum(self.decoder.errors.values())
        if bad != self._bad_seen:  # reported in this chunk's replies already
            self._bad_seen = bad
            self.faults |= p.FAULT_BAD_MESSAGE
        for msg in messages:
            self._last_command = t
            if isinstance(msg, p.SetRates):
                if not self.faults & (p.FAULT_STALL_1 | p.FAULT_STALL_2 | p.FAULT_STALL_3):
                    lim = self.limits.max_rate
                    self.target = np.clip([msg.rate1, msg.rate2, msg.rate3], -lim, lim).astype(float)
            elif isinstance(msg, p.Stop):
                self.target[:] = 0.0
            elif isinstance(msg, p.ClearFaults):
                self.faults = 0
            else:  # a Status sent to the firmware: not a command
                self.faults |= p.FAULT_BAD_MESSAGE
                continue
            out += p.encode(self.status(msg.seq))
        return out

    def status(self, seq: int) -> p.Status:
        steps = [((int(np.floor(x)) + 2 ** 31) % 2 ** 32) - 2 ** 31 for x in self.position]
        return p.Status(seq, int(round(self.t * 1e6)) % 2 ** 32, *steps, self.faults)
