"""The optimised decision paths (compiled KC kernel, perfect memory's store) against the straightforward ones."""

import numpy as np
import pytest

from antarium.ant.eye import View
from antarium.ant.models import ArdinModel, PerfectMemoryModel, _best_angle
from antarium.ant.mushroom_body import MBON, KenyonCells

N_PN = 800


def random_view(seed: int, yaw: float = 0.0) -> View:
    """A smooth random panorama band (16 rows x 300 fine azimuths) like the eye's."""
    rng = np.random.default_rng(seed)
    spectrum = rng.normal(size=(16, 151)) + 1j * rng.normal(size=(16, 151))
    spectrum[:, 25:] = 0.0
    return View(np.fft.irfft(spectrum, n=300, axis=1).astype(np.float32), 6, 50, yaw)


def test_kernel_novelty_equals_argpartition_for_every_batch_size():
    # Tolerance: one KC swapped at the k-WTA boundary (1 / k); on these inputs no swap happens in practice.
    kc = KenyonCells(N_PN, 20_000, 10, 0.01, seed=0)
    left, right = MBON(kc.n_kc), MBON(kc.n_kc)
    left.learn(kc.active(random_view(1).pns(np.linspace(-0.5, 0.5, 9))))
    right.learn(kc.active(random_view(2).pns([0.0])))
    pn = random_view(1, yaw=0.1).pns(np.linspace(-1.0, 1.0, 70))
    for m in (1, 7, 61, 64, 70):
        fast = kc.novelty(pn[:m], [left, right])
        assert fast.shape == (m, 2) and fast.dtype == np.float64
        ref = kc.active(pn[:m])
        np.testing.assert_allclose(fast[:, 0], left.novelty(ref), rtol=0, atol=0.5 / kc.k)
        np.testing.assert_allclose(fast[:, 1], right.novelty(ref), rtol=0, atol=0.5 / kc.k)
    assert fast[:, 0].min() < 0.5 and fast[:, 1].max() == 1.0  # the learned directions are familiar


@pytest.mark.parametrize("kind", ["normal", "ties", "constant", "spread"])
def test_the_kernels_lower_bound_is_reached_by_k_values_and_never_above_the_kth_largest(kind):
    """The block maxima's bound that decides which KCs are read at all: if it were above the k-th largest, an
    active KC would be missed."""
    from antarium.ant.kc_kernel import _BINS, _lower_bound

    rng = np.random.default_rng(3)
    counts = np.empty(_BINS, np.int64)
    for trial in range(200):
        n = int(rng.integers(1, 1500))
        values = {"normal": rng.normal(5.0, 1.0, n), "ties": rng.integers(0, 4, n) * 0.25,
                  "constant": np.full(n, 2.5), "spread": rng.normal(0.0, 1.0, n) * 10.0 ** rng.integers(-30, 30)}[kind]
        values = values.astype(np.float32)
        for k in {1, max(1, n // 100), n}:
            low = _lower_bound(values, k, counts)
            assert (values >= low).sum() >= k and low <= np.sort(values)[-k], (kind, trial, n, k)
            assert low in values


def test_kernel_breaks_ties_toward_lower_kc_and_handles_all_active():
    kc = KenyonCells(N_PN, 1_000, 4, 0.01, seed=1)
    mbon = MBON(kc.n_kc)
    mbon.learn(np.arange(5))                       # KCs 0..4 depressed: half of the k = 10 lowest
    flat = np.zeros((3, N_PN), np.float32)         # every EP ties at 0
    np.testing.assert_allclose(kc.novelty(flat, [mbon])[:, 0], 0.5, rtol=0, atol=1e-12)
    everyone = KenyonCells(N_PN, 50, 4, 1.0, seed=1)   # k = n_kc: all active
    m = MBON(50)
    m.learn(np.arange(10))
    np.testing.assert_allclose(everyone.novelty(random_view(3).pns([0.0, 1.0]), [m])[:, 0], 0.8, atol=1e-12)


def _reference_active(kc: KenyonCells, pn: np.ndarray) -> np.ndarray:
    """The k largest EPs, ties broken toward the lower KC index, by a stable sort (ascending KC index)."""
    order = np.argsort(-kc.excitation(pn), axis=1, kind="stable")[:, :kc.k]
    return np.sort(order, axis=1)


def _quantised_sparse_pn(rng, m: int, zeros: float) -> np.ndarray:
    pn = rng.random((m, N_PN)).astype(np.float32)
    pn[rng.random((m, N_PN)) < zeros] = 0.0
    return np.round(pn * 4) / 4  # few distinct intensities: many KCs tie at the k-th EP


@pytest.mark.parametrize("m", [1, 5, 64, 70])
def test_learning_selects_the_kcs_recall_reads_also_on_ties(m):
    """`KenyonCells.active` (what learning depresses) is the kernel's selection: the k largest EPs, ties at the
    k-th toward the lower KC index; so a view just learned reads novelty 0, also from quantised inputs."""
    rng = np.random.default_rng(4)
    kc = KenyonCells(N_PN, 20_000, 10, 0.01, seed=0)
    for zeros in (0.0, 0.5, 0.97):
        pn = _quantised_sparse_pn(rng, m, zeros)
        active = kc.active(pn)
        assert active.shape == (m, kc.k) and active.dtype == np.int64
        np.testing.assert_array_equal(active, _reference_active(kc, pn))
        for row in range(m):
            mbon = MBON(kc.n_kc)
            mbon.learn(active[row])
            assert kc.novelty(pn[row:row + 1], [mbon])[0, 0] == 0.0
            assert mbon.novelty(kc.active(pn[row:row + 1]))[0] == 0.0
    smooth = random_view(5).pns(np.linspace(-0.5, 0.5, m))  # distinct EPs: the plain k largest
    np.testing.assert_array_equal(kc.active(smooth), _reference_active(kc, smooth))


def test_an_ardin_ant_finds_a_view_it_just_learned_fully_familiar_in_a_sparse_scene():
    """A black scene with one bright patch: few PNs see an edge, so many KCs tie at the k-th EP."""
    band = np.zeros((16, 300), np.float32)
    band[5:7, 100:106] = 1.0
    model = ArdinModel(N_PN)
    model.learn(View(band, 6, 50))
    cmd = model.decide(View(band, 6, 50))
    assert cmd.turn == 0.0 and cmd.trace["novelty"] == 0.0


def test_kernel_rejects_wrong_pn_shape():
    kc = KenyonCells(N_PN, 1_000, 4, 0.01, seed=1)
    with pytest.raises(ValueError, match=r"shape \(m, 800\)"):
        kc.novelty(np.zeros((2, 799), np.float32), [MBON(1_000)])


def test_ardin_decides_the_heading_of_the_straightforward_scan():
    model = ArdinModel(N_PN)
    for seed in range(5):
        model.learn(random_view(seed))
    mbon = model.mbons["familiarity"]
    for seed, yaw in ((0, 0.2), (3, -0.4), (7, 0.0)):
        view = random_view(seed, yaw)
        ref = mbon.novelty(model.kc.active(view.pns(model._scan)))
        cmd = model.decide(view)
        i = _best_angle(model._scan, ref)
        assert cmd.turn == pytest.approx(float(model._scan[i]), abs=1e-12)
        assert cmd.trace["novelty"] == pytest.approx(float(ref[i]), abs=0.5 / model.kc.k)


def _reference_differences(views: np.ndarray, pn: np.ndarray) -> np.ndarray:
    """Smallest RMS difference computed directly in float64, view by view."""
    d = pn.astype(np.float64)[:, None, :] - views.astype(np.float64)[None, :, :]
    return np.sqrt((d * d).mean(axis=2).min(axis=1))


def test_perfect_memory_store_matches_direct_differences_and_headings():
    model = PerfectMemoryModel(N_PN)
    for seed in range(40):                          # more than the first capacity (16): the store grows
        model.learn(random_view(seed))
    assert model.learned_views == 40 and model.views.shape == (40, N_PN)
    reloaded = PerfectMemoryModel(N_PN, views=model.views.copy())
    for seed, yaw in ((3, 0.3), (41, 0.0), (17, -0.2)):
        view = random_view(seed, yaw)
        pn = view.pns(model._scan)
        ref = _reference_differences(model.views, pn)
        fast = model.differences(pn)
        # float32 product vs float64 differences: the image differences here are ~0.1-1, so 1e-3 is ~0.1-1 %.
        np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-3)
        cmd = model.decide(view)
        assert cmd.turn == pytest.approx(float(model._scan[_best_angle(model._scan, ref)]), abs=1e-12)
        assert reloaded.decide(view).turn == cmd.turn


def test_compiled_scan_edges_equal_the_numpy_stages():
    from antarium.ant.eye import sobel_magnitude

    angles = np.linspace(-1.05, 1.05, 61)
    for seed, yaw in ((0, 0.0), (4, 0.37), (9, -2.0)):
        view = random_view(seed, yaw)
        ref = sobel_magnitude(view.rotated_panoramas(angles)).reshape(61, -1)
        fast = view.pns(angles)
        assert fast.dtype == np.float32 and fast.shape == ref.shape
        # the same float32 operations in the same order; tolerance: a few ULPs of edges of order 1
        np.testing.assert_allclose(fast, ref, rtol=1e-6, atol=1e-6)


def test_compiled_band_equals_the_dense_products_of_the_eye():
    """The eye's band (fine sampling, elevation and circular azimuth blur) against the products it replaces."""
    from antarium.ant.eye import Eye
    from antarium.ant.eye_kernel import Band
    from antarium.geometry import load_dome

    eye = Eye.from_dome(load_dome())
    rng = np.random.default_rng(8)
    band = Band(eye._sample, eye._blur_el, eye._blur_az)
    for _ in range(3):
        x = rng.random(eye._sample.shape[1], dtype=np.float32)
        ref = eye._blur_el @ (eye._sample @ x).astype(np.float32).reshape(eye._fine_shape) @ eye._blur_az
        fast = band(x)
        assert fast.dtype == np.float32 and fast.shape == ref.shape == (eye.params.rows, 300)
        np.testing.assert_allclose(fast, ref, rtol=1e-5, atol=1e-6)  # float32 sums in another order
    skewed = eye._blur_az.copy()
    skewed[5, 7] += 0.01
    with pytest.raises(ValueError, match="circulant"):
        Band(eye._sample, eye._blur_el, skewed)
