"""`antarium servosphere`: the simulated live loop, its summary and picture; bad arguments get one clear line."""

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
