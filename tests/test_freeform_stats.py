"""Moran's I against PySAL esda, filters against OpenCV and csaps, surfaces against closed forms."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from ncadapt import filters, stats, surfaces

esda = pytest.importorskip("esda")
libpysal = pytest.importorskip("libpysal")


def _data(n=300, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 10, (n, 2))
    return p, np.sin(p[:, 0]) + 0.3 * rng.normal(size=n)


def _esda(values, w):
    w.transform = "r"
    # one-tailed: esda gives the tail on the side of z, P(Z ≥ z) for z > 0 and P(Z ≤ z) below
    return esda.Moran(values, w, permutations=0, two_tailed=False)


def _same(ours, ref):
    for a, b in (
        (ours.I, ref.I),
        (ours.expected, ref.EI),
        (ours.variance_normality, ref.VI_norm),
        (ours.variance_randomization, ref.VI_rand),
        (ours.z_normality, ref.z_norm),
        (ours.z_randomization, ref.z_rand),
    ):
        assert a == pytest.approx(b, rel=1e-10, abs=1e-10)
    # ours is one-sided towards positive autocorrelation, P(Z ≥ z), whatever the sign of z
    for p, z, tail in ((ours.p_normality, ref.z_norm, ref.p_norm), (ours.p_randomization, ref.z_rand, ref.p_rand)):
        assert p == pytest.approx(tail if z > 0 else 1 - tail, rel=1e-9)


def test_moran_knn_equals_esda():
    p, v = _data()
    _same(stats.moran(p, v, weights="knn", neighbors=6), _esda(v, libpysal.weights.KNN(p, k=6)))


@pytest.mark.parametrize("power", [1.0, 2.0])
def test_moran_distance_band_equals_esda(power):
    p, v = _data(seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # libpysal's own divide-by-zero on the diagonal
        w = libpysal.weights.DistanceBand(p, threshold=2.0, binary=False, alpha=-power, silence_warnings=True)
    _same(stats.moran(p, v, weights="idw", threshold=2.0, power=power), _esda(v, w))


def test_moran_all_pairs_idw_equals_esda():
    from scipy.spatial.distance import cdist

    p, v = _data(n=400, seed=5)
    d = cdist(p, p)
    np.fill_diagonal(d, np.inf)
    _same(stats.moran(p, v), _esda(v, libpysal.weights.full2W(1 / d)))


def test_moran_st_louis_published_value():
    """esda's documented result on the St. Louis homicide rates 1988-93 (libpysal example
    ``stl``, its contiguity weights)."""
    import csv

    with open(libpysal.examples.get_path("stl_hom.txt"), newline="") as f:
        rows = list(csv.reader(f))[1:]
    y = np.array([float(r[rows[0].index("HR8893")]) for r in rows[1:]])
    gal = libpysal.io.open(libpysal.examples.get_path("stl.gal"))
    w = gal.read()
    gal.close()
    ours = stats.moran_matrix(w.full()[0], y)
    # esda's Moran docstring: round(I, 3) = 0.244, EI = -1/77, p_norm = 0.00027147862770937614
    assert round(ours.I, 3) == 0.244
    assert ours.expected == pytest.approx(-0.012987012987012988, rel=1e-12)
    # one-sided (z > 0): half the published two-tailed value
    assert ours.p_normality == pytest.approx(0.00027147862770937614 / 2, rel=1e-6)
    _same(ours, _esda(y, w))


def test_moran_sids_published_value():
    """esda's documented result on the North Carolina SIDS rates 1974 (libpysal example
    ``sids2``, its contiguity weights), which esda notes replicates OpenGeoda."""
    dbf = libpysal.io.open(libpysal.examples.get_path("sids2.dbf"))
    y = np.array(dbf.by_col("SIDR74"), dtype=float)
    dbf.close()
    gal = libpysal.io.open(libpysal.examples.get_path("sids2.gal"))
    w = gal.read()
    gal.close()
    ours = stats.moran_matrix(w.full()[0], y)
    # esda's Moran docstring: round(I, 3) = 0.248, p_norm = 0.0001158330781489969
    assert round(ours.I, 3) == 0.248
    assert ours.expected == pytest.approx(-1.0 / (len(y) - 1), rel=1e-12)
    assert ours.p_normality == pytest.approx(0.0001158330781489969 / 2, rel=1e-6)
    _same(ours, _esda(y, w))


def test_moran_decision_rate_on_noise():
    """Pure noise: 'systematic' at most about alpha of the time (40 seeds, alpha 0.05)."""
    rng = np.random.default_rng(11)
    p = rng.uniform(0, 50, (400, 2))
    hits = sum(stats.moran(p, np.random.default_rng(s).normal(size=400), weights="knn").systematic for s in range(40))
    assert hits <= 5


def test_moran_rejects_bad_input():
    p, v = _data(n=10)
    with pytest.raises(ValueError):
        stats.moran(p, v, power=0.5)
    with pytest.raises(ValueError, match="equal"):
        stats.moran(p, np.ones(10))
    q = p.copy()
    q[1] = q[0]
    with pytest.raises(ValueError, match="coincide"):
        stats.moran(q, v)


def test_moran_idw_large_power_is_the_nearest_neighbour_limit():
    # w_ij = d_ij^-K row-standardised tends, as K grows, to equal weights on each point's nearest
    # neighbours: built here by hand on a jittered grid (a point's nearest is unique) and on an
    # exact grid (2 to 4 nearest at one distance), for the dense and the distance-band weights
    from scipy.spatial.distance import cdist

    rng = np.random.default_rng(4)
    g = np.array([(x, y) for x in range(12) for y in range(9)], float)
    for p in (g + rng.uniform(-0.05, 0.05, g.shape), g):
        v = np.sin(p[:, 0] / 2) + 0.3 * rng.normal(size=len(p))
        d = cdist(p, p)
        np.fill_diagonal(d, np.inf)
        nearest = (d <= d.min(axis=1, keepdims=True) * (1 + 1e-12)).astype(float)
        ref = stats.moran_matrix(nearest, v)
        for kw in ({}, {"threshold": 3.0}):
            ours = stats.moran(p, v, power=1e12, **kw)
            assert np.isfinite([ours.I, ours.z_randomization, ours.z_normality]).all()
            np.testing.assert_allclose(
                [ours.I, ours.z_randomization, ours.z_normality],
                [ref.I, ref.z_randomization, ref.z_normality],
                rtol=1e-9,
            )


def test_moran_is_free_of_units():
    # I and its z do not depend on the units of the points or of the values (closed form: every
    # term is a ratio of sums of the same degree); extreme scales must not overflow
    p, v = _data(n=200, seed=7)
    ref = stats.moran(p, v, power=2.0)
    for sp, sv in ((1e-3, 1.0), (1e3, 1e-200), (1.0, 1e200)):
        m = stats.moran(p * sp, v * sv, power=2.0)
        np.testing.assert_allclose(
            [m.I, m.z_randomization, m.z_normality], [ref.I, ref.z_randomization, ref.z_normality], rtol=1e-9
        )


def test_moran_knn_needs_more_points_than_neighbours():
    p, v = _data(n=10)
    with pytest.raises(ValueError, match="need more than 10 points; there are 10"):
        stats.moran(p, v, weights="knn", neighbors=10)


def test_too_many_pairs_are_refused_before_listing(monkeypatch):
    from ncadapt import neighbours

    p, v = _data(n=100)
    monkeypatch.setattr(neighbours, "MAX_PAIRS", 1000)
    # all pairs: 100 * 99 / 2 = 4950 > 1000
    with pytest.raises(ValueError, match="joins 4,950 pairs"):
        filters.bilateral(p, v, 1e6, 1.0)
    with pytest.raises(ValueError, match="joins 4,950 pairs"):
        stats.moran(p, v, threshold=1e9)


def test_bilateral_limits_of_its_sigmas():
    # sigma_s → 0: no neighbour weighs anything, the values come back as they were; both sigmas
    # → ∞: every weight is 1 and each value becomes the mean (closed forms), with no overflow
    p, v = _data(n=60)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(filters.bilateral(p, v, 1.0, 1e-300), v)
        np.testing.assert_allclose(filters.bilateral(p, v, 1e300, 1e300), np.full(60, v.mean()), rtol=1e-12)


def test_bilateral_equals_opencv_away_from_borders():
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(1)
    ny, nx = 30, 40
    img = (
        np.sin(np.arange(nx) / 5)[None, :] * np.cos(np.arange(ny) / 7)[:, None] + 0.2 * rng.normal(size=(ny, nx))
    ).astype(np.float32)
    sc, ss = 1.5, 0.5
    d = 2 * int(np.ceil(2 * sc)) + 1
    ref = cv2.bilateralFilter(img, d, ss, sc)
    yy, xx = np.mgrid[0:ny, 0:nx]
    ours = filters.bilateral(
        np.column_stack([xx.ravel(), yy.ravel()]), img.ravel().astype(float), sc, ss, radius=d // 2
    ).reshape(ny, nx)
    m = d // 2
    # OpenCV computes in float32
    np.testing.assert_allclose(ours[m:-m, m:-m], ref[m:-m, m:-m], atol=2e-6)


@pytest.mark.parametrize("p", [0.05, 0.3, 0.8, 0.99])
def test_smoothing_spline_grid_equals_csaps(p):
    csaps = pytest.importorskip("csaps")
    rng = np.random.default_rng(2)
    x = np.sort(rng.uniform(0, 5, 12))
    y = np.linspace(0, 3, 9)
    z = rng.normal(size=(12, 9))
    ref = csaps.NdGridCubicSmoothingSpline((x, y), z, smooth=p)((x, y))
    np.testing.assert_allclose(filters.smoothing_spline_grid((x, y), z, p), ref, atol=1e-12)


def test_smoothing_spline_limits():
    x = np.linspace(0, 1, 15)
    y = np.random.default_rng(0).normal(size=15)
    np.testing.assert_allclose(filters.smoothing_spline_grid((x,), y, 1.0), y, atol=1e-12)  # interpolant
    line = np.polyval(np.polyfit(x, y, 1), x)
    np.testing.assert_allclose(filters.smoothing_spline_grid((x,), y, 0.0), line, atol=1e-12)  # LSQ line


def test_mean_curvature_sphere_and_cylinder():
    r = 10.0
    sph = surfaces.Surface.from_function(
        lambda u, v: (r * np.sin(u) * np.cos(v), r * np.sin(u) * np.sin(v), r * np.cos(u)), (0.5, 2.5), (0.1, 3), 81, 81
    )
    assert abs(sph.mean_curvature(1.2, 1.5)) == pytest.approx(1 / r, rel=1e-4)
    cyl = surfaces.Surface.from_function(lambda u, v: (5 * np.cos(u), 5 * np.sin(u), v), (0, 3), (0, 10), 81, 21)
    assert abs(cyl.mean_curvature(1.5, 5.0)) == pytest.approx(1 / (2 * 5), rel=1e-3)
    plane = surfaces.Surface.height(lambda x, y: 0.3 * x - 0.1 * y, (0, 10), (0, 10), 6, 6)
    np.testing.assert_allclose(plane.normal(3.0, 4.0), np.array([-0.3, 0.1, 1]) / np.sqrt(1.1), atol=1e-12)
    assert plane.mean_curvature(3.0, 4.0) == pytest.approx(0, abs=1e-12)


def test_border_extrapolation_is_exact_for_cubics_and_bounded():
    u = np.linspace(0, 10, 21)
    v = np.linspace(0, 8, 17)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    known = (uu > 1) & (uu < 9) & (vv > 0.6) & (vv < 7.4)
    f = 0.002 * uu**3 - 0.03 * uu + 0.4 * vv
    out = surfaces.extrapolate_border(u, v, np.where(known, f, 0.0), known)
    lo, hi = f[known].min(), f[known].max()
    np.testing.assert_allclose(out, np.clip(f, lo - (hi - lo) / 4, hi + (hi - lo) / 4), atol=1e-9)
    assert (np.abs(out - f) < 1e-9).mean() > 0.95  # exact nearly everywhere
    g = 0.05 * uu**3  # runs away beyond the measured area: held within a quarter span of the known range
    out = surfaces.extrapolate_border(u, v, np.where(known, g, 0.0), known)
    lo, hi = g[known].min(), g[known].max()
    assert out.max() == pytest.approx(hi + (hi - lo) / 4) and out.min() >= lo - (hi - lo) / 4 - 1e-12
    np.testing.assert_allclose(out[known], g[known])


def test_a_p_value_that_underflows_is_never_printed_as_zero():
    # z = 40 has p = 2 sf(40) ≈ 7.3e-350, below the smallest double: it underflows to 0
    from scipy.stats import norm

    assert 2 * norm.sf(40) == 0
    assert stats.p_text(2 * norm.sf(40)) == "< 1e-300"
    assert stats.p_text(0.0123456) == "0.0123"
    assert stats.p_text(2.5e-300) == "2.5e-300"


def test_offset_test_equals_scipy_ttest_1samp():
    from scipy.stats import ttest_1samp

    for s in range(5):
        v = np.random.default_rng(s).normal(0.002 * s, 0.005, 50)
        o, ref = stats.offset(v), ttest_1samp(v, 0.0)
        assert (o.t, o.p_value, o.mean) == (
            pytest.approx(ref.statistic, rel=1e-12),
            pytest.approx(ref.pvalue, rel=1e-9),
            pytest.approx(v.mean(), rel=1e-12),
        )
    # every value alike: an offset exactly when it is not 0
    assert stats.offset(np.full(10, 0.02)).p_value < 1e-100 and stats.offset(np.zeros(10)).p_value == 1.0


def test_lag1_test_equals_scipy_pearsonr_one_sided():
    from scipy.stats import pearsonr

    for s in range(5):
        x = np.cumsum(np.random.default_rng(s).normal(size=80)) * (s % 2) + np.random.default_rng(s).normal(size=80)
        r, t, p = stats.lag1_autocorrelation(x)
        ref = pearsonr(x[:-1], x[1:], alternative="greater")
        assert r == pytest.approx(ref.statistic, rel=1e-12) and p == pytest.approx(ref.pvalue, rel=1e-8)


def test_pearson_normality_equals_scipy_chisquare():
    from scipy.stats import chisquare, norm

    x = np.random.default_rng(2).normal(size=500)
    chi2, dof, p = stats.pearson_normality(x)
    k = dof + 3
    edges = norm.ppf(np.linspace(0, 1, k + 1)[1:-1], loc=x.mean(), scale=x.std(ddof=1))
    counts = np.bincount(np.searchsorted(edges, x), minlength=k)
    ref = chisquare(counts, ddof=2)  # two parameters estimated: k - 1 - 2 degrees of freedom
    assert chi2 == pytest.approx(ref.statistic, rel=1e-12) and p == pytest.approx(ref.pvalue, rel=1e-12)


def test_permutation_p_agrees_with_esda_p_sim():
    # both are (1 + #{I_r ≥ I}) / (R + 1) over random permutations (different generators): they
    # agree within the Monte-Carlo error, about sqrt(p (1 - p) / R)
    p, _ = _data(n=150, seed=9)
    v = 0.15 * np.sin(p[:, 0]) + np.random.default_rng(9).normal(size=150)
    w = libpysal.weights.KNN(p, k=6)
    w.transform = "r"
    ref = esda.Moran(v, w, permutations=9999, two_tailed=False)
    ours = stats._with_permutations(
        stats.moran(p, v, weights="knn", neighbors=6),
        stats.weights_matrix(p, stats.Weights("knn", None, None, 6)),
        v - v.mean(),
        r=9999,
    )
    assert ref.p_sim > 0.002 and ref.z_sim > 0
    assert ours.p_permutation == pytest.approx(ref.p_sim, abs=4 * np.sqrt(ref.p_sim * (1 - ref.p_sim) / 9999))
    # the decision uses the permutation p up to PERMUTATION_MAX_N points
    assert stats.moran(p, v).p_value == stats.moran(p, v).p_permutation is not None


def test_default_p_is_csaps_automatic_choice():
    csaps = pytest.importorskip("csaps")
    for h in (0.5, 1.0, 2.5, 4.0):
        x = np.arange(0, 30 * h, h)
        y = np.sin(x / (5 * h)) + np.random.default_rng(1).normal(0, 0.1, len(x))
        assert filters.csaps_auto_p(h) == pytest.approx(csaps.CubicSmoothingSpline(x, y).smooth, rel=1e-9)
    assert filters.csaps_auto_p(2.5) == pytest.approx(0.3655, abs=1e-4)  # the demo's 2.5 mm grid


def test_one_p_smooths_grid_and_scattered_points_alike():
    # points on a grid given to csaps' gridded smoother and to the scattered one: the same surface
    # (the binding figure is 5 %; the functional is the same, so it agrees to rounding), and the
    # same distance from the truth
    csaps = pytest.importorskip("csaps")
    xs, ys = np.arange(0, 70.1, 2.5), np.arange(0, 50.1, 2.5)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel()])
    assert filters.effective_spacing(pts) == pytest.approx(2.5, rel=1e-12)

    def truth(x, y):
        return 0.02 * np.sin(x / 9) * np.cos(y / 11) + 0.01 * (x / 70) ** 2

    rng = np.random.default_rng(0)
    for p in (0.05, 0.2, filters.csaps_auto_p(2.5), 0.6):
        g = truth(X, Y) + rng.normal(0, 0.005, X.shape)
        grid = csaps.NdGridCubicSmoothingSpline((xs, ys), g, smooth=p)((xs, ys)).ravel()
        scattered = filters.smoothing_spline(pts[::-1], g.ravel()[::-1], p)[::-1]  # any order
        signal = np.sqrt(((grid - grid.mean()) ** 2).mean())
        assert np.sqrt(((scattered - grid) ** 2).mean()) < 1e-6 * signal  # far within 5 %
        err_grid = np.sqrt(((grid - truth(X, Y).ravel()) ** 2).mean())
        err_scattered = np.sqrt(((scattered - truth(X, Y).ravel()) ** 2).mean())
        assert err_scattered == pytest.approx(err_grid, rel=0.05) and err_grid < 0.0035  # noise 5 µm


def test_scattered_spline_off_the_grid_keeps_the_grid_smoothing():
    # the grid's points moved by up to a quarter spacing (the node grid no longer on them), the same
    # noise: the surfaces' errors against the truth stay within 8 % of the signal of each other
    # (measured 2-6 %: the noise sits at other places), and the smoothing is no weaker (errors within
    # 15 %); uniform random points of the same density too
    xs, ys = np.arange(0, 70.1, 2.5), np.arange(0, 50.1, 2.5)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    pts = np.column_stack([X.ravel(), Y.ravel()])

    def truth(q):
        return 0.02 * np.sin(q[:, 0] / 9) * np.cos(q[:, 1] / 11) + 0.01 * (q[:, 0] / 70) ** 2

    def rms(a):
        return float(np.sqrt((a**2).mean()))

    for seed in range(3):
        rng = np.random.default_rng(seed)
        noise = rng.normal(0, 0.005, len(pts))
        moved = pts + rng.uniform(-0.625, 0.625, pts.shape)
        uniform = rng.uniform(0, 1, pts.shape) * [70, 50]
        for p in (0.05, 0.2, filters.csaps_auto_p(2.5)):
            e_grid = filters.smoothing_spline_grid((xs, ys), (truth(pts) + noise).reshape(X.shape), p).ravel()
            e_grid -= truth(pts)
            e_moved = filters.smoothing_spline(moved, truth(moved) + noise, p) - truth(moved)
            assert rms(e_moved - e_grid) < 0.08 * rms(truth(pts) - truth(pts).mean()), (seed, p)
            assert rms(e_moved) == pytest.approx(rms(e_grid), rel=0.15)
            e_uniform = filters.smoothing_spline(uniform, truth(uniform) + noise, p) - truth(uniform)
            assert rms(e_uniform) == pytest.approx(rms(e_grid), rel=0.25), (seed, p)


def test_scattered_spline_limits_and_refusals():
    rng = np.random.default_rng(4)
    q = rng.uniform(0, 20, (300, 2))
    plane = 0.01 * q[:, 0] - 0.02 * q[:, 1] + 0.003
    # no roughness in a plane (nor in a bilinear u·v): reproduced at any p
    for p in (1e-4, 0.5, 0.99):
        np.testing.assert_allclose(filters.smoothing_spline(q, plane, p), plane, atol=1e-7)
    # p → 0: the least-squares bilinear surface a + b u + c v + d u v (the roughness' null space)
    v = rng.normal(size=300)
    a = np.column_stack([np.ones(300), q[:, 0], q[:, 1], q[:, 0] * q[:, 1]])
    ls = a @ np.linalg.lstsq(a, v, rcond=None)[0]
    np.testing.assert_allclose(filters.smoothing_spline(q, v, 1e-9), ls, atol=1e-5)
    with pytest.raises(ValueError, match=r"p must be in \(0, 1\)"):
        filters.smoothing_spline(q, v, 1.0)
    with pytest.raises(ValueError, match="at least 4 points"):
        filters.effective_spacing(q[:3])


def test_a_small_alpha_gets_enough_permutations_to_reject():
    # a permutation p is never below 1 / (R + 1): with alpha 0.001 (0.0005 for Moran) 499
    # permutations could never reject; R grows to 20 / alpha, beyond 19,999 the normal approximation
    p, v = _data(n=200, seed=3)
    v = np.sin(p[:, 0]) + 0.05 * np.random.default_rng(3).normal(size=200)  # strongly patterned
    m = stats.moran(p, v, alpha=0.005)
    assert m.permutations == 3_999 and m.p_permutation == pytest.approx(1 / 4000) and m.systematic
    tiny = stats.moran(p, v, alpha=0.0005)  # 39,999 permutations would be needed
    assert tiny.p_permutation is None and tiny.p_value < 1e-20 and tiny.systematic
