"""FicTrac live stream (UDP and TCP on loopback) and .dat replay as locomotion sources."""

import re
import socket
import threading
import time

import pytest
from conftest import wait_for

from antarium.core.clock import SimulatedClock
from antarium.locomotion import open_source
from antarium.locomotion.fictrac.protocol import FicTracFrame, format_line, to_sample


def frame(i: int, t_ms: float = 0.0, dy: float = 0.01) -> FicTracFrame:
    values = [0.0] * 25
    values[0], values[22] = i, i
    values[6] = dy  # d_rot_lab_y
    values[21] = t_ms
    values[23] = 10.0
    return FicTracFrame(*values)




def test_udp_stream_with_malformed_lines_and_a_gap():
    with open_source("fictrac", transport="udp", host="127.0.0.1", port=0) as src:
        assert src.status()["connected"] is False  # nothing yet
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        lines = [format_line(frame(i)) for i in (1, 2, 3)] + ["FT, garbage", "", format_line(frame(6))]
        for line in lines:
            tx.sendto((line + "\n").encode(), src.address)
        tx.sendto((format_line(frame(7)) + "\n" + format_line(frame(8)) + "\n").encode(), src.address)  # 2 in one
        tx.close()
        got = []
        assert wait_for(lambda: len(got.extend(src.read()) or got) >= 6)
        status = src.status()
    assert [s.seq for s in got] == [1, 2, 3, 6, 7, 8]
    assert got[0].rotation == (0.0, -0.01, -0.0)
    assert status["connected"] and status["malformed"] == 1 and status["frames"] == 6
    assert status["gaps"] == 1 and status["lost_frames"] == 2
    assert "25 comma-separated values" in status["last_error"]


def test_connected_goes_false_when_frames_stop():
    clock = SimulatedClock(100.0)
    with open_source("fictrac", port=0, clock=clock, timeout_s=0.5) as src:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            tx.sendto(format_line(frame(1)).encode(), src.address)
        assert wait_for(lambda: src.status()["frames"] == 1)
        assert src.status()["connected"]
        clock.advance(0.6)
        assert not src.status()["connected"]


def test_tcp_client_reassembles_lines_and_reconnects():
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]

    def fictrac(first: int) -> None:
        conn, _ = server.accept()
        with conn:
            data = "".join(format_line(frame(i)) + "\n" for i in range(first, first + 5)).encode()
            for k in range(0, len(data), 37):  # lines split across TCP segments
                conn.sendall(data[k: k + 37])
                time.sleep(0.001)

    with open_source("fictrac", transport="tcp", port=port, retry_s=0.05) as src:
        t = threading.Thread(target=fictrac, args=(1,))
        t.start()
        got = []
        assert wait_for(lambda: len(got.extend(src.read()) or got) >= 5)
        t.join()
        # FicTrac restarts: the source connects again by itself; the frame counter restarting is a reset
        t = threading.Thread(target=fictrac, args=(1,))
        t.start()
        assert wait_for(lambda: len(got.extend(src.read()) or got) >= 10)
        t.join()
        status = src.status()
    server.close()
    assert [s.seq for s in got] == [1, 2, 3, 4, 5] * 2
    assert status["malformed"] == 0 and status["resets"] == 1


def test_tcp_client_reads_fictrac_2_0_lines():
    """FicTrac 2.0's socket recorder (TCP) writes its 23-value log lines, no prefix: all read, none malformed."""
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def fictrac() -> None:
        conn, _ = server.accept()
        with conn:
            conn.sendall("".join(", ".join(format_line(frame(i), prefix=False).split(", ")[:23]) + "\n"
                                 for i in range(1, 6)).encode())

    with open_source("fictrac", transport="tcp", port=server.getsockname()[1], retry_s=0.05) as src:
        t = threading.Thread(target=fictrac)
        t.start()
        got = []
        assert wait_for(lambda: len(got.extend(src.read()) or got) >= 5)
        t.join()
        status = src.status()
    server.close()
    assert [s.seq for s in got] == [1, 2, 3, 4, 5]
    assert [s.rotation for s in got] == [to_sample(frame(i), 0.0).rotation for i in range(1, 6)]
    assert status["malformed"] == 0


def test_replay_is_paced_by_the_log_timestamps(tmp_path):
    path = tmp_path / "run.dat"
    lines = [format_line(frame(i, t_ms=1000.0 + 10.0 * i), prefix=False) for i in range(1, 101)]
    lines.insert(50, "1, 2, not a line")
    path.write_text("\n".join(lines) + "\n")
    clock = SimulatedClock(5.0)
    with open_source("fictrac-replay", path=path, clock=clock, speed=2.0) as src:
        first = src.read()
        assert [s.seq for s in first] == [1]
        clock.advance(0.1)  # 0.2 s of log time at speed 2
        batch = src.read()
        assert [s.seq for s in batch] == list(range(2, 22))
        assert batch[-1].t == pytest.approx(5.1)
        clock.advance(10.0)
        rest = src.read()
        status = src.status()
    assert len(rest) == 79 and src.finished
    assert status["malformed"] == 1 and status["frames"] == 100 and status["replayed"] == 100


def test_bad_arguments_are_rejected_clearly(tmp_path):
    with pytest.raises(ValueError, match="transport must be one of udp, tcp"):
        open_source("fictrac", transport="serial")
    with pytest.raises(ValueError, match="port must be"):
        open_source("fictrac", port=70000)
    with pytest.raises(ValueError, match=r"speed must be a finite number in \(0, 1000\]"):
        open_source("fictrac-replay", path=tmp_path / "x.dat", speed=0)
    with pytest.raises(FileNotFoundError, match="not found"):
        open_source("fictrac-replay", path=tmp_path / "x.dat").start()


@pytest.mark.parametrize("source", ["fictrac", "fictrac-replay"])
@pytest.mark.parametrize("value", [0, -0.5, float("nan"), float("inf"), "0.5"])
def test_max_match_error_must_be_a_positive_number(tmp_path, source, value):
    path = {"path": tmp_path / "x.dat"} if source == "fictrac-replay" else {}
    with pytest.raises(ValueError, match=r"^FicTrac max_match_error must be a finite number > 0 \(FicTrac's match "
                                         rf"error; leave it out for quality 1\), got {value!r}$"):
        open_source(source, max_match_error=value, **path)


@pytest.mark.parametrize("source", ["replay", "fictrac-replay"])
@pytest.mark.parametrize("value", [0, -1.0, float("nan"), float("inf"), 1000.5, "2", True])
def test_replay_speed_must_be_a_finite_number_up_to_1000(tmp_path, source, value):
    """Both replays check speed with one function (inf used to play the whole FicTrac log at start(), "2" gave a
    bare TypeError): one line naming the source, the value and the range."""
    path = tmp_path / "x.csv"
    path.write_text("t,seq,rx,ry,rz,t_device,quality\n0.0,1,0,0,0,0.0,1\n")
    with pytest.raises(ValueError, match=rf"^{source} speed must be a finite number in \(0, 1000\] \(1 = real "
                                         rf"time\), got {re.escape(repr(value))}$"):
        open_source(source, path=path, speed=value)
    assert open_source(source, path=path, speed=1000).speed == 1000.0


@pytest.mark.parametrize("value", [0, float("nan"), "1"])
def test_timeout_must_be_a_positive_number(value):
    with pytest.raises(ValueError, match=r"^FicTrac timeout_s must be a finite number > 0 \(s without frames "
                                         rf"before it is not connected\), got {value!r}$"):
        open_source("fictrac", timeout_s=value)


def test_a_frame_that_does_not_convert_is_counted_and_the_reader_goes_on(monkeypatch):
    from antarium.locomotion.fictrac import source

    def to_sample(frame, t, max_match_error=None):
        if frame.frame == 2:
            raise ZeroDivisionError("float division by zero")
        return real(frame, t, max_match_error)

    real = source.to_sample
    monkeypatch.setattr(source, "to_sample", to_sample)
    with open_source("fictrac", port=0, max_match_error=0.5) as src:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for i in (1, 2, 3):
                tx.sendto((format_line(frame(i)) + "\n").encode(), src.address)
        assert wait_for(lambda: src.status()["lines"] == 3)
        status = src.status()
        assert src._thread.is_alive() and [s.seq for s in src.read()] == [1, 3]
    assert status["frames"] == 2 and status["malformed"] == 1
    assert status["last_error"] == "FicTrac frame 2 does not convert to a sample: float division by zero"


@pytest.mark.parametrize("retry_s", [-1.0, 0.0, "x"])
def test_a_retry_time_the_tcp_reader_cannot_use_is_refused_in_one_line(retry_s):
    """-1 and "x" ended the reader thread with a traceback (the source then waited for ever, last_error empty);
    0 spun a core on `connect` (review 2026-11-27)."""
    with pytest.raises(ValueError, match=r"FicTrac retry_s must be a finite number > 0 \(s between tries"):
        open_source("fictrac", transport="tcp", port=1, retry_s=retry_s)
