"""The monitor page in a real browser (Debian's headless chromium driven by Selenium), against `antarium serve`
(the embedded default: emulator on loopback, habitat, scripted walker) and `antarium monitor`, on loopback.

Checked from the page itself: the map's pixels at known LED positions are the colours of the LED frame the server
sent to the dome (the frame number the page shows, read from the bus' LED stream), after a scene rotation
commanded from the page; the path grows while the walker moves; the stats update; a rig that goes away is shown
as disconnected; a page opened from an address the rig does not allow gets a clear refusal.
"""

import shutil
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from antarium import bus
from antarium.monitor.led_stream import decode_leds, led_key

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def _start_monitor(config, *extra):
    """`antarium monitor` on a free port; returns (process, page URL) once it listens."""
    proc = subprocess.Popen([sys.executable, "-m", "antarium", "monitor", "--config", str(config), "--port", "0",
                             *extra], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    line = proc.stdout.readline()
    assert " at http://" in line, line + proc.stdout.read()
    return proc, line.split(" at ", 1)[1].split()[0]


def _stop(proc):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()


def _wait(predicate, timeout_s, what):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"not within {timeout_s} s: {what}")


def open_chromium():
    """Debian's headless chromium through Selenium (the test fails naming the packages when they are missing)."""
    if not (shutil.which(CHROMIUM) and shutil.which(CHROMEDRIVER)):  # the Makefile's system check installs them
        pytest.fail("Debian's chromium and chromium-driver are missing: sudo apt-get install -y chromium "
                    "chromium-driver (make system-check does it as root)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1500,1100",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(20)
    driver.set_script_timeout(20)
    return driver


@pytest.fixture(scope="module")
def browser():
    driver = open_chromium()
    yield driver
    driver.quit()


@pytest.fixture()
def rig(tmp_path):
    """`antarium serve` (embedded default, on free loopback ports) and a monitor with page commands on."""
    config, endpoint = tmp_path / "rig.toml", bus.free_tcp_endpoint()
    config.write_text(f"""
[rig]
name = "tmon"
[bus]
listen = ["{endpoint}"]
[loop]
realtime_priority = 0
[log]
dir = "{tmp_path / 'logs'}"
[monitor]
commands = true
""")
    serve = subprocess.Popen([sys.executable, "-m", "antarium", "serve", "--config", str(config)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    monitor, url = _start_monitor(config)
    try:
        yield endpoint, serve, url
    finally:
        _stop(serve)
        _stop(monitor)


def _on_panels(leds):
    """Where LEDs `leds` sit on their flat panels, with the panels' corners on the unit sphere (n, 3), as the
    page's 3D view draws them."""
    from antarium.geometry import load_dome

    dome = load_dome()
    d, panel = np.asarray(dome.directions)[leds], np.asarray(dome.panel)[leds]
    corners = np.asarray(dome.panel_corners)[panel]
    corners = corners / np.linalg.norm(corners, axis=-1, keepdims=True)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    along = np.einsum("ij,ij->i", normal, corners[:, 0]) / np.einsum("ij,ij->i", normal, d)
    return d * along[:, None]


def _state(driver):
    return driver.execute_script(
        "const M = window.antariumMonitor; return {alive: M.alive, frame: M.frame, drawn: M.drawn, "
        "path: M.pathLength, status: M.statusCount, stats: M.statsCount, "
        "rotation: document.getElementById('poseinfo').textContent, conn: document.getElementById('conn').textContent}")


def test_the_page_shows_the_dome_the_path_and_the_stats_live(browser, rig):
    endpoint, serve, url = rig
    session = bus.open_session({"connect": [endpoint]}, role="client")
    frames: dict[int, np.ndarray] = {}
    lock = threading.Lock()

    def keep(sample):
        d = decode_leds(sample.payload.to_bytes())
        with lock:
            frames[d["frame"]] = d["values"].copy()
            for old in sorted(frames)[:-400]:
                del frames[old]

    sub = session.declare_subscriber(led_key("tmon"), keep)
    try:
        # the subscription reaches the server before the page opens: every frame the page draws is kept here too
        _wait(lambda: len(frames) > 2, 30, "the test's own LED subscription receives frames")
        browser.get(url)
        _wait(lambda: _state(browser)["alive"] and _state(browser)["drawn"] > 3, 30, "the page shows LED frames")
        first = _state(browser)
        assert "LIVE" in first["conn"]

        # a scene rotation commanded from the page (commands = true): the server validates it and replies
        reply = browser.execute_async_script(
            "const done = arguments[0]; window.antariumMonitor.command('rotate_scene', {deg: 90}).then(done);")
        assert reply["ok"] is True and abs(reply["result"]["scene_rotation_deg"] - 90.0) < 1e-6, reply
        refused = browser.execute_async_script(
            "const done = arguments[0]; window.antariumMonitor.command('rotate_scene', {deg: 1e9}).then(done);")
        assert "deg" in refused["error"], refused  # the server's own validation, relayed to the page
        _wait(lambda: "90.0" in _state(browser)["rotation"], 10, "the page shows the scene rotated by 90°")

        # the map at known LED positions has the colours of the frame it says it shows
        geo = browser.execute_script("const g = window.antariumMonitor.geometry; return {x: g.x, y: g.y, uv: g.uv};")
        xy = np.stack([geo["x"], geo["y"]], axis=1)
        _, first_at, counts = np.unique(xy, axis=0, return_index=True, return_counts=True)
        own_pixel = first_at[counts == 1]  # LEDs alone on their map pixel
        rng = np.random.default_rng(0)
        leds = np.sort(rng.choice(own_pixel, 200, replace=False)).tolist()
        # the map and the 3D view read back in one task: the same frame
        snap, view = browser.execute_script(
            "const M = window.antariumMonitor; return [M.snapshot(arguments[0]), M.snapshot3d(arguments[1])];",
            leds, _on_panels(leds).tolist())
        with lock:
            values = frames.get(snap["frame"])
        assert values is not None, f"frame {snap['frame']} not seen on the LED stream ({len(frames)} kept)"
        level = np.round(255 * np.sqrt(values[leds].astype(float) / 65535))
        uv = np.asarray(geo["uv"], bool)[leds]
        want = np.where(uv[:, None], np.stack([level[:, 0], 0 * level[:, 0], level[:, 0]], 1),
                        np.stack([0 * level[:, 0], level[:, 0], level[:, 1]], 1))
        got = np.asarray(snap["colours"], float)
        assert np.abs(got - want).max() <= 1, np.abs(got - want).max()
        assert want[:, 1:].max() > 20  # the habitat lights the dome: the comparison is not of black on black
        # the 3D view shows each LED it faces where that LED sits on its panel, in the map's colour
        facing = np.array([v["facing"] for v in view["views"]]) > 0.3
        seen = np.asarray([v["colour"] for v in view["views"]], float)[facing]
        assert view["frame"] == snap["frame"] and facing.sum() > 40, (view["frame"], snap["frame"], facing.sum())
        agree = (np.abs(seen - got[facing]).max(axis=1) <= 1).mean()
        assert agree >= 0.9, f"the 3D view agrees with the map at {agree:.0%} of the LEDs it faces"
        # turned (as by a drag), it shows the LEDs that now face it, in the same frame's colours
        snap, turned = browser.execute_script(
            "const M = window.antariumMonitor; M.turn(3.0, 0.0); return [M.snapshot(arguments[0]), "
            "M.snapshot3d(arguments[1])];", leds, _on_panels(leds).tolist())
        facing_now = np.array([v["facing"] for v in turned["views"]]) > 0.3
        seen = np.asarray([v["colour"] for v in turned["views"]], float)[facing_now]
        got = np.asarray(snap["colours"], float)
        assert turned["frame"] == snap["frame"] and facing_now.sum() > 40 and (facing_now & ~facing).sum() > 20
        agree = (np.abs(seen - got[facing_now]).max(axis=1) <= 1).mean()
        assert agree >= 0.9, f"turned, the 3D view agrees with the map at {agree:.0%} of the LEDs it faces"

        # the polarisers' angles from the link's telemetry (degrees on the bus) drawn as bars over the UV pixels
        _wait(lambda: browser.execute_script("return Array.isArray(status && status.telemetry && "
                                             "status.telemetry.polariser_angles_deg)"), 30,
              "the status carries the polarisers' angles in degrees")
        bars = browser.execute_script(
            "document.getElementById('uvov').checked = true; polShown = null; drawPolarisers(); "
            "const c = document.getElementById('pol'), d = c.getContext('2d').getImageData(0, 0, c.width, c.height)"
            ".data; let n = 0; for (let k = 3; k < d.length; k += 4) n += d[k] > 0; return n;")
        assert bars > 495, bars  # a bar of several pixels over each of the 495 UV pixels

        # the path grows while the walker moves, the stats update
        before = _state(browser)
        # waited for, not slept: on a loaded machine 1.5 s once passed without a new path point drawn
        def grown() -> bool:
            now = _state(browser)
            return all(now[key] > before[key] for key in ("path", "status", "stats", "frame"))

        _wait(grown, 30, "the path grows and the status, stats and frame update while the walker moves")
        # the path view adds the new poses to what it drew: the same path as drawing it all again, but where the
        # strokes' edges meet (drawn piece by piece, a joint is covered twice, and its anti-aliased fringe can cross
        # the colour threshold below a pixel further out: 1-2 such pixels in 2 of 6 full runs with a 1-pixel margin)
        incremental, whole = browser.execute_script(
            "drawPath(); const W = 360, a = pathCtx.getImageData(0, 0, W, W).data; pathBox = null; drawPath(); "
            "const b = pathCtx.getImageData(0, 0, W, W).data, blue = (d) => { const m = []; "
            "for (let k = 0; k < d.length; k += 4) m.push(d[k] < 150 && d[k + 2] > 120 ? 1 : 0); return m; }; "
            "return [blue(a), blue(b)];")
        incremental, whole = (np.asarray(m, bool).reshape(360, 360) for m in (incremental, whole))
        assert whole.sum() > 20, whole.sum()
        for this, other in ((incremental, whole), (whole, incremental)):
            near = np.zeros_like(other)  # within two pixels of the other picture's path
            for dy in (-2, -1, 0, 1, 2):
                for dx in (-2, -1, 0, 1, 2):
                    near |= np.roll(np.roll(other, dy, 0), dx, 1)
            assert (this & ~near).sum() == 0, f"{(this & ~near).sum()} path pixels not in the other picture"

        # the rig goes away: the page says so
        _stop(serve)
        _wait(lambda: "DISCONNECTED" in _state(browser)["conn"], 10, "the page shows the rig disconnected")
    finally:
        sub.undeclare()
        session.close()


def test_a_page_from_an_address_the_rig_does_not_allow_is_refused(browser, tmp_path):
    config = tmp_path / "rig.toml"
    config.write_text(f"""
[bus]
listen = ["{bus.free_tcp_endpoint()}"]
[monitor]
allow = ["192.168.10.0/24"]
""")
    monitor, url = _start_monitor(config)
    try:
        browser.get(url)
        text = browser.find_element("tag name", "body").text
        assert "address 127.0.0.1 may not open the monitor of rig 'rig1'; allowed: 192.168.10.0/24" in text, text
        status = browser.execute_async_script(
            "const done = arguments[0]; fetch('/cmd/trial_stop', {method: 'POST', body: '{}'})"
            ".then(r => r.text().then(t => done([r.status, t])));")
        assert status[0] == 403 and "may not open" in status[1]
    finally:
        _stop(monitor)


def test_page_commands_are_refused_unless_the_config_enables_them(browser, tmp_path):
    config = tmp_path / "rig.toml"
    config.write_text(f"""
[bus]
listen = ["{bus.free_tcp_endpoint()}"]
""")
    monitor, url = _start_monitor(config)
    try:
        browser.get(url)
        reply = browser.execute_async_script(
            "const done = arguments[0]; fetch('/cmd/rotate_scene', {method: 'POST', body: '{\"deg\": 90}'})"
            ".then(r => r.json().then(b => done([r.status, b])));")
        assert reply[0] == 403 and "commands from the page are off" in reply[1]["error"], reply
        assert not browser.find_element("id", "cmds").is_displayed()
        _wait(lambda: "DISCONNECTED" in _state(browser)["conn"], 10, "the page shows that no server runs")
    finally:
        _stop(monitor)
