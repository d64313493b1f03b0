"""`antarium check`: the first-run checklist against the emulator process, the virtual dome, and a port where
nothing answers; each check one PASS/FAIL/SKIP line, exit status 1 on any failure (issue #20, point 4)."""

import contextlib
import io
import socket
import threading
from pathlib import Path

import pytest
from conftest import wait_for

from antarium.cli import main
from antarium.config import load_config
from antarium.server.emulator_process import EmulatorProcess, free_udp_port

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _rig(tmp_path, link: str, extra: str = "") -> str:
    path = tmp_path / "rig.toml"
    path.write_text(f'[loop]\nrealtime_priority = 0\n[link]\n{link}\n[log]\ndir = "{tmp_path / "trials"}"\n{extra}')
    return str(path)


def _lines(out: str) -> dict[str, str]:
    """check name -> verdict, from the report's lines."""
    return {line[5:].split(":")[0]: line[:4].strip() for line in out.splitlines() if line[:4] in
            ("PASS", "FAIL", "SKIP")}


@pytest.fixture
def emulator():
    process = EmulatorProcess()
    process.start()
    yield process
    process.stop()


def test_every_check_passes_against_the_emulator(tmp_path, emulator, capsys):
    rig = _rig(tmp_path, f'host = "127.0.0.1"\nport = {emulator.port}\nspawn_emulator = false')
    assert main(["check", "--config", rig, "--auto", "--timeout-s", "5", "--min-free-gb", "0.01"]) == 0
    out = capsys.readouterr().out
    assert _lines(out) == {"config": "PASS", "distributor": "PASS", "panels": "PASS", "trackball": "SKIP",
                           "real time": "SKIP", "disk": "PASS", "panel mapping": "PASS"}
    assert "55 panels of 370 pixels, firmware 1.0, protocol 1" in out
    assert "55 test patterns sent and latched" in out


def test_nothing_answering_fails_with_what_to_do(tmp_path, capsys):
    rig = _rig(tmp_path, f'host = "127.0.0.1"\nport = {free_udp_port("127.0.0.1")}\nspawn_emulator = false')
    assert main(["check", "--config", rig, "--auto", "--timeout-s", "0.3", "--min-free-gb", "0.01"]) == 1
    out = capsys.readouterr().out
    verdicts = _lines(out)
    assert verdicts["distributor"] == verdicts["panels"] == verdicts["panel mapping"] == "FAIL"
    assert verdicts["disk"] == "PASS"
    assert "network card" in out and "[link] host/port" in out
    assert "3 failed: distributor, panels, panel mapping" in out


@contextlib.contextmanager
def _board(version, emulator=None):
    """A distributor on a loopback UDP port (yields the port) that answers HELLO with the bytes `version(tag)`
    and every other datagram as `emulator` (a `firmware_proto.emulator.Emulator`) would, or not at all."""
    board = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    board.bind(("127.0.0.1", 0))
    board.settimeout(0.1)
    done = threading.Event()

    def answer():
        while not done.is_set():
            try:
                data, peer = board.recvfrom(2048)
            except TimeoutError:
                continue
            if len(data) >= 4 and data[2] == 0x06:  # HELLO (TD 0x7F: control to all, opcode 0x06)
                board.sendto(version(data[3]), peer)
            elif emulator is not None:
                for reply in emulator.handle_datagram(data):
                    board.sendto(reply, peer)

    thread = threading.Thread(target=answer, daemon=True)
    thread.start()
    try:
        yield board.getsockname()[1]
    finally:
        done.set()
        thread.join()
        board.close()


def _version_without_dot_correction(tag: int) -> bytes:
    from antarium.firmware_proto.replies import OP_VERSION, VERSION_BODY, _reply

    return _reply(OP_VERSION, tag, VERSION_BODY.pack(protocol_version=1, firmware_major=1, firmware_minor=0,
                                                     n_panels=55, pixels_per_panel=370, capabilities=0x3F & ~0x02))


def test_a_distributor_of_another_protocol_version_is_named_not_called_silent(tmp_path, capsys):
    """A board answering VERSION in protocol version 2 (header VERSION byte 2) is what the check names."""
    with _board(lambda tag: bytes([0xBF, 0x02, 0x81, tag, 2, 2, 0, 55, 1, 0x72, 0, 0x3F])) as port:
        rig = _rig(tmp_path, f'host = "127.0.0.1"\nport = {port}\nspawn_emulator = false')
        assert main(["check", "--config", rig, "--auto", "--timeout-s", "1", "--min-free-gb", "0.01"]) == 1
    out = capsys.readouterr().out
    assert _lines(out)["distributor"] == "FAIL"
    assert "answers but the distributor speaks protocol version 2; this host speaks 1" in out, out
    assert "no answer from" not in out


def test_a_distributor_without_a_capability_the_dome_needs_fails_the_panel_check(tmp_path, capsys):
    """The real emulator on UDP, but its VERSION without dot correction: `antarium check` names the capability
    (it checked only the panel count and pixels per panel until 2026-11-27)."""
    from antarium.firmware_proto.emulator import Emulator

    with _board(_version_without_dot_correction, Emulator()) as port:
        rig = _rig(tmp_path, f'host = "127.0.0.1"\nport = {port}\nspawn_emulator = false')
        assert main(["check", "--config", rig, "--auto", "--timeout-s", "2", "--min-free-gb", "0.01"]) == 1
    out = capsys.readouterr().out
    assert _lines(out)["distributor"] == "PASS" and _lines(out)["panels"] == "FAIL", out
    assert "without dot_correction" in out, out


def test_a_served_rig_whose_distributor_lacks_a_capability_raises_an_alarm(tmp_path):
    """`status()` of a running server names what the distributor's VERSION lacks among its alarms."""
    from antarium.config import resolve
    from antarium.firmware_proto.emulator import Emulator
    from antarium.server import Server

    with _board(_version_without_dot_correction, Emulator()) as port:
        config = resolve({"link": {"host": "127.0.0.1", "port": port, "spawn_emulator": False},
                          "loop": {"realtime_priority": 0}, "log": {"dir": str(tmp_path)},
                          "bus": {"enabled": False}})
        with Server(config) as server:
            assert wait_for(lambda: any("without dot_correction" in a for a in server.status()["alarms"]), 10.0)


def test_a_distributor_that_latched_an_earlier_run_shows_the_first_panel_when_asked(tmp_path, monkeypatch, capsys):
    """A second `antarium check` on the same board (or one after `antarium serve`) starts its frame sequence at 0
    again, which the board's latch rule drops as stale (docs/protocol.md, "Restarts"): the first panel was named to
    the operator while the dome stayed dark (review 2026-11-27)."""
    from antarium.firmware_proto.control import encode_hello
    from antarium.firmware_proto.emulator import Emulator
    from antarium.geometry.constants import PIXELS_PER_PANEL

    board, lit = Emulator(), []

    def operator(panel: int, where: str) -> bool:
        rows = slice(panel * PIXELS_PER_PANEL, (panel + 1) * PIXELS_PER_PANEL)
        lit.append(wait_for(lambda: board.led_values()[rows].any(), 1.0))
        return lit[-1]

    monkeypatch.setattr("antarium.commands.check._ask_operator", operator)
    with _board(lambda tag: board.handle_datagram(encode_hello(tag))[0], board) as port:
        rig = _rig(tmp_path, f'host = "127.0.0.1"\nport = {port}\nspawn_emulator = false')
        for _ in range(2):
            assert main(["check", "--config", rig, "--min-free-gb", "0.01", "--panels", "0,1"]) == 0, \
                capsys.readouterr().out
    assert lit == [True, True, True, True]


def test_a_second_auto_check_on_the_same_distributor_passes(tmp_path, emulator, capsys):
    """--auto counted the first pattern of the second run as dropped: `1 failed: panel mapping` on a good rig."""
    rig = _rig(tmp_path, f'host = "127.0.0.1"\nport = {emulator.port}\nspawn_emulator = false')
    for _ in range(2):
        assert main(["check", "--config", rig, "--auto", "--timeout-s", "5", "--min-free-gb", "0.01",
                     "--panels", "0,1"]) == 0, capsys.readouterr().out


def test_the_operator_confirms_each_panel(tmp_path, monkeypatch, capsys):
    rig = _rig(tmp_path, 'interface = "virtual"')
    monkeypatch.setattr("sys.stdin", io.StringIO("\nn\n"))  # panel 7 lit where expected, panel 30 not
    assert main(["check", "--config", rig, "--panels", "7,30", "--min-free-gb", "0.01"]) == 1
    out = capsys.readouterr().out
    assert "panel 7 (pentagon 1 slot 2, azimuth" in out
    assert "FAIL panel mapping: panels [30] not where expected" in out


def test_no_answer_is_not_a_confirmation(tmp_path, monkeypatch, capsys):
    rig = _rig(tmp_path, 'interface = "virtual"')
    monkeypatch.setattr("sys.stdin", io.StringIO("\n"))  # panel 7 confirmed, then the input ends
    assert main(["check", "--config", rig, "--panels", "7,30,31", "--min-free-gb", "0.01"]) == 1
    out = capsys.readouterr().out
    assert "FAIL panel mapping: no answer for panel 30 (the input ended)" in out
    assert "panel 31 (" not in out  # not lit once nobody answers


def test_a_usb_trackball_that_is_absent_fails(tmp_path, capsys):
    rig = _rig(tmp_path, 'interface = "virtual"',
               '[locomotion]\nsource = "usb"\n[trackball]\nvendor_id = 0xfffe\nproduct_id = 0xfffd\n')
    assert main(["check", "--config", rig, "--auto", "--min-free-gb", "0.01"]) == 1
    out = capsys.readouterr().out
    assert _lines(out)["trackball"] == "FAIL" and "fffe:fffd" in out


def test_real_time_refused_and_a_full_disk_fail(tmp_path, monkeypatch, capsys):
    def refuse(priority, pid=0):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr("antarium.core.realtime.set_realtime", refuse)
    rig = _rig(tmp_path, 'interface = "virtual"')
    Path(rig).write_text(Path(rig).read_text().replace("realtime_priority = 0", "realtime_priority = 20"))
    assert main(["check", "--config", rig, "--auto", "--min-free-gb", "1e9"]) == 1
    out = capsys.readouterr().out
    assert _lines(out)["real time"] == "FAIL" and "rtprio 20" in out
    assert _lines(out)["disk"] == "FAIL" and "GB wanted" in out


@pytest.mark.parametrize("host, shown", [
    ("192.168.55.256", "[link] host '192.168.55.256' is not an IP address; allowed: the distributor's IP address"),
    ("no-such-board.invalid", "[link] host 'no-such-board.invalid' is not an IP address and does not resolve"),
])
def test_a_bad_distributor_host_fails_its_line_and_the_other_checks_run(tmp_path, capsys, host, shown):
    rig = _rig(tmp_path, f'host = "{host}"\nport = 19055\nspawn_emulator = false')
    assert main(["check", "--config", rig, "--auto", "--min-free-gb", "0.01"]) == 1
    out = capsys.readouterr().out
    assert _lines(out) == {"config": "FAIL", "distributor": "FAIL", "panels": "FAIL", "trackball": "SKIP",
                           "real time": "SKIP", "disk": "PASS", "panel mapping": "FAIL"}
    assert f"FAIL distributor: {shown}" in out and "fix [link] host" in out


def test_a_log_folder_not_made_yet_is_measured_at_its_existing_parent_and_said_so(tmp_path, capsys):
    rig = _rig(tmp_path, 'interface = "virtual"')
    Path(rig).write_text(Path(rig).read_text().replace(str(tmp_path / "trials"), str(tmp_path / "data" / "trials")))
    assert main(["check", "--config", rig, "--auto", "--min-free-gb", "0.01"]) == 0
    disk = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("PASS disk: "))
    missing = tmp_path / "data" / "trials"
    assert f"free for trial logs at {tmp_path}, the nearest existing folder of [log] dir {missing}, which does not "\
           "exist yet (`antarium serve` makes it at start)" in disk
    assert not (tmp_path / "data").exists()  # the check makes nothing


def test_bad_panels_are_refused(capsys):
    assert main(["check", "--panels", "3,55"]) == 2
    assert "--panels must be 'all' or comma-separated numbers 0..54, got '3,55'" in capsys.readouterr().err


def test_the_real_rig_example_loads():
    config = load_config(DOCS / "rig.real.example.toml")
    assert config.link.interface == "udp" and not config.link.spawn_emulator and config.link.port == 19055
    assert config.locomotion.source == "usb" and config.loop.realtime_priority > 0
    assert config.foreign["trackball"]["vendor_id"] == 0x1209


@pytest.mark.parametrize("answers, verdict", [
    ("b\ny\n", "PASS"),        # an unclear answer is asked again; y confirms
    ("maybe\nno\n", "FAIL"),   # no fails the panel
    ("yes\n", "PASS"),
    ("nope\n", "FAIL"),        # asked again, then the input ends: not a confirmation
])
def test_only_yes_or_enter_confirms_a_panel(tmp_path, monkeypatch, capsys, answers, verdict):
    rig = _rig(tmp_path, 'interface = "virtual"')
    monkeypatch.setattr("sys.stdin", io.StringIO(answers))
    assert main(["check", "--config", rig, "--panels", "0", "--min-free-gb", "0.01"]) == (0 if verdict == "PASS" else 1)
    out = capsys.readouterr().out
    assert f"{verdict} panel mapping: " in out
    if answers.split("\n")[0] not in ("", "y", "yes", "n", "no"):
        assert "is not an answer" in out and out.count("panel 0 (pentagon") == 2  # asked twice



def _fictrac_line(i: int) -> bytes:
    from antarium.locomotion.fictrac.protocol import FicTracFrame, format_line

    values = [0.0] * 25
    values[0] = values[22] = i
    return (format_line(FicTracFrame(*values)) + "\n").encode()


def test_fictrac_frames_that_arrive_pass_the_trackball_line(tmp_path, capsys):
    port = free_udp_port("127.0.0.1")
    rig = _rig(tmp_path, 'interface = "virtual"', f'[locomotion]\nsource = "fictrac"\nport = {port}\n')
    done = threading.Event()

    def fictrac():
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            i = 1
            while not done.wait(0.01):
                tx.sendto(_fictrac_line(i), ("127.0.0.1", port))
                i += 1

    sender = threading.Thread(target=fictrac)
    sender.start()
    try:
        assert main(["check", "--config", rig, "--auto", "--min-free-gb", "0.01"]) == 0
    finally:
        done.set()
        sender.join()
    assert f"PASS trackball: FicTrac frames arrive on udp 127.0.0.1:{port} (" in capsys.readouterr().out


@pytest.mark.parametrize("locomotion, verdicts, shown", [
    # nothing sends: the check passed (trackball SKIP) on a rig whose ant could never move
    ('source = "fictrac"\nport = {port}', {"config": "PASS", "trackball": "FAIL"},
     "FAIL trackball: no FicTrac frame within 0.3 s: is FicTrac running and sending to udp 127.0.0.1:{port}"),
    # a log of no frames, and an option `antarium serve` refuses: both passed
    ('source = "fictrac-replay"\npath = "{log}"', {"config": "PASS", "trackball": "FAIL"},
     "FAIL trackball: no FicTrac frame in {log}, 1 malformed (last: FicTrac line must hold 25"),
    ('source = "fictrac"\ntransport = "tpc"', {"config": "FAIL", "trackball": "FAIL"},
     "FAIL config: [locomotion] FicTrac transport must be one of udp, tcp, got 'tpc' (`antarium serve` refuses"),
    ('source = "replay"\npath = "{tmp}/gone.h5"', {"config": "FAIL", "trackball": "SKIP"},
     "FAIL config: [locomotion] path '{tmp}/gone.h5' does not exist"),
])
def test_a_locomotion_source_that_cannot_work_fails(tmp_path, capsys, locomotion, verdicts, shown):
    log = tmp_path / "run.dat"
    log.write_text("not, a, fictrac, line\n")
    fill = {"port": free_udp_port("127.0.0.1"), "log": log, "tmp": tmp_path}
    rig = _rig(tmp_path, 'interface = "virtual"', "[locomotion]\n" + locomotion.format(**fill) + "\n")
    assert main(["check", "--config", rig, "--auto", "--timeout-s", "0.3", "--min-free-gb", "0.01"]) == 1
    out = capsys.readouterr().out
    assert {k: _lines(out)[k] for k in verdicts} == verdicts, out
    assert shown.format(**fill) in out, out


#: a lab computer's /proc/net/route: default via 192.0.2.1 on eth0, eth0 on 192.0.2.0/24, the rig card enp3s0 on
#: 192.168.55.0/24 (the kernel writes each address as a little-endian hex word)
ROUTES = ("Iface\tDestination\tGateway \tFlags\tRefCnt\tUse\tMetric\tMask\t\tMTU\tWindow\tIRTT\n"
          "eth0\t00000000\t010200C0\t0003\t0\t0\t0\t00000000\t0\t0\t0\n"
          "eth0\t000200C0\t00000000\t0001\t0\t0\t0\t00FFFFFF\t0\t0\t0\n"
          "enp3s0\t0037A8C0\t00000000\t0001\t0\t0\t0\t00FFFFFF\t0\t0\t0\n")


@pytest.mark.parametrize("rig_card, host, route", [
    (True, "192.168.55.2", None),                      # the rig card is on the distributor's subnet
    (False, "192.168.55.2", ("eth0", "192.0.2.1")),    # it is not: the datagrams go to the lab's gateway
    (False, "192.0.2.9", None),                        # on eth0's own subnet
    (False, "127.0.0.1", None),                        # a local emulator
])
def test_a_distributor_behind_a_gateway_names_the_card_it_goes_through(tmp_path, rig_card, host, route):
    """A rig card without an address (or the cable in the lab card) was reported as a silent distributor among
    five possible causes; the route table says which (review 2026-11-27)."""
    from antarium.commands.check import gateway_route

    table = tmp_path / "route"
    table.write_text(ROUTES if rig_card else "".join(ROUTES.splitlines(keepends=True)[:3]))
    assert gateway_route(host, str(table)) == route
    assert gateway_route(host, str(tmp_path / "no-such-table")) is None


def test_the_trackball_ids_of_a_file_named_by_locomotion_are_the_ones_searched(tmp_path, capsys):
    """`[locomotion] trackball = "tb.toml"` (the driver reads the ids there): the check searched the default ids
    1209:0001 instead (review 2026-11-27)."""
    tb = tmp_path / "tb.toml"
    tb.write_text("[trackball]\nvendor_id = 0xfffe\nproduct_id = 0xfffd\n")
    rig = _rig(tmp_path, 'interface = "virtual"', f'[locomotion]\nsource = "usb"\ntrackball = "{tb}"\n')
    assert main(["check", "--config", rig, "--auto", "--min-free-gb", "0.01"]) == 1
    out = capsys.readouterr().out
    assert "FAIL trackball: no USB device fffe:fffd" in out, out
