"""The `opencv` camera back-end: any camera OpenCV's VideoCapture opens (a Basler through its GenICam/V4L2 driver),
frames converted to monochrome uint8 (BGR ones to grey; other formats are handed on for the tracker to refuse).
Timestamps are the loop clock's when the frame was read; a read that gives no frame (a dropped frame, the end of
a video) is (t, None), which the loop counts as a `bad_frame` fault."""

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

    def grab(self) -> tuple[float, np.ndarray | None]:
        ok, frame = self._cap.read()
        if not ok:
            return self.clock.now(), None
        if frame.ndim == 3 and frame.shape[2] == 3:
            frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        return self.clock.now(), frame

    def close(self) -> None:
        self._cap.release()
