"""The [trackball] config section and the calibration procedure (pure and end to end on the emulated device)."""

import tomllib
from dataclasses import replace

import numpy as np
import pytest

from antarium.cli import main
from antarium.locomotion.trackball import calibration
from antarium.locomotion.trackball import config as tbconfig
from antarium.locomotion.trackball.driver import UsbTrackball

OTHER = """
[rig]
name = "lab2"

[bus]
listen = ["tcp/127.0.0.1:7999"]

[monitor]
allow = ["127.0.0.1/32", "10.1.2.0/24", "::1/128"]
"""


def test_defaults_and_round_trip():
    c = tbconfig.parse_section({})
    assert c == tbconfig.TrackballConfig()
    assert c.sensors[1].azimuth_deg == 90.0 and c.metres_per_count() == pytest.approx([1e-3 / (1200 / 25.4)] * 4)
    assert tbconfig.parse_section(tbconfig.to_section(c)) == c


@pytest.mark.parametrize("section, match", [
    ({"vendorid": 1}, "unknown key"),
    ({"vendor_id": 0x10000}, r"vendor_id must be in"),
    ({"ball_radius": "5cm"}, "ball_radius must be a finite number"),
    ({"sample_rate_hz": 2000}, "sample_rate_hz"),
    ({"sensors": [{"azimuth_deg": 0}]}, "2 \\[\\[trackball.sensors\\]\\]"),
    ({"sensors": [{"azimuth_deg": 0}, {"elevation_deg": 3}]}, "needs azimuth_deg"),
    ({"sensors": [{"azimuth_deg": 0, "signs": [1, 0]}, {"azimuth_deg": 90}]}, "signs must be"),
    ({"sensors": [{"azimuth_deg": 0, "counts_per_mm": [40]}, {"azimuth_deg": 90}]}, "counts_per_mm must be two"),
    ({"sensors": [{"azimuth_deg": 0}, {"azimuth_deg": 0}]}, "cannot resolve"),
])
def test_bad_sections_name_the_key(section, match):
    with pytest.raises(tbconfig.TrackballConfigError, match=match):
        tbconfig.parse_section(section)


def test_write_section_keeps_other_sections(tmp_path):
    rig = tmp_path / "rig.toml"
    rig.write_text(OTHER + "\n[trackball]\nvendor_id = 0x1234\n")
    c = tbconfig.load(rig)
    assert c.vendor_id == 0x1234
    new = replace(c, sensors=(replace(c.sensors[0], counts_per_mm=(40.5, 41.5), signs=(1, -1)), c.sensors[1]))
    tbconfig.write_section(rig, new)
    doc = tomllib.loads(rig.read_text())
    assert doc["rig"] == {"name": "lab2"} and doc["monitor"] == {"allow": ["127.0.0.1/32", "10.1.2.0/24", "::1/128"]}
    assert doc["bus"] == {"listen": ["tcp/127.0.0.1:7999"]}
    assert tbconfig.load(rig) == new


def test_load_errors(tmp_path):
    """The rig file is read as `antarium.config` reads it: one ConfigError line naming the file."""
    from antarium.config import ConfigError

    with pytest.raises(ConfigError, match="not found"):
        tbconfig.load(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[trackball\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        tbconfig.load(bad)
    latin1 = tmp_path / "latin1.toml"
    latin1.write_bytes("# caf\xe9\n[trackball]\n".encode("latin-1"))  # a UnicodeDecodeError naming no file before
    with pytest.raises(ConfigError, match=r"latin1.toml' is not UTF-8 text \(byte 0xe9 at line 1\)"):
        tbconfig.load(latin1)
    with pytest.raises(tbconfig.TrackballConfigError, match="a rig file's path or a \\[trackball\\] table, got 5"):
        tbconfig.load(5)  # [locomotion] trackball = 5: a TypeError of os.fspath before


def test_calibrate_from_synthetic_counts():
    c = tbconfig.TrackballConfig()
    true_cpmm = np.array([45.0, 50.0, 39.0, 61.0])
    true_sign = np.array([1, -1, -1, 1])
    steps = []
    for axis in ("z", "x", "y"):
        travel_mm = calibration.predicted_travel(c, axis, 2.0) * 1e3
        steps.append(calibration.Step(axis, 2.0, tuple(int(round(v)) for v in travel_mm * true_cpmm * true_sign)))
    result = calibration.calibrate(c, steps)
    got = [v for s in result.config.sensors for v in s.counts_per_mm]
    np.testing.assert_allclose(got, true_cpmm, rtol=1e-4)
    assert [g for s in result.config.sensors for g in s.signs] == list(true_sign)
    assert result.estimates["x0"] and len(result.estimates["x0"]) == 1  # only the turn about z moves x0


def test_calibration_refuses_incomplete_or_dead_data():
    c = tbconfig.TrackballConfig()
    z = calibration.Step("z", 1.0, (14000, 0, 14000, 0))
    with pytest.raises(calibration.CalibrationError, match=r"\['y0', 'y1'\] were not calibrated"):
        calibration.calibrate(c, [z])
    dead = calibration.Step("x", 1.0, (0, 0, 0, 3))
    with pytest.raises(calibration.CalibrationError, match="y1 counted only 3"):
        calibration.calibrate(c, [z, dead])
    with pytest.raises(calibration.CalibrationError, match="axis must be one of"):
        calibration.calibrate(c, [calibration.Step("w", 1.0, (0, 0, 0, 0))])


def test_end_to_end_on_the_emulated_device_recovers_its_lens():
    config = tbconfig.TrackballConfig()
    backend = calibration.miscalibrated_emulator(config, realtime=False)
    with UsbTrackball(trackball=config, backend=backend) as driver:
        driver.wait_connected(5.0)
        steps = [calibration.Step(a, 1.0, tuple(calibration.turn_emulated(driver, backend, a, 1.0)))
                 for a in ("z", "x", "y")]
    result = calibration.calibrate(config, steps)
    expected = [47.244094 * f for f in calibration.EMULATED_CPMM_FACTORS]
    got = [v for s in result.config.sensors for v in s.counts_per_mm]
    np.testing.assert_allclose(got, expected, rtol=1e-3)
    assert [g for s in result.config.sensors for g in s.signs] == list(calibration.EMULATED_SIGN_FLIP)
    assert max(result.spread().values()) < 1e-3


COMMENTED = """# the lab's rig: keep these notes
[rig]
name = "lab2"   # bus prefix

[bus]
listen = [ "tcp/127.0.0.1:7999",   # loopback only
]

[trackball]
vendor_id = 0x1209   # pid.codes
ball_radius = 0.05

[[trackball.sensors]]   # front sensor
azimuth_deg = 0.0
counts_per_mm = [ 47.0,
  47.5 ]   # measured 2024
signs = [1, 1]

[[trackball.sensors]]   # left sensor
azimuth_deg = 90.0
# counts_per_mm left at its default
signs = [1, 1]  # mounting

[log]
dir = "trials"   # trailing notes
"""


def _calibrated(config):
    cpmm = ((50.5, 44.25), (48.125, 42.0))
    signs = ((1, 1), (1, -1))
    return replace(config, sensors=tuple(replace(s, counts_per_mm=c, signs=g)
                                         for s, c, g in zip(config.sensors, cpmm, signs, strict=True)))


def test_write_section_changes_only_the_calibration_and_keeps_every_other_byte(tmp_path):
    rig = tmp_path / "rig.toml"
    rig.write_text(COMMENTED)
    new = _calibrated(tbconfig.load(rig))
    assert tbconfig.write_section(rig, new) is None  # edited in place: no backup needed
    expected = (COMMENTED.replace("counts_per_mm = [ 47.0,\n  47.5 ]   # measured",
                                  "counts_per_mm = [50.5, 44.25]   # measured")
                .replace("[[trackball.sensors]]   # left sensor\n",
                         "[[trackball.sensors]]   # left sensor\ncounts_per_mm = [48.125, 42.0]\n")
                .replace("signs = [1, 1]  # mounting", "signs = [1, -1]  # mounting"))
    assert rig.read_text() == expected
    assert tbconfig.load(rig) == new and not (tmp_path / "rig.toml.bak").exists()


def test_write_section_appends_sensor_tables_to_a_file_without_them(tmp_path):
    rig = tmp_path / "rig.toml"
    text = OTHER.replace("[rig]", "# notes\n[rig]") + "[trackball]   # ours\nvendor_id = 0x1234"  # no final newline
    rig.write_text(text)
    new = _calibrated(tbconfig.load(rig))
    assert tbconfig.write_section(rig, new) is None
    assert rig.read_text().startswith(text + "\n") and tbconfig.load(rig) == new


def test_write_section_backs_up_a_file_it_cannot_edit_in_place(tmp_path):
    rig = tmp_path / "rig.toml"
    inline = OTHER + '\n[trackball]\nsensors = [{azimuth_deg = 0.0}, {azimuth_deg = 90.0}]  # inline\n'
    rig.write_text(inline)
    new = _calibrated(tbconfig.load(rig))
    backup = tbconfig.write_section(rig, new)
    assert backup == tmp_path / "rig.toml.bak" and backup.read_text() == inline
    assert tbconfig.load(rig) == new and tomllib.loads(rig.read_text())["monitor"]["allow"][1] == "10.1.2.0/24"


def test_cli_calibrate_writes_the_rig_config_keeping_its_comments(tmp_path, capsys, emulated_hands):
    """Without --emulate (the driver's USB backend replaced by the miscalibrated emulator, the operator's turns by
    the emulated ones) the results go into the file; its comments stay."""
    rig = tmp_path / "rig.toml"
    rig.write_text(COMMENTED)
    assert main(["trackball", "calibrate", "--config", str(rig), "--turns", "0.25"]) == 0
    out = capsys.readouterr().out
    assert "every other line is unchanged" in out
    text = rig.read_text()
    assert "# measured 2024" in text and "# the lab's rig: keep these notes" in text and "# mounting" in text
    cpmm = [v for s in tbconfig.load(rig).sensors for v in s.counts_per_mm]
    expected = [47.0 * 1.06, 47.5 * 0.94, 47.244094 * 1.03, 47.244094 * 0.91]
    np.testing.assert_allclose(cpmm, expected, rtol=5e-3)
    assert main(["trackball", "calibrate", "--config", str(rig), "--axes", "q"]) == 2
    assert rig.read_text() == text  # the failed run changed nothing


def test_cli_calibrate_emulate_never_writes_a_rig_config(tmp_path, capsys):
    rig = tmp_path / "rig.toml"
    rig.write_text(COMMENTED)
    assert main(["trackball", "calibrate", "--emulate", "--config", str(rig), "--turns", "0.25"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--emulate" in err and "--dry-run" in err
    assert main(["trackball", "calibrate", "--emulate", "--dry-run", "--config", str(rig), "--turns", "0.25"]) == 0
    assert "dry run: rig config not changed" in capsys.readouterr().out
    assert rig.read_text() == COMMENTED and not (tmp_path / "rig.toml.bak").exists()


@pytest.mark.parametrize("args", [["calibrate", "--emulate", "--dry-run", "--turns", "0.25"], ["calibrate"],
                                  ["--emulate", "--seconds", "0.1", "--no-bus"]])
def test_every_trackball_action_refuses_a_config_that_does_not_exist(tmp_path, capsys, args):
    """A typo (rig.tml) is named, not read as 'no file: the default USB ids' (nor created by a calibration)."""
    typo = tmp_path / "rig.tml"
    assert main(["trackball", *args, "--config", str(typo)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.strip() == f"antarium trackball: error: rig config '{typo}' not found"
    assert not typo.exists()
