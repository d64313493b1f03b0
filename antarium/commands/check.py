"""`antarium check --config rig.toml`: the first-run checklist of a rig, one PASS/FAIL line per check.

    antarium check --config rig.toml          # asks the operator to confirm each panel of the test pattern
    antarium check --config rig.toml --auto   # sends the test pattern, checks the distributor latched it

Checks: the config is one `antarium serve` can run (`check_config`: scene, locomotion options, ...); the
distributor answers (VERSION and STATUS telemetry); panel count, pixels per panel, protocol and
firmware versions, faults; the USB trackball is present (source "usb") or FicTrac's frames arrive (source
"fictrac"; "fictrac-replay": its log holds frames); real-time
scheduling is allowed at [loop] realtime_priority; free disk space for [log] dir; the panel mapping (each
panel lit in turn). Exit status 0 when nothing failed, 1 otherwise. See docs/real_rig.md.
"""

from __future__ import annotations

import argparse
import math
import shutil
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from antarium.commands import require_seconds

HELP = "first-run checklist of a rig: config, distributor, panels, trackball, real time, disk, panel mapping"

#: test-pattern drive of a lit panel's green LEDs (of 65535): bright enough to see, far below full current
PATTERN_LEVEL = 8192


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None,
                        help="rig config TOML to check (default: the embedded default, an emulated dome)")
    parser.add_argument("--auto", action="store_true",
                        help="send the panel test pattern without asking the operator; the distributor's counters "
                             "must show every pattern latched")
    parser.add_argument("--timeout-s", type=float, default=2.0,
                        help="seconds to wait for the distributor's answers (default 2)")
    parser.add_argument("--min-free-gb", type=float, default=5.0,
                        help="free space the log folder needs (GB, default 5: about 4 h of trials)")
    parser.add_argument("--panels", default="all",
                        help="panels to light in the mapping check: 'all' or comma-separated numbers 0..54")


class Report:
    """Prints one line per check and remembers whether any failed."""

    def __init__(self) -> None:
        self.failed: list[str] = []

    def line(self, verdict: str, name: str, text: str) -> bool:
        print(f"{verdict:4} {name}: {text}", flush=True)
        if verdict == "FAIL":
            self.failed.append(name)
        return verdict != "FAIL"

    def passed(self, name: str, text: str) -> bool:
        return self.line("PASS", name, text)

    def fail(self, name: str, text: str) -> bool:
        return self.line("FAIL", name, text)

    def skip(self, name: str, text: str) -> bool:
        return self.line("SKIP", name, text)


@contextmanager
def _dome_link(config, timeout_s: float) -> Iterator[tuple[object | None, str]]:
    """The link the server would open (starting the emulator where the config spawns one) and its address; or
    (None, why not) when no link can be opened to [link] host/port: the distributor's check fails on that, the
    checks that do not need it still run."""
    from antarium.config import ConfigError
    from antarium.firmware_proto.link import open_link
    from antarium.server.config_check import check_link_host
    from antarium.server.emulator_process import EmulatorProcess

    link_cfg = config.link
    if link_cfg.interface == "virtual":
        with open_link("virtual") as link:
            yield link, "the in-process virtual dome ([link] interface = \"virtual\")"
        return
    host, port = link_cfg.host, link_cfg.port
    try:
        check_link_host(host)
    except ConfigError as exc:
        yield None, f"{exc}: fix [link] host in the rig config"
        return
    emulator = None
    try:
        if link_cfg.spawn_emulator:
            emulator = EmulatorProcess(host, port)
            emulator.start()
            port = emulator.port
        try:
            link = open_link("udp", host=host, port=port)
        except OSError as exc:
            yield None, (f"cannot open the UDP link to [link] host {host!r} port {port} ({exc}): check that this "
                         "computer has an address on the distributor's network (`ip addr`)")
            return
        with link:
            yield link, f"{host}:{port}" + (" (emulator spawned: [link] spawn_emulator = true)" if emulator else "")
    finally:
        if emulator is not None:
            emulator.stop()


def _ask_version(link, timeout_s: float) -> dict | None:
    """VERSION from the distributor, asking again every 0.2 s for `timeout_s` (a just-started emulator binds late)."""
    deadline = time.monotonic() + timeout_s
    while True:
        version = link.hello(wait_s=min(0.2, max(0.0, deadline - time.monotonic())))
        if version is not None or time.monotonic() >= deadline:
            return version


def gateway_route(host: str, routes: str = "/proc/net/route") -> tuple[str, str] | None:
    """(interface, gateway address) when this computer sends IPv4 `host` (an address or a name) through a gateway,
    read from the kernel's route table `routes` (Linux, longest prefix first); None when `host` is on a network of
    one of its cards, is its own loopback, or the table cannot be read. The distributor is never behind a gateway:
    such a route means that no card has an address on its subnet."""
    import ipaddress

    try:
        address = ipaddress.IPv4Address(socket.gethostbyname(host))
        rows = [line.split() for line in Path(routes).read_text().splitlines()[1:]]
    except (OSError, ValueError, UnicodeError):
        return None
    if address.is_loopback:
        return None
    best = None
    for row in rows:
        iface, dest, gateway, mask = row[0], int(row[1], 16), int(row[2], 16), int(row[7], 16)
        # the table's words are little-endian
        dest, gateway, mask = (int.from_bytes(v.to_bytes(4, "little"), "big") for v in (dest, gateway, mask))
        if int(address) & mask == dest and (best is None or mask > best[0]):
            best = (mask, iface, gateway)
    if best is None or best[2] == 0:
        return None
    return best[1], str(ipaddress.IPv4Address(best[2]))


def check_distributor(report: Report, link, where: str, timeout_s: float, host: str | None = None) -> dict | None:
    """Distributor reachable and answering VERSION and STATUS; returns its telemetry (None when silent). host: the
    distributor's [link] host, whose route names a wrong network card when it goes through a gateway."""
    version = _ask_version(link, timeout_s)
    if link.incompatible:  # it answered VERSION, in another protocol version: no frames can go to it
        report.fail("distributor", f"{where} answers but {link.incompatible}")
        return None
    telemetry = link.telemetry(wait_s=timeout_s) if version is not None else None
    if version is None or not telemetry.get("counters"):
        route = gateway_route(host) if host else None
        if route is not None:
            report.fail("distributor", f"no answer from {where} within {timeout_s:g} s: no network card of this "
                        f"computer has an address on its subnet, so its datagrams go to the gateway {route[1]} on "
                        f"{route[0]} (`ip route get {host}`); give the rig card an address on the distributor's "
                        "subnet (docs/real_rig.md section 2), or fix [link] host")
            return None
        report.fail("distributor", f"no answer from {where} within {timeout_s:g} s: check the distributor is "
                    "powered, its cable is in this computer's rig network card, that card has an address on the "
                    "distributor's subnet (`ip addr`), and [link] host/port name the distributor")
        return None
    report.passed("distributor", f"{where} answers VERSION and STATUS "
                  f"(link counters: {telemetry['link']['datagrams_sent']} sent, "
                  f"{telemetry['link']['replies_received']} replies)")
    return {**telemetry, "version": version}


def check_panels(report: Report, telemetry: dict) -> bool:
    """Panel count, pixels per panel, protocol and firmware versions, faults, from the distributor's telemetry."""
    from antarium.firmware_proto.header import PROTOCOL_VERSION

    v = telemetry["version"]
    firmware = f"firmware {v['firmware_major']}.{v['firmware_minor']}, protocol {v['protocol_version']}"
    wrong = [telemetry["mismatch"]] if telemetry.get("mismatch") else []  # panels, pixels, capabilities
    if v["protocol_version"] != PROTOCOL_VERSION:
        wrong.append(f"protocol {v['protocol_version']}, this software speaks {PROTOCOL_VERSION}: update one")
    faults = int(telemetry.get("fault_total") or 0)
    if faults:
        wrong.append(f"{faults} LED faults reported: see `telemetry` faults per panel (docs/protocol.md)")
    if wrong:
        return report.fail("panels", f"{firmware}; " + "; ".join(wrong))
    temps = telemetry.get("temperature_c")
    hottest = f", hottest panel {max(temps):.1f} °C" if temps else ""
    return report.passed("panels", f"{v['n_panels']} panels of {v['pixels_per_panel']} pixels, {firmware}, "
                                   f"no LED faults{hottest}")


def check_rig_config(report: Report, config) -> bool:
    """What `antarium serve` would refuse in the file before it starts (`check_config`), the ports in use aside."""
    from antarium.config import ConfigError
    from antarium.server.config_check import check_config

    try:
        check_config(config, ports=False)
    except ConfigError as exc:
        return report.fail("config", f"{exc} (`antarium serve` refuses this config)")
    return report.passed("config", "scene, [locomotion] source and options, [link] and [trackball] are usable "
                                   "(`antarium serve` checks the ports in use when it starts)")


#: locomotion sources whose input `check_trackball` reads: FicTrac's live stream and its logs
FICTRAC_SOURCES = ("fictrac", "fictrac-replay")


def check_trackball(report: Report, config, timeout_s: float) -> bool:
    """The USB trackball of [trackball] is plugged in ([locomotion] source = "usb"), or FicTrac's frames arrive
    within `timeout_s` (s; "fictrac") or its log holds frames ("fictrac-replay")."""
    source = config.locomotion.source
    if source in FICTRAC_SOURCES:
        return _check_fictrac(report, config, timeout_s)
    if source != "usb":
        return report.skip("trackball", f"[locomotion] source = {source!r}, neither \"usb\" nor FicTrac")
    from antarium.locomotion.trackball import config as tbconfig
    from antarium.server.config_check import source_options

    try:  # as the driver reads it: [trackball] here, or the file [locomotion] trackball names
        tb = tbconfig.load(source_options(config).get("trackball"))
    except (OSError, ValueError) as exc:
        return report.fail("trackball", f"{exc}: fix [trackball] or [locomotion] trackball")
    ids = f"{tb.vendor_id:04x}:{tb.product_id:04x}"
    try:
        import usb.core

        device = usb.core.find(idVendor=tb.vendor_id, idProduct=tb.product_id)
    except Exception as exc:  # noqa: BLE001 - no libusb, no permission: each is the operator's to fix
        return report.fail("trackball", f"cannot search USB for {ids}: {exc}; install libusb-1.0 and check "
                                        "the udev rule of docs/trackball_usb.md")
    if device is None:
        return report.fail("trackball", f"no USB device {ids} ([trackball] vendor_id/product_id): plug it in, "
                                        "check `lsusb`, then `antarium trackball calibrate --config RIG.toml`")
    return report.passed("trackball", f"USB device {ids} present")


def _check_fictrac(report: Report, config, timeout_s: float) -> bool:
    """Open the FicTrac source as `antarium serve` would and wait up to `timeout_s` (s) for a frame."""
    from antarium.locomotion import open_source
    from antarium.server.config_check import source_options

    name = config.locomotion.source
    try:
        source = open_source(name, **source_options(config))
        source.start()
    except (OSError, RuntimeError, TypeError, ValueError) as exc:  # port in use, no such log, a bad option
        return report.fail("trackball", f"{name}: {exc}")
    try:
        deadline = time.monotonic() + timeout_s
        while source.status()["frames"] == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
        status = source.status()
    finally:
        source.stop()
    malformed = f", {status['malformed']} malformed (last: {status['last_error']})" if status["malformed"] else ""
    live = name == "fictrac"
    if status["frames"] == 0:
        where, hint = ((f"within {timeout_s:g} s", source.lost_hint()) if live
                       else (f"in {status['path']}", "give a FicTrac .dat log as [locomotion] path"))
        return report.fail("trackball", f"no FicTrac frame {where}{malformed}: {hint}")
    where = (f"arrive on {status['source'][len('fictrac-'):]} {status['address'][0]}:{status['address'][1]}" if live
             else f"read from {status['path']}")
    return report.passed("trackball", f"FicTrac frames {where} ({status['frames']} frames{malformed})")


def check_realtime(report: Report, config) -> bool:
    """SCHED_FIFO at [loop] realtime_priority is granted (tried on a short-lived thread of this process)."""
    priority = config.loop.realtime_priority
    if priority == 0:
        return report.skip("real time", "[loop] realtime_priority = 0 (off)")
    from antarium.core import realtime

    outcome: list[BaseException | None] = []

    def attempt() -> None:
        try:
            realtime.set_realtime(priority)
            realtime.set_ordinary()
            outcome.append(None)
        except (OSError, AttributeError) as exc:
            outcome.append(exc)

    thread = threading.Thread(target=attempt, name="antarium-check-rt")
    thread.start()
    thread.join()
    if outcome[0] is not None:
        return report.fail("real time", f"SCHED_FIFO priority {priority} refused ({outcome[0]}): add "
                           f"'@antarium - rtprio {priority}' to /etc/security/limits.d/antarium.conf and log in "
                           "again, or give the interpreter CAP_SYS_NICE (docs/real_rig.md)")
    return report.passed("real time", f"SCHED_FIFO priority {priority} allowed")


def check_disk(report: Report, config, min_free_gb: float) -> bool:
    """Free space at [log] dir, or, while it does not exist yet, at its nearest existing parent, which must be a
    writable folder: `antarium serve` makes the missing folders when it starts (`check_log_dir`)."""
    folder = Path(config.log.dir).expanduser().resolve()
    existing = next(p for p in (folder, *folder.parents) if p.exists())
    free_gb = shutil.disk_usage(existing).free / 1e9
    if not existing.is_dir() or not _writable(existing):
        return report.fail("disk", f"{existing} is not a writable folder: fix [log] dir ({folder})")
    where = str(folder) if existing == folder else (f"{existing}, the nearest existing folder of [log] dir {folder}, "
                                                     "which does not exist yet (`antarium serve` makes it at start)")
    if free_gb < min_free_gb:
        return report.fail("disk", f"{free_gb:.1f} GB free at {where}; {min_free_gb:g} GB wanted: free space or "
                                   "point [log] dir at a larger disk")
    return report.passed("disk", f"{free_gb:.1f} GB free for trial logs at {where}")


def _writable(folder: Path) -> bool:
    import os

    return os.access(folder, os.W_OK | os.X_OK)


def panel_pattern(panel: int):
    """LED frame (20350, 2) uint16 with panel `panel`'s green LEDs at PATTERN_LEVEL, the rest dark."""
    import numpy as np

    from antarium.geometry.constants import GB_PER_PANEL, N_PIXELS, PIXELS_PER_PANEL

    frame = np.zeros((N_PIXELS, 2), np.uint16)
    start = panel * PIXELS_PER_PANEL
    frame[start:start + GB_PER_PANEL, 0] = PATTERN_LEVEL
    return frame


def check_mapping(report: Report, link, panels: list[int], confirm: Callable[[int, str], bool] | None,
                  timeout_s: float) -> bool:
    """Light each panel in turn. `confirm(panel, where)` asks the operator (None: --auto, the distributor's
    latch counter must rise by one per pattern)."""
    import numpy as np

    from antarium.geometry import load_dome

    dome = load_dome()
    dark = np.zeros((dome.positions.shape[0], 2), np.uint16)
    # a distributor that latched frames of an earlier run drops this run's first frame (docs/protocol.md, "Restarts"):
    # that frame is a dark one, so that the first panel's pattern is shown and counted
    link.send_frame(dark)
    before = link.telemetry(wait_s=timeout_s).get("counters", {}).get("frames_latched", 0)
    wrong, unanswered = [], None
    for p in panels:
        link.send_frame(panel_pattern(p))
        outward = -dome.panel_normals[p]
        where = (f"pentagon {p // 5} slot {p % 5}, azimuth {math.degrees(math.atan2(outward[1], outward[0])):.0f}°, "
                 f"elevation {math.degrees(math.asin(np.clip(outward[2], -1, 1))):.0f}°")
        if confirm is not None:
            try:
                if not confirm(p, where):
                    wrong.append(p)
            except NoAnswer:
                unanswered = p
                break
    link.send_frame(dark)
    if unanswered is not None:
        return report.fail("panel mapping", f"no answer for panel {unanswered} (the input ended): run it at a "
                                            "terminal to confirm each panel by eye, or with --auto")
    if confirm is None:
        time.sleep(0.05)
        after = link.telemetry(wait_s=timeout_s).get("counters", {}).get("frames_latched", 0)
        latched = after - before
        if latched < len(panels) + 1:
            return report.fail("panel mapping", f"{len(panels)} test patterns (and a dark frame) sent, {latched} "
                                                "latched: the distributor drops frames; see its counters")
        return report.passed("panel mapping", f"{len(panels)} test patterns sent and latched; run without --auto "
                                              "to confirm each panel by eye")
    if wrong:
        return report.fail("panel mapping", f"panels {wrong} not where expected: check their cables' order at the "
                                            "pentagon boards (docs/real_rig.md, 'Panel mapping')")
    return report.passed("panel mapping", f"{len(panels)} panels confirmed by the operator")


class NoAnswer(Exception):
    """The operator's input ended before an answer (stdin closed or not a terminal)."""


#: the operator's answers: Enter or y/yes confirms the panel, n/no fails it; anything else is asked again
YES, NO = ("", "y", "yes"), ("n", "no")


def _ask_operator(panel: int, where: str) -> bool:
    """True when the operator answers that `panel` is lit where expected (Enter, y, yes), False for n or no; any
    other answer is asked again; `NoAnswer` at the end of the input."""
    prompt = f"  panel {panel} ({where}) should be lit green alone: Enter (or y) if so, n + Enter if not: "
    while True:
        print(prompt, end="", flush=True)
        answer = sys.stdin.readline()
        if not answer:
            print(flush=True)
            raise NoAnswer
        word = answer.strip().lower()
        if word in YES or word in NO:
            return word in YES
        print(f"  {answer.strip()[:40]!r} is not an answer: Enter or y (lit where expected), n (not)", flush=True)


def _panel_list(text: str) -> list[int]:
    if text == "all":
        return list(range(55))
    try:
        panels = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        panels = []
    if not panels or any(not 0 <= p < 55 for p in panels):
        raise ValueError(f"--panels must be 'all' or comma-separated numbers 0..54, got {text!r}")
    return panels


def run(args: argparse.Namespace) -> int:
    from antarium.config import load_config

    require_seconds(args, "timeout_s")
    if not (math.isfinite(args.min_free_gb) and args.min_free_gb >= 0):
        raise ValueError(f"--min-free-gb must be a number of GB >= 0, got {args.min_free_gb:g}")
    panels = _panel_list(args.panels)
    config = load_config(args.config)
    report = Report()
    print(f"antarium check: rig {config.rig.name!r} ({args.config or 'embedded default'})", flush=True)
    check_rig_config(report, config)
    with _dome_link(config, args.timeout_s) as (link, where):
        if link is None:
            telemetry = None
            report.fail("distributor", where)
        else:
            telemetry = check_distributor(report, link, where, args.timeout_s, config.link.host)
        if telemetry is None:
            report.fail("panels", "no telemetry: fix the distributor first")
        else:
            check_panels(report, telemetry)
        check_trackball(report, config, args.timeout_s)
        check_realtime(report, config)
        check_disk(report, config, args.min_free_gb)
        if telemetry is None:
            report.fail("panel mapping", "not tried: the distributor does not answer")
        else:
            check_mapping(report, link, panels, None if args.auto else _ask_operator, args.timeout_s)
    if report.failed:
        print(f"antarium check: {len(report.failed)} failed: {', '.join(report.failed)}", flush=True)
        return 1
    print("antarium check: every check passed", flush=True)
    return 0
