"""Starting the monitor: `antarium serve` says where its monitor serves the page, or why the monitor stopped; a port in
use is one line, not a traceback; a config that enables the monitor without the bus is refused."""

from __future__ import annotations

import errno
import socket
import subprocess
import sys
import urllib.request

import pytest
from conftest import wait_for

from antarium import bus
from antarium.config import ConfigError, resolve
from antarium.monitor.app import bind_error
from antarium.server import Server
from antarium.server.config_check import check_config


@pytest.fixture
def taken_port():
    """A loopback TCP port something else listens on."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


def test_a_port_in_use_is_one_line(tmp_path, taken_port):
    config = tmp_path / "rig.toml"
    config.write_text(f'[bus]\nlisten = ["{bus.free_tcp_endpoint()}"]\n')
    done = subprocess.run([sys.executable, "-m", "antarium", "monitor", "--config", str(config), "--port",
                           str(taken_port)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done
    assert done.stdout == "" and done.stderr == (
        f"antarium monitor: error: the page cannot be served on 127.0.0.1 port {taken_port}: in use (another "
        "monitor?); set [monitor] port (or --port; 0: any free port)\n"), done.stderr


def test_an_address_that_cannot_be_bound_names_the_host_setting(tmp_path):
    config = tmp_path / "rig.toml"
    config.write_text(f'[bus]\nlisten = ["{bus.free_tcp_endpoint()}"]\n')
    done = subprocess.run([sys.executable, "-m", "antarium", "monitor", "--config", str(config), "--host",
                           "999.1.1.1", "--port", "0"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "antarium monitor: error: the page cannot be served on 999.1.1.1 port 0: refused: "), done.stderr
    assert lines[0].endswith("; set [monitor] host (or --host) to an address of this computer (\"127.0.0.1\", "
                             "\"0.0.0.0\" for the lab network)"), done.stderr


def test_a_privileged_port_names_the_port_setting():
    assert bind_error(OSError(errno.EACCES, "Permission denied")) == (
        "refused: Permission denied (ports below 1024 need privileges); set [monitor] port (or --port; 0: any free "
        "port)")


def test_an_ipv6_page_address_is_printed_in_brackets(tmp_path):
    """The printed address opens the page: an IPv6 host in brackets (`http://[::1]:port/`, not `http://::1:port/`)."""
    with socket.socket(socket.AF_INET6) as probe:
        try:
            probe.bind(("::1", 0))
        except OSError:
            pytest.skip("this computer has no IPv6 loopback")
    config = tmp_path / "rig.toml"
    config.write_text(f'[bus]\nlisten = ["{bus.free_tcp_endpoint()}"]\n')
    proc = subprocess.Popen([sys.executable, "-m", "antarium", "monitor", "--config", str(config), "--host", "::1",
                             "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("antarium monitor: rig 'rig1' at http://[::1]:"), line
        url = line.split(" at ", 1)[1].split()[0]
        with urllib.request.urlopen(url, timeout=10) as page:
            assert "antarium monitor" in page.read().decode()
    finally:
        proc.terminate()
        proc.wait(30)
        proc.stdout.close()


def _serve(tmp_path, port: int):
    """`antarium serve`'s server (no renderer, no link) with the monitor on `port`; its echoed lines."""
    config = resolve({"rig": {"name": "tsay"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                      "loop": {"realtime_priority": 0, "cpu": "off"}, "log": {"dir": str(tmp_path)},
                      "monitor": {"enabled": True, "port": port}})
    lines: list[str] = []
    return Server(config, renderer_factory=None, link=False, echo=lines.append), lines


def test_serve_prints_where_its_monitor_serves_the_page(tmp_path):
    server, lines = _serve(tmp_path, 0)  # any free port: only the monitor's line says which
    with server.start_thread():
        assert wait_for(lambda: any(" at http://" in line for line in lines), 60.0), lines
        line = next(line for line in lines if " at http://" in line)
        assert line.startswith("antarium monitor: rig 'tsay' at http://127.0.0.1:"), line
        url = line.split(" at ", 1)[1].split()[0]
        with urllib.request.urlopen(url, timeout=10) as page:
            assert "antarium monitor" in page.read().decode()
        server.stop()


def test_serve_says_when_its_monitor_ends_while_it_runs(tmp_path):
    """A monitor killed (or crashed) after it listened is told once, not left unnoticed; a server that stops its
    monitor says nothing more."""
    server, lines = _serve(tmp_path, 0)
    with server.start_thread():
        assert wait_for(lambda: any(" at http://" in line for line in lines), 60.0), lines
        server.monitor.child.proc.kill()
        assert wait_for(lambda: any("the monitor stopped while" in line for line in lines), 30.0), lines
        server.stop()
    said = [line for line in lines if "the monitor stopped" in line]
    assert said == ["antarium serve: the monitor stopped while the server runs (exit code -9): it printed nothing "
                    "more; the server goes on without it (its page is gone)"], lines


def test_serve_says_why_its_monitor_stopped(tmp_path, taken_port):
    server, lines = _serve(tmp_path, taken_port)
    with server.start_thread():
        assert wait_for(lambda: any("monitor" in line for line in lines), 60.0), lines
        server.stop()
    said = [line for line in lines if "monitor" in line]
    assert said == [f"antarium serve: the monitor stopped at its start (exit code 2): antarium monitor: error: the "
                    f"page cannot be served on 127.0.0.1 port {taken_port}: in use (another monitor?); set [monitor] "
                    "port (or --port; 0: any free port)"], lines


def test_the_monitor_without_the_bus_is_refused():
    with pytest.raises(ConfigError, match=r"^\[monitor\] enabled = true needs the bus, but \[bus\] enabled = false: "
                                          r"the monitor shows the rig's bus streams; enable \[bus\] or set \[monitor\] "
                                          r"enabled = false$"):
        check_config(resolve({"bus": {"enabled": False}, "monitor": {"enabled": True}}))
    check_config(resolve({"bus": {"enabled": False}}))  # the monitor off: no bus needed
