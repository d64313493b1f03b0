"""MBI5040-style LED driver model: 16-bit scrambled PWM at 20 MHz, open/short detection.

Scrambled PWM: the 65,536-clock PWM period is cut into 32 segments of 2,048 clocks; an LED at value v is on for
v div 32 clocks at the start of every segment, plus one clock in each of the first v mod 32 segments. From v >= 32
every segment carries light, so the flicker is at 20 MHz / 2,048 = 9,766 Hz; below, the LED lights in only
v segments of the period and flickers at 20 MHz / 65,536 = 305 Hz (Kocsi et al. 2020, Flicker Considerations).
"""

from __future__ import annotations

import numpy as np

PWM_CLOCK_HZ = 20_000_000
PWM_STEPS = 65_536
SEGMENTS = 32
SEGMENT_CLOCKS = PWM_STEPS // SEGMENTS  # 2,048
PWM_PERIOD_S = PWM_STEPS / PWM_CLOCK_HZ  # 3.28 ms
BASE_FLICKER_HZ = PWM_CLOCK_HZ / PWM_STEPS          # 305.2 Hz
SCRAMBLED_FLICKER_HZ = PWM_CLOCK_HZ / SEGMENT_CLOCKS  # 9,765.6 Hz
SCRAMBLE_THRESHOLD = SEGMENTS  # value from which every segment carries light

LED_CURRENT_A = 0.020   # one LED (one pixel) at full scale
CHIP_CURRENT_A = 0.030  # quiescent current of one driver chip

FAULT_NONE = 0
FAULT_OPEN = 1
FAULT_SHORT = 2
FAULT_NAMES = {FAULT_OPEN: "open", FAULT_SHORT: "short"}


def pwm_waveform(value: int) -> np.ndarray:
    """On/off state of an LED at `value` (0..65535) for each of the 65,536 clocks of one PWM period, bool."""
    if not 0 <= int(value) < PWM_STEPS:
        raise ValueError(f"PWM value {value} out of range: allowed 0..{PWM_STEPS - 1}")
    base, extra = divmod(int(value), SEGMENTS)
    on_clocks = base + (np.arange(SEGMENTS) < extra)  # per segment
    return (np.arange(SEGMENT_CLOCKS)[None, :] < on_clocks[:, None]).ravel()


def flicker_frequency_hz(values) -> np.ndarray:
    """Effective flicker frequency of LEDs at `values` (uint16 array): 0 for dark LEDs, 305 Hz below 32,
    9,766 Hz from 32 on."""
    v = np.asarray(values)
    return np.where(v == 0, 0.0, np.where(v >= SCRAMBLE_THRESHOLD, SCRAMBLED_FLICKER_HZ, BASE_FLICKER_HZ))


def emitted(values: np.ndarray, faults: np.ndarray) -> np.ndarray:
    """Light actually emitted: an open or shorted LED stays dark (no current through its junction)."""
    return np.where(faults == FAULT_NONE, values, 0).astype(values.dtype)


def detected_faults(values: np.ndarray, faults: np.ndarray) -> np.ndarray:
    """Faults the driver reports: its open/short detection works only on channels that are being driven."""
    return np.where(values > 0, faults, FAULT_NONE).astype(np.uint8)


def supply_current_a(values: np.ndarray, n_chips: int) -> np.ndarray:
    """LED-supply current of each row of `values` (n, 740) uint16: 20 mA per LED at full scale + 30 mA per chip.

    A shorted LED still draws its drive current; an open one draws none.
    """
    return values.sum(axis=-1, dtype=np.float64) * (LED_CURRENT_A / (PWM_STEPS - 1)) + n_chips * CHIP_CURRENT_A
