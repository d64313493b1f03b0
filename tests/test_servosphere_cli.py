"""`antarium servosphere`: the simulated live loop, its summary and picture; bad arguments get one clear line."""

import re

from antarium.cli import main


def test_simulated_run_prints_a_summary_and_writes_the_picture(tmp_path, capsys):
    out = tmp_path / "servo.png"
    assert main(["servosphere", "--simulate", "--seconds", "0.6", "--plot", str(out)]) == 0
    captured = capsys.readouterr()
    assert "frames 421, control loop 70" in captured.out and "error from the apex: median" in captured.out
    assert "% of the distance" in captured.out and out.stat().st_size > 10_000
    assert "\rt " in captured.err and "x real time" in captured.err  # the live status line


def test_bad_arguments_name_what_is_wrong(capsys):
    assert main(["servosphere", "--seconds", "1"]) == 2
    assert "--config" in capsys.readouterr().err
    assert main(["servosphere", "--simulate", "--seconds", "-1"]) == 2
    assert "--seconds must be a positive number" in capsys.readouterr().err
    assert main(["servosphere", "--simulate", "--seconds", "1", "--slip", "0.9"]) == 2
    assert "slip must be in [0, 0.5]" in capsys.readouterr().err


def test_a_config_is_checked_with_its_loop_as_antarium_serve_checks_it(tmp_path, capsys):
    """[loop] ball_radius_m and tether reach the source: a second radius, or a tether that does not fit
    counter_rotate, is refused as `antarium serve` refuses it."""
    for loop, message in [("ball_radius_m = 0.10", "sphere_radius 0.06 m differs from the loop's ball_radius 0.1 m"),
                          ('tether = "fixed"', "tether 'fixed' with counter_rotate false")]:
        config = tmp_path / "rig.toml"
        config.write_text(f'[rig]\nname = "r10"\n[loop]\n{loop}\n[locomotion]\nsource = "servosphere"\n'
                          'camera = "simulated"\nlink = "simulated"\nrotors = { sphere_radius = 0.06 }\n')
        assert main(["servosphere", "--config", str(config), "--seconds", "0.05"]) == 2
        assert message in capsys.readouterr().err


def _config(tmp_path, locomotion):
    config = tmp_path / f"rig{len(list(tmp_path.glob('rig*.toml')))}.toml"
    config.write_text('[rig]\nname = "r10"\n[loop]\nball_radius_m = 0.06\n[locomotion]\nsource = "servosphere"\n'
                      f'camera = "simulated"\nlink = "simulated"\n{locomotion}\n')
    return str(config)


def test_a_run_where_no_ant_is_ever_seen_says_so(tmp_path, capsys):
    """An ant area that no blob fits: every frame is no_ant; the summary says so instead of failing."""
    out = tmp_path / "servo.png"
    config = _config(tmp_path, "area_mm2 = [100, 200]")
    assert main(["servosphere", "--config", config, "--seconds", "0.1", "--plot", str(out)]) == 0
    captured = capsys.readouterr().out
    frames = re.search(r"frames (\d+),", captured)
    assert frames and int(frames[1]) > 0, captured
    # every frame is no_ant (how many frames 0.1 s holds depends on the machine: 69 on a slow day)
    assert "no ant tracked" in captured and f"'no_ant': {frames[1]}," in captured and not out.exists()


def test_options_that_would_be_ignored_are_refused(tmp_path, capsys):
    config = _config(tmp_path, "kp = 0.2")
    for args, message in [
        (["--simulate", "--config", str(tmp_path / "no_such.toml")], "--simulate and --config exclude each other"),
        (["--config", config, "--speed", "0.2"], "--speed is a --simulate option; allowed without --simulate"),
        (["--config", config, "--slip", "0.1"], "--slip is a --simulate option"),
        (["--config", config, "--seed", "3"], "--seed is a --simulate option"),
        (["--config", config, "--realtime"], "--realtime is a --simulate option"),
        (["--config", _config(tmp_path, 'port = "/dev/ttyACM9"')], "option port is for a real rig"),
        (["--config", _config(tmp_path, "camera_index = 3")], "option camera_index is for a real rig"),
        (["--config", _config(tmp_path, "baudrate = 9600")], "option baudrate is for a real rig"),
        (["--config", _config(tmp_path, "calibration = { apex_px = [10, 10], mm_per_px = 5.0 }")],
         "option calibration is for a real rig; the simulated rig calibrates itself"),
    ]:
        assert main(["servosphere", *args, "--seconds", "0.05"]) == 2, args
        assert message in capsys.readouterr().err, args


def test_simulation_options_with_a_real_rig_are_refused():
    import pytest

    from antarium.core.clock import SimulatedClock
    from antarium.locomotion.servosphere.source import ServosphereSource

    with pytest.raises(ValueError, match="simulation options are for the simulated rig.*allowed with a real rig"):
        ServosphereSource(camera="opencv", link="serial", port="loop://", simulation={"speed": 0.2},
                          calibration={"apex_px": [320, 240], "mm_per_px": 0.06}, clock=SimulatedClock())
