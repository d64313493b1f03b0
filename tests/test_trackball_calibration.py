"""The [trackball] config section and the calibration procedure (pure and end to end on the emulated device)."""

import math
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

[ant]
model = "mb"
weights = [1, 2, 3]
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
    assert doc["rig"] == {"name": "lab2"} and doc["ant"] == {"model": "mb", "weights": [1, 2, 3]}
    assert doc["bus"] == {"listen": ["tcp/127.0.0.1:7999"]}
    assert tbconfig.load(rig) == new


def test_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        tbconfig.load(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[trackball\n")
    with pytest.raises(tbconfig.TrackballConfigError, match="not valid TOML"):
        tbconfig.load(bad)


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


def test_cli_calibrate_writes_the_rig_config(tmp_path, capsys):
    rig = tmp_path / "rig.toml"
    rig.write_text(OTHER)
    assert main(["trackball", "calibrate", "--emulate", "--config", str(rig), "--turns", "0.25"]) == 0
    doc = tomllib.loads(rig.read_text())
    assert doc["rig"] == {"name": "lab2"} and doc["ant"]["weights"] == [1, 2, 3]
    cpmm = [v for s in doc["trackball"]["sensors"] for v in s["counts_per_mm"]]
    np.testing.assert_allclose(cpmm, [47.244094 * f for f in calibration.EMULATED_CPMM_FACTORS], rtol=5e-3)
    assert "wrote [trackball]" in capsys.readouterr().out
    assert main(["trackball", "calibrate", "--emulate", "--config", str(rig), "--axes", "q"]) == 2
    assert math.isclose(tbconfig.load(rig).sensors[0].counts_per_mm[0], cpmm[0])  # the failed run changed nothing
