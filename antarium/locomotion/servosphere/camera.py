"""The `opencv` camera back-end: any camera OpenCV's VideoCapture opens (a Basler through its GenICam/V4L2 driver),
frames converted to monochrome uint8. Timestamps are the loop clock's when the frame was read."""

from __future__ import annotations

import cv2
import numpy as np

from antarium.core.clock import Clock, MonotonicClock


class OpenCVCamera:
    def __init__(self, index: int | str = 0, frame_rate: float = 700.0, clock: Clock | None = None, **_) -> None:
        self._cap = cv2.VideoCapture(index)
        if not self._cap.isOpened():
            raise RuntimeError(f"cannot open camera {index!r} with OpenCV; allowed: a device index or a video URL")
        self._cap.set(cv2.CAP_PROP_FPS, frame_rate)
        self.frame_rate = float(self._cap.get(cv2.CAP_PROP_FPS) or frame_rate)
        self.clock = clock or MonotonicClock()

    def grab(self) -> tuple[float, np.ndarray]:
        ok, frame = self._cap.read()
        if not ok:
            raise RuntimeError("the camera returned no frame")
        if frame.ndim == 3:
            frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        return self.clock.now(), frame

    def close(self) -> None:
        self._cap.release()
