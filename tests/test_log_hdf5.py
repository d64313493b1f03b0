"""Trial logs open in any HDF5 >= 1.10 (MATLAB's bundled library included): format versions checked byte by byte
against the HDF5 file-format specification, the superblock's status flags clear after a close and after a
SIGKILL between batches, and Debian's HDF5 1.10 tools (`hdf5-tools`, when installed) reading the files."""

import os
import shutil
import signal
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest

from antarium.core.clock import SimulatedClock
from antarium.locomotion import open_source
from antarium.server.frame_loop import FrameLoop
from antarium.trial_log import TrialLog

SIGNATURE = b"\x89HDF\r\n\x1a\n"
WRITE_ACCESS, SWMR_WRITE_ACCESS = 0x01, 0x04  # superblock v3 "file consistency flags" (bits 0 and 2)

#: the newest version of each object-header message that HDF5 1.10 decodes (file-format spec 3.0);
#: for the datatype message the version is the high nibble of its first byte
MAX_VERSION_1_10 = {0x01: 2, 0x02: 0, 0x03: 3, 0x05: 3, 0x06: 1, 0x08: 4, 0x0A: 0, 0x0B: 2, 0x0C: 3, 0x12: 1, 0x15: 0}
CONTINUATION = 0x10


def superblock(path) -> tuple[int, int]:
    """(superblock version, file consistency flags) of an HDF5 file without a user block."""
    head = open(path, "rb").read(12)
    assert head[:8] == SIGNATURE, "not an HDF5 file (or one with a user block)"
    version = head[8]
    assert version in (2, 3), f"superblock version {version} has no one-byte flags field"
    return version, head[11]


def message_versions(path) -> list[tuple[int, int]]:
    """(message type, version) of every message in every version-2 object header (and its continuation
    chunks) of a file with 8-byte offsets and lengths, following the file-format specification."""
    data = open(path, "rb").read()
    found = []

    def messages(start: int, end: int, track_order: bool) -> None:
        pos = start
        while pos + 4 <= end:
            mtype, size = data[pos], int.from_bytes(data[pos + 1:pos + 3], "little")
            body = pos + 4 + (2 if track_order else 0)
            if size == 0 and mtype == 0:  # NIL message or gap
                pos = body
                continue
            if mtype == CONTINUATION:
                address = int.from_bytes(data[body:body + 8], "little")
                length = int.from_bytes(data[body + 8:body + 16], "little")
                assert data[address:address + 4] == b"OCHK"
                messages(address + 4, address + length - 4, track_order)
            elif mtype in MAX_VERSION_1_10:
                first = data[body]
                found.append((mtype, first >> 4 if mtype == 0x03 else first))
            pos = body + size

    at = data.find(b"OHDR")
    while at >= 0:
        version, flags = data[at + 4], data[at + 5]
        if version == 2:
            pos = at + 6 + (16 if flags & 0x20 else 0) + (4 if flags & 0x10 else 0)
            width = 1 << (flags & 0x03)
            chunk = int.from_bytes(data[pos:pos + width], "little")
            pos += width
            messages(pos, pos + chunk, bool(flags & 0x04))
        at = data.find(b"OHDR", at + 4)
    return found


def too_new_for_1_10(path) -> list[tuple[int, int]]:
    return [(t, v) for t, v in message_versions(path) if v > MAX_VERSION_1_10[t]]


@pytest.fixture(scope="module")
def closed_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("logs") / "closed.h5"
    clock = SimulatedClock()
    with TrialLog(path, {"rig": {"name": "r"}}, "closed", {"ant": 3}) as log:
        loop = FrameLoop(clock=clock, source=open_source("scripted", clock=clock), log=log)
        loop.run(until=0.5)
        loop.rotate_scene(np.pi / 2)
        log.add_command(clock.now(), "rotate_scene", {"deg": 90}, {"ok": True}, True)
        log.add_scene(clock.now(), "habitat", "")
    return path


def test_closed_log_is_in_the_1_10_format_with_clear_status_flags(closed_log):
    assert superblock(closed_log) == (3, 0)  # version 3: the oldest with SWMR; no "open for write" mark
    versions = message_versions(closed_log)
    kinds = {t for t, _ in versions}
    assert {0x01, 0x03, 0x05, 0x08, 0x06, 0x0C} <= kinds  # dataspace, datatype, fill, layout, link, attribute
    assert too_new_for_1_10(closed_log) == []
    with h5py.File(closed_log, "r") as f:  # a plain (non-SWMR) read, as MATLAB's h5read does
        assert len(f["frames"]) == 95 and f["commands"][0]["name"] == b"rotate_scene"


def test_the_byte_check_catches_a_file_too_new_for_1_10(tmp_path):
    """The check has teeth: h5py's default 'latest' format, with an HDF5 2.x library, is unreadable by 1.10."""
    if h5py.version.hdf5_version_tuple < (2, 0, 0):
        pytest.skip(f"HDF5 {h5py.version.hdf5_version}: 'latest' is still readable by 1.10")
    with h5py.File(tmp_path / "latest.h5", "w", libver="latest") as f:
        f.create_dataset("t", data=np.zeros(3, dtype=[("a", "<f8"), ("b", "u1")]))
    assert (0x03, 5) in too_new_for_1_10(tmp_path / "latest.h5")


_IDLE_WRITER = textwrap.dedent("""
    import sys, time
    from antarium.core.clock import SimulatedClock
    from antarium.server.frame_loop import FrameLoop
    from antarium.locomotion import open_source
    from antarium.trial_log import TrialLog
    clock = SimulatedClock()
    log = TrialLog(sys.argv[1], {"rig": {"name": "k"}}, "killed", flush_s=1.0)
    loop = FrameLoop(clock=clock, source=open_source("scripted", clock=clock), log=log)
    loop.run(until=1.0)
    log.flush(wait=True)
    print(log.status()["rows_written"]["frames"], flush=True)
    time.sleep(60)
""")


def test_log_killed_between_batches_opens_without_swmr_or_h5clear(tmp_path):
    path = tmp_path / "k.h5"
    proc = subprocess.Popen([sys.executable, "-c", _IDLE_WRITER, str(path)], stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        written = int(proc.stdout.readline())
    finally:  # the server and its writer killed at once, after a batch was written
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)
    assert written == 190
    assert superblock(path) == (3, 0)
    with h5py.File(path, "r") as f:  # no swmr=True needed
        assert len(f["frames"]) == 190 and np.all(np.diff(f["frames"]["frame"]) == 1)
    if shutil.which("h5dump"):
        out = subprocess.run(["h5dump", "-d", "/frames", "-c", "1", str(path)], capture_output=True, text=True)
        assert out.returncode == 0 and "( 190 )" in out.stdout, out.stderr


def _h5dump_version() -> str:
    out = subprocess.run(["h5dump", "--version"], capture_output=True, text=True)
    return out.stdout.split()[-1]


@pytest.mark.skipif(not shutil.which("h5dump"), reason="HDF5 command-line tools not installed (apt install hdf5-tools)")
def test_hdf5_tools_read_every_table_and_attribute(closed_log):
    for table, expect in (("frames", "( 95 )"), ("locomotion", "H5T_IEEE_F32LE \"quality\""),
                          ("events", "scene_rotated"), ("commands", "rotate_scene"), ("scenes", "habitat")):
        out = subprocess.run(["h5dump", "-d", f"/{table}", str(closed_log)], capture_output=True, text=True)
        assert out.returncode == 0, (table, _h5dump_version(), out.stderr)
        assert expect in out.stdout, table
    out = subprocess.run(["h5dump", "-a", "/metadata", str(closed_log)], capture_output=True, text=True)
    assert out.returncode == 0 and '"ant": 3' in out.stdout


def test_a_reader_holding_the_file_open_never_stops_the_recording(tmp_path):
    path = tmp_path / "held.h5"
    clock = SimulatedClock()
    with TrialLog(path, {}, "held") as log:
        loop = FrameLoop(clock=clock, source=open_source("scripted", clock=clock), log=log)
        loop.run(until=0.5)
        log.flush(wait=True)
        with h5py.File(path, "r") as reader:  # a plain reader (HDF5 file lock taken) between two batches
            assert len(reader["frames"]) == 95
            loop.run(until=1.0)
            log.flush(wait=True)
            assert log.status()["error"] is None and log.status()["rows_written"]["frames"] == 190
    with h5py.File(path, "r") as f:
        assert len(f["frames"]) == 190
