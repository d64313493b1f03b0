"""The USB driver through the real pyusb code path, against the emulated device (a pyusb backend)."""

import array
import time

import numpy as np
import pytest
import usb.core
import usb.util
from conftest import wait_for

from antarium.locomotion import BallSample, open_source
from antarium.locomotion.trackball import protocol as P
from antarium.locomotion.trackball.config import TrackballConfig
from antarium.locomotion.trackball.driver import UsbTrackball
from antarium.locomotion.trackball.emulator import EmulatedTrackball, constant, segments

R = 0.05




def collect(src, n, timeout_s=10.0):
    out = []
    assert wait_for(lambda: len(out.extend(src.read()) or out) >= n, timeout_s)
    return out


def test_pyusb_finds_the_emulated_device_and_reads_its_descriptors():
    backend = EmulatedTrackball(realtime=False)
    dev = usb.core.find(backend=backend, idVendor=0x1209, idProduct=0x0001)
    assert dev is not None and usb.core.find(backend=backend, idVendor=0x1234) is None
    dev.set_configuration()
    intf = dev.get_active_configuration()[(0, 0)]
    assert intf.bInterfaceClass == P.INTERFACE_CLASS_VENDOR
    ep = usb.util.find_descriptor(intf, custom_match=lambda e: usb.util.endpoint_direction(e.bEndpointAddress)
                                  == usb.util.ENDPOINT_IN)
    assert ep.bEndpointAddress == P.ENDPOINT_IN
    assert usb.util.endpoint_type(ep.bmAttributes) == usb.util.ENDPOINT_TYPE_INTR
    assert ep.wMaxPacketSize == P.REPORT_SIZE
    # control requests: set rate and resolution, start, read reports, info reflects it
    dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_SET_RATE, 500, 0)
    dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_SET_RESOLUTION, 2400, 0)
    with pytest.raises(usb.core.USBTimeoutError):  # not started: nothing to read
        dev.read(P.ENDPOINT_IN, 64, 10)
    dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_START, 0, 0)
    info = P.decode_info(dev.ctrl_transfer(P.REQUEST_TYPE_IN, P.REQ_GET_INFO, 0, 0, P.INFO.size))
    assert info == P.Info(P.PROTOCOL_VERSION, 2, 500, 2400, True)
    reports = [P.decode_report(dev.read(P.ENDPOINT_IN, 64, 10)) for _ in range(3)]
    assert [r.seq for r in reports] == [0, 1, 2]
    assert [r.t_us for r in reports] == [2000, 4000, 6000]
    usb.util.dispose_resources(dev)


@pytest.mark.parametrize("request_, value", [(0x7F, 0), (P.REQ_SET_RATE, 0), (P.REQ_SET_RATE, 1001),
                                              (P.REQ_SET_RESOLUTION, 50)])
def test_bad_control_requests_stall(request_, value):
    dev = usb.core.find(backend=EmulatedTrackball(realtime=False))
    with pytest.raises(usb.core.USBError, match="stalled"):
        dev.ctrl_transfer(P.REQUEST_TYPE_OUT, request_, value, 0)


def test_rotation_integrates_to_the_scripted_motion():
    omega = np.array([0.3, -0.6, 0.4])  # rad/s
    backend = EmulatedTrackball(motion=constant(omega), realtime=False)
    with UsbTrackball(backend=backend) as src:
        samples = collect(src, 2000)
        status = src.status()
    samples = samples[:2000]
    assert all(isinstance(s, BallSample) for s in samples)
    assert [s.seq for s in samples] == list(range(2000))
    assert samples[-1].t_device == pytest.approx(2.0)
    total = np.sum([s.rotation for s in samples], axis=0)
    # one count of quantisation per sensor axis at most: 1 / 47.24 counts/mm over a 50 mm radius
    np.testing.assert_allclose(total, omega * 2.0, atol=2 * (1e-3 / 47.24) / R)
    assert min(s.quality for s in samples) > 0.5
    assert status["connected"] and status["gaps"] == status["short_reports"] == status["bad_reports"] == 0


def test_wrong_calibration_in_config_scales_the_rotation():
    # the device's lens gives 2x the counts the config believes: the driver reports twice the rotation
    truth = TrackballConfig()
    from dataclasses import replace
    lens = replace(truth, sensors=tuple(replace(s, counts_per_mm=(94.48, 94.48)) for s in truth.sensors))
    backend = EmulatedTrackball(motion=constant((0.0, 0.0, 1.0)), truth=lens, realtime=False)
    with UsbTrackball(trackball=truth, backend=backend) as src:
        samples = collect(src, 1000)[:1000]
    assert sum(s.rotation[2] for s in samples) == pytest.approx(2.0, rel=1e-3)


def test_faults_are_counted_and_dropped_and_gaps_detected():
    faults = {10: "short", 20: "garbage", 30: "drop", 31: "drop", 40: "lift"}
    backend = EmulatedTrackball(motion=constant((0.0, -10.0, 5.0)), realtime=False, faults=faults)
    with UsbTrackball(backend=backend) as src:
        samples = collect(src, 100)
        status = src.status()
    assert status["short_reports"] == 1 and status["bad_reports"] == 1
    assert status["gaps"] == 3  # the short and garbage reports leave gaps too: 10, 20, then 30-31
    assert status["lost_reports"] == 1 + 1 + 2
    seqs = [s.seq for s in samples]
    assert 10 not in seqs and 20 not in seqs and 30 not in seqs and 31 not in seqs
    lifted = next(s for s in samples if s.seq == 40)
    # sensor 1 read nothing: its yaw disagrees with sensor 0's (quantisation alone costs < 3 %)
    assert lifted.quality < 0.8 and all(s.quality > 0.95 for s in samples if s.seq != 40)


@pytest.mark.parametrize("before, after, resets, lost", [
    ((1000, 5_000_000), (0, 1000), 1, 0),  # restarted: seq and device time back to 0
    ((2**31 + 1000, 5_000_000), (0, 1000), 1, 0),  # the same late in a run: seq looks 2**31 - 1001 ahead
    ((2**31 + 1000, 1000), (0, 1000), 1, 0),  # ... even where the device time says nothing
    ((10, 5000), (11, 4000), 1, 0),  # the device time went back
    ((100, 1000), (103, 4000), 0, 2),  # 2 reports lost in 3 ms at 1 kHz
    ((2**32 - 2, 1000), (1, 4000), 0, 2),  # the same across the u32 wrap
])
def test_a_device_restart_is_a_reset_and_lost_reports_a_gap(before, after, resets, lost):
    src = UsbTrackball()  # 1000 reports/s
    for seq, t_us in (before, after):
        src._handle(memoryview(P.encode_report(P.Report(seq, t_us, (0, 0, 0, 0), (100, 100), (False, False)))), 0.0)
    assert (src.counters["seq_resets"], src.counters["gaps"], src.counters["lost_reports"]) == (resets, int(lost > 0),
                                                                                                lost)


def test_overflow_flag_is_counted():
    backend = EmulatedTrackball(motion=constant((0.0, 0.0, 200.0)), realtime=False)  # 10 m/s surface speed
    with UsbTrackball(backend=backend) as src:
        collect(src, 10)
        assert src.status()["overflows"] >= 10


def test_unplug_is_reported_at_once_and_reading_resumes_after_replug():
    events = []
    backend = EmulatedTrackball(realtime=True)
    src = open_source("usb", backend=backend, on_event=events.append)
    with src:
        assert wait_for(lambda: src.status()["connected"] and src.status()["reports"] > 20)
        backend.unplug()
        t0 = time.monotonic()
        assert wait_for(lambda: not src.status()["connected"], 1.0)
        detected = time.monotonic() - t0
        assert [e["event"] for e in events] == ["locomotion_connected", "locomotion_lost"]
        assert "No such device" in events[-1]["reason"]
        src.read()
        time.sleep(0.05)
        assert src.read() == []  # nothing while unplugged
        backend.replug()
        assert wait_for(lambda: src.status()["connected"], 2.0)
        samples = collect(src, 10)
        assert samples[0].seq == 0  # the replugged device restarted
    assert events[-1]["event"] == "locomotion_back"
    assert src.status()["unplugs"] == 1 and src.status()["connects"] == 2
    print(f"unplug detected after {detected * 1e3:.2f} ms")


def test_unplug_from_the_script_and_automatic_replug():
    backend = EmulatedTrackball(realtime=False, faults={50: "unplug"}, replug_after_s=0.05)
    with UsbTrackball(backend=backend, retry_s=0.01) as src:
        assert wait_for(lambda: src.status()["connects"] == 2 and src.status()["reports"] > 100)
        assert src.status()["unplugs"] == 1


def test_device_that_never_appears_is_not_connected_and_says_why():
    backend = EmulatedTrackball(truth=TrackballConfig(vendor_id=0xBEEF), realtime=False)
    with UsbTrackball(backend=backend) as src:
        time.sleep(0.05)
        assert src.status()["connected"] is False
        assert src.read() == []


def test_stopped_device_is_restarted_by_the_silence_probe():
    backend = EmulatedTrackball(realtime=True)
    with UsbTrackball(backend=backend) as src:
        assert wait_for(lambda: src.status()["reports"] > 10)
        dev = usb.core.find(backend=backend)
        dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_STOP, 0, 0)  # e.g. a firmware watchdog reset
        n = src.status()["reports"]
        assert wait_for(lambda: src.status()["reports"] > n + 50, 3.0)
        assert src.status()["connected"]


def test_a_device_silent_while_it_says_running_gets_its_stream_restarted():
    """The report path hangs after 300 reports while GET_INFO says running: the probe restarts the stream (STOP,
    START; it used to take "running" for fine and wait for ever), reports come again from seq 0, nothing is lost."""
    events = []
    backend = EmulatedTrackball(realtime=True, faults={300: "hang"})
    with UsbTrackball(backend=backend, on_event=events.append) as src:
        samples = collect(src, 400, 5.0)
        status = src.status()
    seqs = [s.seq for s in samples]
    assert seqs[:300] == list(range(300)) and seqs[300:400] == list(range(100))  # restarted: seq from 0
    assert status["connected"] and status["unplugs"] == 0 and status["connects"] == 1
    assert status["seq_resets"] == 1 and status["gaps"] == 0
    assert [e["event"] for e in events] == ["locomotion_connected"]


def test_a_device_still_silent_after_its_stream_restart_is_lost_until_it_sends():
    """A connected device says running but sends nothing, even after the restart of its stream: one
    locomotion_lost naming it; last_report_age_s counts from its last report (probes used to reset it, and
    `connected` stayed True); reconnections that get no report stay quiet; its first report is locomotion_back."""
    events = []
    backend = EmulatedTrackball(realtime=True, faults={300: "hang"})
    with UsbTrackball(backend=backend, on_event=events.append) as src:
        assert wait_for(lambda: src.status()["reports"] > 100)
        backend.faults[0] = "hang"  # from the next START on its report path hangs at once
        assert wait_for(lambda: not src.status()["connected"], 2.0)
        lost = events[-1]
        assert [e["event"] for e in events] == ["locomotion_connected", "locomotion_lost"]
        assert "says it is running" in lost["reason"] and "(STOP, START)" in lost["reason"]
        assert lost["last_seq"] == 299
        time.sleep(0.3)  # the driver reconnects, restarts, gives up, ... every ~0.1 s
        status = src.status()
        assert not status["connected"] and status["unplugs"] == 1 and len(events) == 2
        assert status["last_report_age_s"] > 0.3 and status["last_seq"] == 299
        assert "says it is running" in status["last_error"]
        del backend.faults[0]  # the report path works again: the next connection's START gets reports
        assert wait_for(lambda: src.status()["connected"], 2.0)
        assert collect(src, 10)[-1].seq < 300
    assert [e["event"] for e in events] == ["locomotion_connected", "locomotion_lost", "locomotion_back"]
    assert src.status()["connects"] == 2


def test_raw_buffer_read_path_matches_pyusb_array_semantics():
    backend = EmulatedTrackball(realtime=False)
    dev = usb.core.find(backend=backend)
    dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_START, 0, 0)
    buf = array.array("B", bytes(64))
    n = dev.read(P.ENDPOINT_IN, buf, 10)
    assert n == P.REPORT_SIZE and P.decode_report(memoryview(buf)[:n]).seq == 0


def test_segments_motion_and_bad_fault_names():
    m = segments([(1.0, (1.0, 0.0, 0.0)), (1.0, (0.0, 2.0, 0.0))])
    assert list(m(0.5)) == [1.0, 0.0, 0.0] and list(m(1.5)) == [0.0, 2.0, 0.0] and list(m(3.0)) == [0.0] * 3
    with pytest.raises(ValueError, match="allowed"):
        EmulatedTrackball(faults={1: "melt"})


def test_a_failing_publisher_is_counted_and_reading_goes_on():
    def broken(sample):
        raise ConnectionError("bus down")

    with UsbTrackball(backend=EmulatedTrackball(realtime=False), on_sample=broken) as src:
        samples = collect(src, 50)
        status = src.status()
    assert len(samples) >= 50 and status["connected"]
    assert status["publish_errors"] >= 50 and "bus down" in status["last_error"]
    assert 0.0 <= status["quality_avg"] <= 1.0
