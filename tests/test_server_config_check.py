"""`check_config`: `serve` and `serve --print-config` refuse what would fail only once the server runs, in one
line naming the key and what is allowed, before anything starts (issue 20, points 3 and 7)."""

import socket

import pytest

from antarium.cli import main
from antarium.config import ConfigError, resolve
from antarium.server.config_check import check_config


def _write(tmp_path, text: str) -> str:
    path = tmp_path / "rig.toml"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("toml, message", [
    ('[render]\nscene = "habitatt"\n', "scene 'habitatt' is not a known scene or a scene file; allowed: habitat"),
    ('[render]\nscene = "/nonexistent/world.glb"\n', "[render] scene file '/nonexistent/world.glb' (path) does not"),
    ('[render]\nscene = {scene = "horizon", panorama = "/no/pano.png"}\n', "(panorama) does not exist"),
    ('[locomotion]\nsource = "scriptd"\n', "[locomotion] source 'scriptd' is unknown; allowed: ant, bus, fictrac"),
    ('[loop]\nrate_hz = 192.0\n', "[loop] rate_hz = 192 leaves no room on the 100 Mbit/s dome link ([link] "
     "speed_mbit_s) for a polariser update (the polarisers would never move); allowed: at most 191.1 frames/s"),
    ('[loop]\nrate_hz = 1920.0\n[link]\nspeed_mbit_s = 1000\n', "[loop] rate_hz = 1920 leaves no room on the 1000 "
     "Mbit/s dome link ([link] speed_mbit_s) for a polariser update (the polarisers would never move); allowed: at "
     "most 1911.2 frames/s"),
    ('[render]\nface_size_px = 7\n', "[render] face_size_px = 7 is not a face size the renderer accepts; allowed: 55"),
    ('[locomotion]\nsource = "scripted"\nsped = 0.03\n',
     "[locomotion] source 'scripted' has no option 'sped'; allowed: ball_radius, clock, duration, heading_deg, "
     "meander, path, pause_fraction, rate_hz, seed, speed, spurt_s, tether, turn_rate"),
    ('[locomotion]\nsource = "scripted"\nspeed = 5.0\n',
     "[locomotion] scripted source speed must be a number in [0.0, 2.0], got 5.0"),
    ('[locomotion]\nsource = "usb"\nemulate = true\n[trackball]\nsample_rate_hz = 5000\n',
     "[trackball] sample_rate_hz must be in [1, 1000], got 5000"),
    ('[locomotion]\nsource = "fictrac"\nmax_match_error = 0\n', "[locomotion] FicTrac max_match_error must be a "
     "finite number > 0"),
    ('[loop]\ntether = "fixed"\n[locomotion]\nsource = "scripted"\nheading_deg = 90.0\n',
     "[locomotion] scripted source heading_deg applies to the free_yaw tether only"),
    ('[link]\nhost = "192.168.55.256"\nport = 19055\nspawn_emulator = false\n',
     "[link] host '192.168.55.256' is not an IP address; allowed: the distributor's IP address"),
    ('[link]\nhost = "no-such-board.invalid"\nport = 19055\nspawn_emulator = false\n',
     "[link] host 'no-such-board.invalid' is not an IP address and does not resolve as a host name"),
])
@pytest.mark.parametrize("print_config", [True, False])
def test_serve_refuses_a_config_it_could_not_run_before_anything_starts(tmp_path, capsys, toml, message,
                                                                        print_config):
    args = ["serve", "--config", _write(tmp_path, toml)] + (["--print-config"] if print_config else [])
    assert main(args) == 2
    out, err = capsys.readouterr()
    assert out == ""  # no start banner, no config printed
    assert err.count("\n") == 1 and message in err


def test_a_bus_port_in_use_is_named_with_what_to_do(tmp_path, capsys):
    with socket.socket() as other:  # another server holding the port
        other.bind(("127.0.0.1", 0))
        other.listen()
        port = other.getsockname()[1]
        with pytest.raises(ConfigError, match=rf"\[bus\] listen endpoint tcp/127.0.0.1:{port} is in use .*"
                                              r"set \[bus\] listen to another port, or stop the other server"):
            check_config(resolve({"bus": {"listen": [f"tcp/127.0.0.1:{port}"]}}))
        assert main(["serve", "--config", _write(tmp_path, f'[bus]\nlisten = ["tcp/127.0.0.1:{port}"]\n')]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "is in use" in err


def test_print_config_checks_the_file_not_the_ports_a_running_server_holds(tmp_path, capsys):
    with socket.socket() as other:  # the rig's own server, running
        other.bind(("127.0.0.1", 0))
        other.listen()
        endpoint = f"tcp/127.0.0.1:{other.getsockname()[1]}"
        assert main(["serve", "--config", _write(tmp_path, f'[bus]\nlisten = ["{endpoint}"]\n'), "--print-config"]) == 0
    out, err = capsys.readouterr()
    assert err == "" and f'listen = [\n    "{endpoint}",\n]' in out


def test_the_locomotion_options_are_checked_without_starting_the_source(tmp_path):
    ball = tmp_path / "ball.toml"
    ball.write_text("[trackball]\nsample_rate_hz = 500\n")
    for locomotion in ({"source": "scripted", "speed": 0.03, "heading_deg": 90.0, "duration": 10.0},
                       {"source": "usb", "trackball": str(ball)},  # no device: building the driver opens nothing
                       {"source": "fictrac", "port": 0, "max_match_error": 0.5, "timeout_s": 2.0}):
        config = resolve({"bus": {"enabled": False}, "locomotion": locomotion})
        assert check_config(config) is config and config.locomotion.options == {
            k: v for k, v in locomotion.items() if k != "source"}  # not changed by the check
    ball.write_text("[trackball]\nsample_rate_hz = 5000\n")
    with pytest.raises(ConfigError, match=r"^\[trackball\] sample_rate_hz must be in \[1, 1000\], got 5000$"):
        check_config(resolve({"bus": {"enabled": False}, "locomotion": {"source": "usb", "trackball": str(ball)}}))


def test_a_good_config_passes(tmp_path):
    config = resolve({"bus": {"listen": [f"tcp/127.0.0.1:{_free_port()}"]},
                      "render": {"scene": {"scene": "grating", "period_deg": 20}, "face_size_px": 64}})
    assert check_config(config) is config


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_link_budget_follows_the_configured_line_rate(tmp_path):
    """`[link] speed_mbit_s`: the frame loop's polariser budget is that link's (a gigabit distributor carries an
    update in every period at 190 frames/s, where the board's 100 Mbit/s defers about one in seven)."""
    from antarium.config import LinkSection
    from antarium.firmware_proto.budget import DEFAULT_LINK_BPS
    from antarium.server.server import Server

    assert LinkSection().speed_mbit_s * 1e6 == DEFAULT_LINK_BPS
    check_config(resolve({"loop": {"rate_hz": 192.0}, "link": {"speed_mbit_s": 1000.0}}), ports=False)
    for speed, deferred in ((100.0, True), (1000.0, False)):
        config = resolve({"link": {"interface": "virtual", "speed_mbit_s": speed}, "bus": {"enabled": False},
                          "log": {"dir": str(tmp_path / "trials")}})
        server = Server(config, renderer_factory=None, echo=lambda line: None)
        server.run(seconds=0.0)
        budget = server.loop.link_budget
        assert budget.period_bits == pytest.approx(speed * 1e6 / 190.0)
        for _ in range(70):  # an update every period, as when the angles change every frame
            sent = budget.update_fits()
            budget.deferred += not sent
            budget.period(sent)
        assert (budget.deferred > 0) == deferred
    with pytest.raises(ConfigError, match=r"\[link\] speed_mbit_s"):
        resolve({"link": {"speed_mbit_s": 0.5}})
