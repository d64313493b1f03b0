"""One error path for every command: bad input, files, ports, the bus -> one line `antarium CMD: error: ...`, exit
status 2, nothing written and no work done first; `--debug` shows the traceback instead."""

from __future__ import annotations

import argparse
import errno
import socket
import subprocess
import sys

import pytest

from antarium.cli import build_parser, main
from antarium.config import ConfigError


def _one_line(capsys, command: str) -> str:
    """The one error line of `command` (and nothing on stdout: no work was done before the refusal)."""
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"antarium {command}: error: "), err
    assert "Traceback" not in err and out == ""
    return lines[0]


@pytest.fixture
def fake_png(tmp_path):
    """A file where a folder is expected (the reviewer's fake.png)."""
    path = tmp_path / "fake.png"
    path.write_bytes(b"not a folder")
    return path


# --- item 1: one error path, --debug -----------------------------------------------------------------------------

def test_a_config_that_is_a_folder_is_one_line(tmp_path, capsys):
    assert main(["serve", "--config", str(tmp_path), "--print-config"]) == 2
    assert "is a folder; give a file" in _one_line(capsys, "serve")


def test_a_config_below_a_file_is_one_line(fake_png, capsys):
    assert main(["serve", "--config", str(fake_png / "rig.toml"), "--print-config"]) == 2
    assert "is a file, not a folder" in _one_line(capsys, "serve")


@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_before_or_after_the_command_shows_the_traceback(tmp_path, where):
    args = ["serve", "--config", str(tmp_path)]
    with pytest.raises(ConfigError, match="is a folder") as raised:
        main(["--debug", *args] if where == "before" else [*args, "--debug"])
    assert isinstance(raised.value.__cause__, IsADirectoryError)  # in the traceback --debug shows


def test_debug_is_in_the_help():
    assert "--debug" in build_parser().format_help()


def _zerror():
    import zenoh

    return zenoh.ZError("Can not create a new TCP listener at /root/.cargo/git/x/src/lib.rs:62.")


ERRORS = {
    "permission": (lambda: PermissionError(errno.EACCES, "Permission denied", "/root/x.json"), "Permission denied"),
    "exists": (lambda: FileExistsError(errno.EEXIST, "File exists", "trials/t1"), "File exists"),
    "not a folder": (lambda: NotADirectoryError(errno.ENOTDIR, "Not a directory", "a.png/b"), "not a folder"),
    "address": (lambda: socket.gaierror(socket.EAI_NONAME, "Name or service not known"), "address not found"),
    "port": (lambda: OverflowError("bind(): port must be 0-65535."), "0..65535"),
    "zenoh": (_zerror, "bus (zenoh): Can not create a new TCP listener"),
    "numpy number": (lambda: ValueError("period must be > 0, got np.float64(-20.0)"), "got -20.0"),
}


@pytest.mark.parametrize("kind", ERRORS)
def test_errors_of_every_kind_are_one_line_with_status_2(kind, monkeypatch, capsys):
    make, shown = ERRORS[kind]

    def run(args):
        raise make()

    monkeypatch.setattr("antarium.commands.scene.run", run)
    assert main(["scene", "habitat"]) == 2
    line = _one_line(capsys, "scene")
    assert shown in line and ".rs:" not in line and "np.float64" not in line and "Errno" not in line
    with pytest.raises(type(make())):
        main(["--debug", "scene", "habitat"])


def test_the_error_path_does_not_import_zenoh():
    code = ("import sys; from antarium.cli import main; "
            "assert main(['scene', 'habitat', '--seed', '-1']) == 2; print('zenoh' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.stdout.strip() == "False", done.stderr


def test_bench_jitter_refuses_too_much_work_like_every_command(capsys):
    assert main(["bench", "jitter", "--work-ms", "100"]) == 2
    assert "--work-ms must be in [0, " in _one_line(capsys, "bench")


# --- item 2: outputs checked before the work ---------------------------------------------------------------------

def test_bench_json_below_a_file_is_refused_before_the_benchmark(fake_png, capsys):
    assert main(["bench", "protocol", "--frames", "20", "--json", str(fake_png / "x.json")]) == 2
    assert "--json" in _one_line(capsys, "bench")  # _one_line: nothing on stdout, the benchmark did not run


def test_servosphere_plot_below_a_file_is_refused_before_the_run(fake_png, capsys):
    assert main(["servosphere", "--simulate", "--seconds", "2", "--plot", str(fake_png / "p.png")]) == 2
    assert "--plot" in _one_line(capsys, "servosphere")


@pytest.mark.parametrize("args", [["habitat", "--out", "{fake}/x.png"],
                                  ["uniform", "--cube", "{fake}/c.png", "--out", "{tmp}/ok.png"]])
def test_render_outputs_below_a_file_are_refused_before_anything_is_written(args, tmp_path, fake_png, capsys):
    assert main(["render", *(a.format(fake=fake_png, tmp=tmp_path) for a in args)]) == 2
    assert "is a file, not a folder" in _one_line(capsys, "render")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fake.png"]  # no ok.png


@pytest.mark.parametrize("command", [["layout", "--out"], ["demo", "--out"]])
def test_an_output_folder_that_is_a_file_is_refused_before_the_work(command, fake_png, capsys):
    assert main([*command, str(fake_png)]) == 2
    assert "is a file, not a folder" in _one_line(capsys, command[0])


def test_demo_out_the_system_refuses_is_named_before_the_work(monkeypatch, capsys):
    """/proc/x passes a permission check as root, and no folder can be made there: said first, naming --out."""
    monkeypatch.setattr("antarium.commands.layout.run", lambda args: pytest.fail("the demo's work began"))
    assert main(["demo", "--out", "/proc/antarium-demo-out"]) == 2
    assert "--out '/proc/antarium-demo-out': " in _one_line(capsys, "demo")


def test_layout_out_the_system_refuses_is_named_before_the_work(capsys):
    """The same for `layout --out` (its summary was printed, then the pictures failed without naming --out)."""
    assert main(["layout", "--out", "/proc/antarium-layout-out"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert "--out '/proc/antarium-layout-out': cannot make the folder" in err


def test_layout_export_below_a_file_says_so(fake_png, capsys):
    assert main(["layout", "--export", str(fake_png / "leds.csv")]) == 2
    line = _one_line(capsys, "layout")
    assert "is a file, not a folder" in line and "does not exist" not in line


def test_scene_out_that_is_a_folder_is_refused_before_the_habitat_is_built(tmp_path, capsys, monkeypatch):
    (tmp_path / "d.glb").mkdir()
    monkeypatch.setattr("antarium.renderers.habitat.habitat_objects", lambda **kw: pytest.fail("habitat built"))
    assert main(["scene", "habitat", "--out", str(tmp_path / "d.glb")]) == 2
    assert "is a folder" in _one_line(capsys, "scene")


# --- item 3: ports ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("port", ["70000", "-1"])
def test_emulate_refuses_a_port_out_of_range(port, capsys):
    assert main(["emulate", "--port", port, "--seconds", "0.1"]) == 2
    assert f"--port must be an integer >= 0 and <= 65535, got {port}" in _one_line(capsys, "emulate")


# --- items 4, 5: the config check, the same for --print-config ----------------------------------------------------

CONFIGS = {
    "garbage endpoint": ('[bus]\nlisten = ["garbage"]\n', "[bus] listen 'garbage' is not a zenoh endpoint"),
    "endpoint port": ('[bus]\nconnect = ["tcp/127.0.0.1:70000"]\n', "[bus] connect"),
    "trackball key": ("[trackball]\nvendr_id = 5\n", "['vendr_id'] in [trackball]"),
    "scene parameter": ('[render]\nscene = {scene = "grating", period_deg = -20}\n', "degrees, got -20"),
}


@pytest.mark.parametrize("kind", CONFIGS)
def test_print_config_refuses_what_the_start_would(kind, tmp_path, capsys):
    text, shown = CONFIGS[kind]
    path = tmp_path / "rig.toml"
    path.write_text('[rig]\nname = "cli"\n' + text)
    assert main(["serve", "--config", str(path), "--print-config"]) == 2
    line = _one_line(capsys, "serve")
    assert shown in line and "np.float64" not in line and ".rs:" not in line


def test_endpoint_message_says_what_is_allowed(tmp_path, capsys):
    path = tmp_path / "rig.toml"
    path.write_text('[bus]\nlisten = ["garbage"]\n')
    assert main(["serve", "--config", str(path), "--print-config"]) == 2
    assert "allowed: PROTOCOL/HOST:PORT with PROTOCOL one of tcp" in _one_line(capsys, "serve")


@pytest.mark.parametrize("endpoint", ["tcp/127.0.0.1:7447", "udp/0.0.0.0:0", "tcp/[::1]:7447", "tcp/localhost:0",
                                      "tcp/192.168.1.10:7447#iface=eth0", "unixsock-stream//tmp/antarium.sock"])
def test_good_endpoints_pass(endpoint):
    from antarium.config import BusSection

    assert BusSection.read({"listen": [endpoint], "connect": [endpoint]}).listen == [endpoint]


# --- item 6: outputs without their extension, the shipped layout --------------------------------------------------

@pytest.fixture
def no_layout_search(monkeypatch):
    """The layout search and its writer must not run (a refusal comes first)."""
    monkeypatch.setattr("antarium.geometry.generate_layout", lambda *a, **k: pytest.fail("layout search ran"))
    monkeypatch.setattr("antarium.geometry.layout.save_layout", lambda *a, **k: pytest.fail("layout written"))


def test_regenerate_without_layout_out_does_not_touch_the_shipped_layout(no_layout_search, capsys):
    assert main(["layout", "--regenerate", "--no-pictures"]) == 2
    assert "--regenerate needs --layout-out" in _one_line(capsys, "layout")


def test_layout_out_without_npz_is_refused_before_the_search(no_layout_search, tmp_path, capsys):
    assert main(["layout", "--regenerate", "--layout-out", str(tmp_path / "lnoext")]) == 2
    assert "--layout-out file must end in .npz, got 'lnoext'" in _one_line(capsys, "layout")
    assert list(tmp_path.iterdir()) == []


def test_servosphere_plot_without_png_is_refused_before_the_run(tmp_path, capsys):
    assert main(["servosphere", "--simulate", "--seconds", "2", "--plot", str(tmp_path / "p")]) == 2
    assert "--plot file must end in .png, got 'p'" in _one_line(capsys, "servosphere")
    assert list(tmp_path.iterdir()) == []


# --- item 7: messages name the option and show plain numbers -------------------------------------------------------

@pytest.mark.parametrize("args, shown", [
    (["scene", "habitat", "--seed", "-1"], "--seed must be an integer >= 0, got -1"),
    (["servosphere", "--simulate", "--seed", "-1"], "--seed must be an integer >= 0, got -1"),
    (["servosphere", "--simulate", "--slip", "0.9"], "--slip: "),
    (["render", "habitat", "--heading", "inf"], "--heading (degrees) must be a finite number, got inf"),
    (["render", "grating", "--set", "period_deg=-20"], "got -20 (scene"),
    (["render", "uniform", "--face-size", "20"], "--face-size (cube face_size, texels) must be an integer >= "),
])
def test_messages_name_the_option_and_show_plain_numbers(args, shown, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(args) == 2
    line = _one_line(capsys, args[0])
    assert shown in line and "np." not in line and "metres or radians" not in line
    assert list(tmp_path.iterdir()) == []


# --- item 8: help texts ---------------------------------------------------------------------------------------------

def _options(command: str) -> dict[str, argparse.Action]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices[command]
    return {s: a for a in sub._actions for s in a.option_strings}


MINE = ("bench", "demo", "emulate", "layout", "render", "scene", "servosphere")


@pytest.mark.parametrize("command", MINE)
def test_options_with_a_default_say_it(command):
    missing = [s for s, a in _options(command).items()
               if a.default not in (None, False, [], argparse.SUPPRESS) and "default" not in (a.help or "")]
    assert missing == []


@pytest.mark.parametrize("command, option, words", [
    ("render", "--out", ("view.png", "overwrit")),
    ("render", "--time", ("seconds", "default")),
    ("render", "--face-size", ("texels", "2048")),
    ("emulate", "--line", ("default",)),
    ("servosphere", "--slip", ("0..0.5",)),
    ("layout", "--layout-out", ("needed",)),
])
def test_help_gives_units_ranges_and_defaults(command, option, words):
    action = _options(command)[option]
    text = action.help % {**vars(action), "prog": f"antarium {command}"}  # as argparse shows it
    assert all(w in text for w in words), text
