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
    ('[render]\nface_size_px = 7\n', "[render] face_size_px = 7 is not a face size the renderer accepts; allowed: 16"),
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


def test_a_good_config_passes(tmp_path):
    config = resolve({"bus": {"listen": [f"tcp/127.0.0.1:{_free_port()}"]},
                      "render": {"scene": {"scene": "grating", "period_deg": 20}, "face_size_px": 64}})
    assert check_config(config) is config


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
