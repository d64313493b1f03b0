"""A trial log as the record of a trial, read as a lab reads it: while it is written, and joined to its frames."""

import threading

import numpy as np
from test_log_trial import frame_row

from antarium.trial_log import TrialLog, read_table


def test_a_log_read_while_its_writer_appends_gives_its_rows_never_an_hdf5_error(tmp_path):
    """A read falling into one of the writer's batches (it takes no file lock) raised OSError ("addr overflow",
    "not already open for SWMR writing") or LogError "truncated file": about 1 read in 20 failed."""
    path = tmp_path / "live.h5"
    log = TrialLog(path, {}, "live", flush_s=0.01)
    done = threading.Event()

    def record():  # a loop of 10 frames and events every 2 ms, handed over every 10 ms
        frame = 0
        while not done.wait(0.002):
            for _ in range(10):
                log.add_frame(frame_row(frame))
                log.add_event(float(frame), "tick", {"frame": frame})
                frame += 1

    recorder = threading.Thread(target=record)
    recorder.start()
    try:
        for _ in range(60):
            frames = read_table(path, "frames")["frame"]
            assert np.array_equal(frames, np.arange(len(frames)))
            events = read_table(path, "events")
            assert all(kind == "tick" for kind in events["kind"])
    finally:
        done.set()
        recorder.join()
        log.close()
    assert log.status()["rows_lost"] == 0 and len(read_table(path, "frames")["frame"]) > 0
