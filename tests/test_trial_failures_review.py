"""Failures a lab meets during a trial, injected at the lowest seam (the file system): a disk that fills, a log folder
removed, and what the lab then finds in the folder, the status and the error."""

import shutil
import subprocess
import sys
import textwrap
from multiprocessing import Pipe

import numpy as np
from conftest import wait_for
from test_log_trial import frame_row

from antarium.config import resolve
from antarium.server import Server
from antarium.trial_log import TrialLog, _create, _text_dtypes, open_log, read_table

_FULL_WITH_TWO_TABLES = textwrap.dedent("""
    import resource, signal, sys
    import numpy as np
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))  # inherited by the writer: the 'disk' fills
    from antarium.trial_log import FRAME_DTYPE, SAMPLE_DTYPE, TrialLog
    frame = np.zeros((), FRAME_DTYPE).item()
    sample = np.zeros((), SAMPLE_DTYPE).item()
    log = TrialLog(sys.argv[1], {}, "full", flush_s=0.05)
    for i in range(400):
        for k in range(100):
            log.add_frame((i * 100 + k, *frame[1:]))
        log._append("locomotion", (float(i), i, *sample[2:]))
        log.flush(wait=True)
        if log.status()["error"]:
            break
    log.close()
    print(log.error)
""")


def test_a_disk_that_fills_while_two_tables_are_written_is_reported_not_a_writer_crash(tmp_path):
    """A batch of frames and ball samples on a full disk: the dataset closed when the next table was taken failed its
    write inside h5py's dealloc (printed only) and HDF5 then crashed the writer (SIGSEGV) closing the file; the error
    became "writer died (exit -11): ...; a new writer could not take the file over", not the disk's error."""
    path = tmp_path / "full.h5"
    out = subprocess.run([sys.executable, "-c", _FULL_WITH_TWO_TABLES, str(path)], capture_output=True, text=True,
                         timeout=90)
    assert out.returncode == 0, out.stderr
    error = out.stdout.strip()
    assert error.startswith(f"writing trial log {str(path)!r} failed: ") and "File too large" in error
    assert "died" not in error
    with open_log(path) as f:  # every batch written before the disk filled
        frames, samples = f["frames"][:], f["locomotion"][:]
    assert len(frames) > 0 and np.array_equal(frames["frame"], np.arange(len(frames)))
    assert np.array_equal(samples["seq"], np.arange(len(samples)))


def test_a_log_whose_folder_was_removed_says_no_file_is_left_at_its_path(tmp_path):
    """The error said "what was written before stays ... h5clear -s PATH" of a file that no longer exists."""
    folder = tmp_path / "trials"
    folder.mkdir()
    path = folder / "gone.h5"
    log = TrialLog(path, {}, "gone", flush_s=1.0)
    try:
        log.add_frame(frame_row(0))
        log.flush(wait=True)
        assert log.status()["rows_written"]["frames"] == 1
        shutil.rmtree(folder)
        log.add_frame(frame_row(1))
        log.flush(wait=True)
        status = log.status()
    finally:
        log.close()
    assert status["rows_lost"] == 1
    assert status["error"].startswith(f"writing trial log {str(path)!r} failed: ")
    assert status["error"].endswith("no file is at that path any more (it, or its folder, was removed or moved): the "
                                    "rows written before went with it")


def test_a_file_that_cannot_be_opened_for_a_batch_is_said_to_stay_readable(tmp_path):
    """The open failed, nothing was written: the file is closed and clean, not "marked open for writing"."""
    path = tmp_path / "moved.h5"
    log = TrialLog(path, {}, "moved", flush_s=1.0)
    try:
        log.add_frame(frame_row(0))
        log.flush(wait=True)
        path.rename(tmp_path / "elsewhere.h5")
        path.mkdir()  # what stands at its path now is no file HDF5 opens
        log.add_frame(frame_row(1))
        log.flush(wait=True)
        error = log.status()["error"]
    finally:
        log.close()
    assert error.endswith("nothing was written to it: it stays as the batches before left it, closed and readable")
    assert len(read_table(tmp_path / "elsewhere.h5", "frames")["frame"]) == 1


_FULL_AT_START = textwrap.dedent("""
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (40, 40))  # inherited by the writer: not a superblock fits
    from antarium.trial_log import LogError, TrialLog
    try:
        TrialLog(sys.argv[1], {}, "full")
    except LogError as exc:
        print(exc)
""")


def test_a_disk_full_at_the_start_of_a_trial_leaves_no_empty_file(tmp_path):
    """The file was made but its first bytes did not fit: an empty .h5 (no reader opens it) stayed in the folder."""
    path = tmp_path / "full.h5"
    out = subprocess.run([sys.executable, "-c", _FULL_AT_START, str(path)], capture_output=True, text=True, timeout=90)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith(f"cannot create trial log {str(path)!r}: ") and "File too large" in out.stdout
    assert list(tmp_path.iterdir()) == []


def test_a_writer_refused_an_existing_file_leaves_it_as_it_was(tmp_path):
    """Whoever made the file between the check and the writer's create: it is theirs and stays."""
    path = tmp_path / "theirs.h5"
    path.write_bytes(b"their data")
    ours, theirs = Pipe()
    _create(theirs, str(path), {}, _text_dtypes())
    kind, reason = ours.recv()
    assert kind == "error" and "File exists" in reason
    assert path.read_bytes() == b"their data"


def test_the_log_folder_removed_between_trials_is_made_again_at_the_next_trial_start(tmp_path):
    """A clean-up of the trials folder while the server runs made every later trial_start fail ("No such file or
    directory") until the server was restarted; a `folder` given to trial_start was made, the [log] dir was not."""
    logs = tmp_path / "logs"
    config = resolve({"rig": {"name": "again"}, "bus": {"enabled": False}, "log": {"dir": str(logs), "flush_s": 0.1},
                      "loop": {"rate_hz": 100.0}, "locomotion": {"source": "scripted", "rate_hz": 100.0}})
    server = Server(config, renderer_factory=None, link=False, echo=lambda line: None).start_thread()
    try:
        assert wait_for(lambda: server.loop.frame > 2, 30.0)
        shutil.rmtree(logs)
        path = server.command("trial_start", {"name": "after", "metadata": {}})["path"]
        frame = server.loop.frame
        assert wait_for(lambda: server.loop.frame > frame + 5, 30.0)
        stopped = server.command("trial_stop")
    finally:
        server.stop()
    assert stopped["error"] is None and stopped["rows_written"]["frames"] > 0
    assert str(logs) == str(tmp_path / "logs") and path.startswith(str(logs))
    assert len(read_table(path, "frames")["frame"]) == stopped["rows_written"]["frames"]
