"""Tracking the ant in the top-down camera's frames (Goulard et al. 2021, Fig. 1D).

Threshold and contrast inversion in one pass (the dark ant becomes a white blob), outer contours, candidate blobs
by area, the one nearest the last position; its second moments give the equivalent ellipse: centroid and body
axis in [-90, 90] deg. The 180 deg ambiguity is resolved by continuity and by assuming the ant walks forwards.
`Calibration` maps pixels to mm on the ball's top (dome frame: +x right in the image, +y up in the image).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from antarium.locomotion.servosphere import finite_numbers


@dataclass(frozen=True)
class Calibration:
    """apex_px: the ball's apex in the image (x, y pixels); mm_per_px: scale on the ball's top;
    rotation_deg: the camera's x axis from the dome's +x (counter-clockwise)."""

    apex_px: tuple[float, float]
    mm_per_px: float
    rotation_deg: float = 0.0

    def __post_init__(self) -> None:
        if not finite_numbers(self.apex_px, 2):
            raise ValueError(f"camera calibration apex_px must be 2 finite numbers (x, y pixels), got {self.apex_px!r}")
        if not finite_numbers([self.mm_per_px], 1) or not 1e-4 <= self.mm_per_px <= 10.0:
            raise ValueError(f"camera calibration mm_per_px must be a number in [1e-4, 10], got {self.mm_per_px!r}")
        if not finite_numbers([self.rotation_deg], 1):
            raise ValueError(f"camera calibration rotation_deg must be a finite number (deg), got "
                             f"{self.rotation_deg!r}")

    def to_mm(self, px: float, py: float) -> tuple[float, float]:
        """Image point (pixels) -> (x, y) mm from the apex in the dome frame."""
        u, v = (px - self.apex_px[0]) * self.mm_per_px, (self.apex_px[1] - py) * self.mm_per_px
        c, s = math.cos(math.radians(self.rotation_deg)), math.sin(math.radians(self.rotation_deg))
        return c * u - s * v, s * u + c * v

    def to_px(self, x_mm: float, y_mm: float) -> tuple[float, float]:
        c, s = math.cos(math.radians(self.rotation_deg)), math.sin(math.radians(self.rotation_deg))
        u, v = c * x_mm + s * y_mm, -s * x_mm + c * y_mm
        return self.apex_px[0] + u / self.mm_per_px, self.apex_px[1] - v / self.mm_per_px

    def angle_to_dome(self, image_angle: float) -> float:
        """An image-frame angle (rad, y down) -> dome-frame angle (rad)."""
        return -image_angle + math.radians(self.rotation_deg)


def frame_problem(frame) -> str | None:
    """None for a frame the tracker can use (uint8 (H, W), H, W >= 1), else what it is instead: 'no frame' or
    its dtype and shape."""
    if frame is None:
        return "no frame"
    if not isinstance(frame, np.ndarray):
        return f"a {type(frame).__name__}, not an array"
    if frame.dtype != np.uint8 or frame.ndim != 2 or frame.size == 0:
        return f"{frame.dtype} {frame.shape}"
    return None


def calibrate(image: np.ndarray, disc_diameter_mm: float = 10.0, rotation_deg: float = 0.0) -> Calibration:
    """Calibration from a frame of a dark disc of `disc_diameter_mm` centred on the ball's apex (uint8 (H, W)):
    its centroid is the apex, its area gives the scale. ValueError when no single round dark disc is seen."""
    problem = frame_problem(image)
    if problem is not None:
        raise ValueError(f"calibration image must be a uint8 (H, W) monochrome frame, got {problem}")
    _, binary = cv2.threshold(image, 0, 255, cv2.THRESH_BINARY_INV | cv2.THRESH_OTSU)
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise ValueError("calibration image shows no dark disc; allowed: one dark disc on the bright ball")
    disc = max(contours, key=cv2.contourArea)
    m = cv2.moments(disc)
    area = m["m00"]
    (_, _), r_enclosing = cv2.minEnclosingCircle(disc)
    if area < 50 or area / (math.pi * r_enclosing ** 2) < 0.8:
        raise ValueError(f"calibration blob is not a round disc (area {area:.0f} px, roundness "
                         f"{area / (math.pi * r_enclosing ** 2 + 1e-9):.2f}); allowed: one dark disc, roundness >= 0.8")
    radius_px = math.sqrt(area / math.pi)
    return Calibration((m["m10"] / area, m["m01"] / area), disc_diameter_mm / 2 / radius_px, rotation_deg)


#: the binary image's closing (3x3), for a frame without one clean blob: mends the ant's outline across 1-2 px
#: cracks before its contour is taken
_CLOSE = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))


@dataclass(frozen=True, slots=True)
class Detection:
    """One frame's result. x_mm, y_mm: ant from the apex (dome frame); orientation: body axis (rad, [-pi/2, pi/2]);
    heading: resolved direction (rad, (-pi, pi]); area_mm2; fault: None, "no_ant", "two_blobs", "ant_at_edge"
    (the only blob of the ant's size touches the frame's border: cut, not trusted) or "bad_frame" (no frame, or
    not a uint8 (H, W) image: `frame_problem`);
    heading_confident: the head end was confirmed by the ant's walk since it was last lost (else it is a guess)."""

    x_mm: float = math.nan
    y_mm: float = math.nan
    orientation: float = math.nan
    heading: float = math.nan
    area_mm2: float = math.nan
    fault: str | None = None
    heading_confident: bool = False


class Tracker:
    """Find the ant in uint8 (H, W) frames. threshold: grey level below which a pixel is ant (0..255);
    area_mm2: (min, max) area of a blob that can be the ant; min_walk_mm_s: slowest walk that decides the heading
    (the walk given to `update` is meant to be a mean over ~50-100 ms, not one frame's: see `ServosphereLoop`).
    Hysteresis: the heading flips only when the walk points more than 120 deg away from it, and is confirmed
    (`heading_confident`) when it points within 60 deg; in between, and standing still, the previous choice stays.
    A lost ant (no_ant, two_blobs, ant_at_edge, bad_frame) makes the heading unconfirmed until the walk confirms
    it again; the last position and heading are kept."""

    def __init__(self, calibration: Calibration, threshold: int = 120, area_mm2: tuple[float, float] = (5.0, 60.0),
                 min_walk_mm_s: float = 5.0) -> None:
        if not 1 <= threshold <= 254:
            raise ValueError(f"tracker threshold must be a grey level in [1, 254], got {threshold!r}")
        if not 0 < area_mm2[0] < area_mm2[1]:
            raise ValueError(f"tracker area_mm2 must be (min, max) with 0 < min < max, got {area_mm2!r}")
        self.calibration = calibration
        self.threshold = int(threshold)
        px2 = calibration.mm_per_px ** 2
        self._area_px = (area_mm2[0] / px2, area_mm2[1] / px2)
        self.min_walk_mm_s = float(min_walk_mm_s)
        self.last_px: tuple[float, float] | None = None
        self.heading: float | None = None
        self.heading_confident = False
        self.faults: dict[str, int] = {}

    def update(self, frame: np.ndarray, walk_mm_s: tuple[float, float] | None = None) -> Detection:
        """Track one frame. walk_mm_s: the ant's walking velocity over the ball's surface (mm/s, dome frame) if
        known (the ball's motion added back), used to tell its head from its tail. A frame the tracker cannot use
        (`frame_problem`) is the fault "bad_frame"."""
        if frame_problem(frame) is not None:
            return self._fault("bad_frame")
        _, binary = cv2.threshold(frame, self.threshold, 255, cv2.THRESH_BINARY_INV)
        blobs, at_edge = self._candidates(binary)
        if len(blobs) != 1:  # not one clean blob: mend 1-2 px cracks (noise, a thin glint) and look again
            blobs, at_edge = self._candidates(cv2.morphologyEx(binary, cv2.MORPH_CLOSE, _CLOSE))
        if not blobs:
            return self._fault("ant_at_edge" if at_edge else "no_ant")
        fault = None
        if len(blobs) > 1:  # the paper's choice (nearest the last position) is reported, never trusted
            fault = self._fault("two_blobs").fault
            ref = self.last_px or (frame.shape[1] / 2, frame.shape[0] / 2)
            blobs.sort(key=lambda b: math.hypot(b["m10"] / b["m00"] - ref[0], b["m01"] / b["m00"] - ref[1]))
        m = blobs[0]
        area = m["m00"]
        px, py = m["m10"] / area, m["m01"] / area
        axis = 0.5 * math.atan2(2.0 * m["mu11"], m["mu20"] - m["mu02"])  # image frame, y down
        orientation = math.remainder(self.calibration.angle_to_dome(axis), math.pi)
        x, y = self.calibration.to_mm(px, py)
        area_mm2 = area * self.calibration.mm_per_px ** 2
        if fault is not None:
            return Detection(x, y, orientation, math.nan, area_mm2, fault)
        self.last_px = (px, py)
        heading = self._resolve(orientation, walk_mm_s)
        return Detection(x, y, orientation, heading, area_mm2, heading_confident=self.heading_confident)

    def _candidates(self, binary: np.ndarray) -> tuple[list[dict], bool]:
        """Moments of the blobs of the ant's size clear of the frame's border, and whether one touched it."""
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        lo, hi = self._area_px
        h, w = binary.shape
        blobs = []
        at_edge = False
        for c in contours:  # any contour has moments; a degenerate one (point, line) has area 0
            m = cv2.moments(c)
            if lo <= m["m00"] <= hi:
                x, y, bw, bh = cv2.boundingRect(c)
                if x == 0 or y == 0 or x + bw == w or y + bh == h:
                    at_edge = True  # cut by the frame (or a dark rim): its centroid and axis are not the ant's
                    continue
                blobs.append(m)
        return blobs, at_edge

    def _fault(self, name: str) -> Detection:
        self.faults[name] = self.faults.get(name, 0) + 1
        self.heading_confident = False
        return Detection(fault=name)

    def _resolve(self, orientation: float, walk_mm_s) -> float:
        """Heading from the body axis: the end nearer the previous heading, flipped if the ant clearly walks
        backwards (more than 120 deg off), confirmed if it clearly walks forwards (within 60 deg)."""
        heading = orientation
        if self.heading is not None and abs(math.remainder(heading - self.heading, math.tau)) > math.pi / 2:
            heading += math.pi
        if walk_mm_s is not None and math.hypot(*walk_mm_s) >= self.min_walk_mm_s:
            c = math.cos(heading - math.atan2(walk_mm_s[1], walk_mm_s[0]))
            if c < -0.5:
                heading += math.pi
            if abs(c) > 0.5:
                self.heading_confident = True
        self.heading = math.remainder(heading, math.tau)
        return self.heading
