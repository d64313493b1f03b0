"""Hardware addresses: round trips and range checks."""

import numpy as np
import pytest

from antarium.geometry import addressing as a
from antarium.geometry import load_dome
from antarium.geometry.constants import CHIPS_PER_CHAIN, LEDS_PER_PANEL, N_PIXELS


def test_global_round_trip():
    g = np.arange(N_PIXELS)
    panel, local = a.split_global(g)
    np.testing.assert_array_equal(a.join_global(panel, local), g)
    pent, slot = a.split_panel(np.arange(55))
    np.testing.assert_array_equal(a.join_panel(pent, slot), np.arange(55))


def test_driver_round_trip_covers_every_led_once():
    local = np.repeat(np.arange(370), 2)
    led = np.tile([0, 1], 370)
    chain, chip, ch = a.led_to_driver(local, led)
    keys = set(zip(chain.tolist(), chip.tolist(), ch.tolist(), strict=True))
    assert len(keys) == LEDS_PER_PANEL == 740
    back_local, back_led = a.driver_to_led(chain, chip, ch)
    np.testing.assert_array_equal(back_local, local)
    np.testing.assert_array_equal(back_led, led)
    assert sum(CHIPS_PER_CHAIN) == 47
    assert np.all(chip < np.asarray(CHIPS_PER_CHAIN)[chain])


def test_address_of_first_and_last_pixels():
    first = a.address(0)
    assert (first.panel, first.pentagon, first.slot, first.local, first.is_uv) == (0, 0, 0, 0, False)
    assert first.drivers == ((0, 0, 0), (0, 0, 1))
    last = a.address(20349)
    assert (last.panel, last.pentagon, last.slot, last.local, last.actuator) == (54, 10, 4, 369, 8)
    assert last.drivers == ((3, 10, 2), (3, 10, 3))
    uv0 = a.address(361)
    assert uv0.is_uv and uv0.actuator == 0


def test_dome_arrays_agree_with_address():
    dome = load_dome()
    for g in (0, 360, 361, 5000, 20349):
        adr = dome.address(g)
        assert (adr.panel, adr.pentagon, adr.slot, adr.local, adr.is_uv) == (
            dome.panel[g], dome.pentagon[g], dome.slot[g], dome.local[g], dome.is_uv[g])
    np.testing.assert_array_equal(dome.panel_pixels(3), np.arange(3 * 370, 4 * 370))


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: a.address(20350), "pixel index out of range: allowed 0..20349"),
        (lambda: a.address(-1), "allowed 0..20349"),
        (lambda: a.address(1.5), "must be an integer"),
        (lambda: a.join_global(55, 0), "panel out of range: allowed 0..54"),
        (lambda: a.join_global(0, 370), "local pixel index out of range: allowed 0..369"),
        (lambda: a.join_panel(11, 0), "pentagon out of range: allowed 0..10"),
        (lambda: a.led_to_driver(0, 2), "led out of range: allowed 0..1"),
        (lambda: a.driver_to_led(4, 0, 0), "chain out of range"),
        (lambda: a.driver_to_led(3, 11, 0), "chip_in_chain out of range"),
        (lambda: a.driver_to_led(3, 10, 4), "not connected"),
        (lambda: load_dome().panel_pixels(55), "panel must be an integer 0..54"),
    ],
)
def test_unknown_ids_rejected(call, match):
    with pytest.raises(ValueError, match=match):
        call()
