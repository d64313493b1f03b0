"""The ant's eye: LED frames in, 800 Sobel-filtered projection neurons out, rotation in silico."""

import math

import numpy as np
import pytest

from antarium.ant.eye import Eye, EyeParams, View, row_gain_control, sobel_magnitude


@pytest.fixture(scope="module")
def eye(dome):
    return Eye.from_dome(dome)


def bar_frame(dome, azimuth, column=0, width=0.17, top=0.52):
    """An LED frame with a bright vertical bar at `azimuth` (rad, +-width) below `top` (rad) in LED column `column`."""
    frame = np.zeros((dome.directions.shape[0], 2), np.uint16)
    delta = np.remainder(dome.azimuth - azimuth + math.pi, math.tau) - math.pi
    on = (np.abs(delta) < width) & (dome.elevation < top) & ~dome.is_uv
    frame[on, column] = 40000
    return frame


def test_eye_has_800_projection_neurons_at_about_7_degrees(eye):
    p = eye.params
    assert p.n_pn == 800
    assert 360 / p.cols == pytest.approx(7.2)
    assert np.degrees(np.diff(eye.elevations)) == pytest.approx(np.full(p.rows - 1, 7.0))


def test_a_bar_appears_where_it_is_and_moves_with_the_ants_yaw(dome, eye):
    frame = bar_frame(dome, math.radians(90))
    row = 6  # about 7 deg above the horizon
    pano = eye.look(frame).rotated_panoramas(0.0)[0]
    assert np.argmax(pano[row]) in (12, 13)           # 90 deg / 7.2 deg = 12.5 columns to the left
    facing = eye.look(frame, yaw=math.radians(90)).rotated_panoramas(0.0)[0]
    assert np.argmax(facing[row]) in (0, 49)           # the ant faces the bar


def test_in_silico_rotation_matches_a_rotated_scene(dome, eye):
    # Turning the ant by +a (CCW) in silico must look like the scene turned by -a on the dome's LEDs.
    a = math.radians(37.0)
    turned = eye.look(bar_frame(dome, math.radians(60))).pns([a])[0]
    scene_turned = eye.look(bar_frame(dome, math.radians(60) - a)).pns([0.0])[0]
    assert np.corrcoef(turned, scene_turned)[0, 1] > 0.97


def test_channels_read_their_own_leds(dome):
    green, blue = (Eye.from_dome(dome, EyeParams(channel=c)) for c in ("green", "blue"))
    frame = bar_frame(dome, 0.0, column=1)  # blue only
    assert np.abs(green.look(frame).pns()).max() == 0.0
    assert np.abs(blue.look(frame).pns()).max() > 0.0
    uv = Eye.from_dome(dome, EyeParams(channel="uv"))
    assert uv.channel_pixels.size == 495


def test_the_eye_reads_what_the_centre_sees_through_the_photometric_gain():
    dirs = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0], [0, -1.0, 0]])
    eye = Eye(dirs, gain=np.array([1.0, 0.5, 1.0, 1.0]), params=EyeParams(neighbours=1))
    frame = np.full((4, 2), 1000, np.uint16)
    i = eye.intensities(frame)
    assert i[1] == pytest.approx(2 * i[0])


def test_photoreceptor_compression_is_a_power_of_the_intensity():
    dirs = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0], [0, -1.0, 0]])
    frame = np.array([[65535, 0], [16384, 0], [0, 0], [4096, 0]], np.uint16)
    linear = Eye(dirs, params=EyeParams(neighbours=1)).intensities(frame)
    compressed = Eye(dirs, params=EyeParams(neighbours=1, gamma=0.5)).intensities(frame)
    np.testing.assert_allclose(compressed, np.sqrt(linear), rtol=1e-6)
    with pytest.raises(ValueError, match="gamma"):
        EyeParams(gamma=0.0)


def test_sobel_is_zero_on_a_uniform_panorama_and_wraps_in_azimuth():
    assert np.all(sobel_magnitude(np.full((4, 16, 50), 3.0, np.float32)) == 0.0)
    step = np.zeros((16, 50), np.float32)
    step[:, :25] = 1.0
    edges = sobel_magnitude(step)
    assert edges[8, 49] > 0 and edges[8, 0] > 0 and edges[8, 24] > 0 and edges[8, 12] == 0


def test_row_gain_control_evens_out_the_rows_and_commutes_with_rotation():
    rng = np.random.default_rng(0)
    edges = rng.random((16, 50)).astype(np.float32) * np.linspace(0.01, 2.0, 16, dtype=np.float32)[:, None]
    out = row_gain_control(edges)
    # every row then has a mean of about 1 whatever its contrast (up to the floor), and turning commutes with it
    np.testing.assert_allclose(out.mean(axis=1), 1.0 / (1.0 + 0.01 * edges.mean() / edges.mean(axis=1)), rtol=1e-5)
    np.testing.assert_allclose(row_gain_control(np.roll(edges, 7, axis=1)), np.roll(out, 7, axis=1), rtol=1e-6)
    band = rng.random((16, 300)).astype(np.float32)
    plain, gained = View(band, 6, 50), View(band, 6, 50, row_gain=True)
    angles = np.radians([0.0, 7.2, -30.0])
    expected = row_gain_control(plain.pns(angles).reshape(3, 16, 50)).reshape(3, -1)
    np.testing.assert_allclose(gained.pns(angles), expected, rtol=1e-6)


def test_bad_input_is_refused_with_a_clear_error(eye):
    with pytest.raises(ValueError, match=r"shape \(20350, 2\)"):
        eye.look(np.zeros((100, 2), np.uint16))
    with pytest.raises(ValueError, match="allowed: green, blue, uv"):
        EyeParams(channel="red")
    with pytest.raises(ValueError, match="finite"):
        eye.look(np.zeros((20350, 2), np.uint16), yaw=math.nan)


@pytest.mark.parametrize("params", [EyeParams(sigma_deg=16.0), EyeParams(sigma_deg=60.0),
                                    EyeParams(elevation_min_deg=-90.0, sigma_deg=20.0),
                                    EyeParams(sigma_deg=1.0, fine_elevation_deg=10.0)])
def test_every_valid_eye_gives_a_finite_view(dome, params):
    """A wide acceptance reaches below the dome's lowest LEDs (-57 deg): those fine samples take their nearest LEDs
    instead of 0 / 0 = NaN; a fine grid coarse against sigma keeps each row's nearest fine elevation."""
    eye = Eye.from_dome(dome, params)
    x = np.random.default_rng(0).random(eye.channel_pixels.size).astype(np.float32)
    view = eye.look_intensities(x)
    assert np.all(np.isfinite(view.band)) and np.all(np.isfinite(view.pns()))
    assert 0.0 < view.band.min() and view.band.max() < 1.0  # a weighted mean of intensities in (0, 1)


@pytest.mark.parametrize("params", [EyeParams(), EyeParams(sigma_deg=30.0), EyeParams(sigma_deg=60.0),
                                    EyeParams(cols=25, fine_per_col=3, sigma_deg=60.0)])
def test_the_compiled_band_equals_the_dense_reference(dome, params):
    """Also for an azimuth blur as wide as the circle (an even number of fine columns: the opposite column once)."""
    eye = Eye.from_dome(dome, params)
    x = np.random.default_rng(1).random(eye.channel_pixels.size).astype(np.float32)
    band = eye.look_intensities(x).band
    ref = eye._blur_el.astype(np.float64) @ (eye._sample @ x.astype(np.float64)).reshape(eye._fine_shape) \
        @ eye._blur_az.astype(np.float64)
    assert np.abs(band - ref).max() <= 1e-5 * np.abs(ref).max()
