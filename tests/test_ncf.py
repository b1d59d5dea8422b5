"""Normal covariance filter: closed-form propagation against finite differences and Monte Carlo.

Neighbourhoods are built the way a lidar samples them: a small grid of beams
from the origin (4 rings x 5 columns, 1 deg x 0.5 deg apart, about 10 m away)
cast onto one, two or three planes. The predicted normal covariance is
linearised at the noise-free neighbourhood and compared with the covariance of
normals recomputed (independently, by numpy's SVD of the centred matrix, mean
included) over N_DRAWS noisy copies. With N_DRAWS = 4000 the sample variance
has a relative standard error of sqrt(2 / N) = 2.2 %; the first-order model
adds a bias of order sigma^2 / (lambda_1 - lambda_2), a few % in these cases
(chosen so that the noise is well below the neighbourhood's second extent,
the regime the model is for), so 20 % leaves room for both with margin and
still catches any wrong factor (2, a missing term, a sign).
"""

from __future__ import annotations

import numpy as np
import pytest

from odometry.ncf import (
    DEFAULT_C_TAU_RAD2,
    IsotropicNoise,
    RangeNoise,
    ncf_keep,
    normal_covariance,
    normal_covariance_filter,
    normal_covariance_from_point_covariances,
    normal_jacobians,
    point_covariances,
)
from odometry.normals import angle_between_normals_rad, estimate_normals, local_pca

SIGMA_M = 0.02
N_DRAWS = 4000
S2 = 1.0 / np.sqrt(2.0)
WALLS = [((S2, S2, 0.0), 10.0 * S2), ((S2, -S2, 0.0), 10.0 * S2)]  # concave vertical edge at x = 10
GROUND = [((0.0, 0.0, -1.0), 1.7)]  # ground 1.7 m below the sensor


def beam_grid(az0_deg, el0_deg, n_el=4, n_az=5, d_el_deg=1.0, d_az_deg=0.5) -> np.ndarray:
    """(n_el * n_az, 3) unit beam directions around (az0, el0)."""
    e = np.radians(el0_deg + (np.arange(n_el) - (n_el - 1) / 2) * d_el_deg)
    a = np.radians(az0_deg + (np.arange(n_az) - (n_az - 1) / 2) * d_az_deg)
    E, A = np.meshgrid(e, a, indexing="ij")
    E, A = E.ravel(), A.ravel()
    return np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=1)


def cast(dirs: np.ndarray, planes) -> np.ndarray:
    """First hit of beams from the origin on planes ``n . x = c`` (a region around the origin)."""
    ts = []
    for n, c in planes:
        dn = dirs @ np.asarray(n, dtype=float)
        with np.errstate(divide="ignore"):
            t = np.where(dn > 0, c / dn, np.inf)
        ts.append(t)
    return dirs * np.min(ts, axis=0)[:, None]


def case(name: str) -> np.ndarray:
    """(k, 3) a neighbourhood: 'plane', 'edge' (two walls) or 'corner' (two walls and ground)."""
    if name == "plane":
        n = np.array([np.cos(0.6), np.sin(0.6), 0.3])
        return cast(beam_grid(17.0, -2.0), [(n / np.linalg.norm(n), 10.0)])
    if name == "edge":  # 2 columns on one wall, 3 on the other (the edge between columns)
        return cast(beam_grid(0.3, 0.0), WALLS)
    if name == "corner":  # 12 points on one wall, 3 on the other, 5 on the ground
        return cast(beam_grid(0.55, -8.6), WALLS + GROUND)
    raise ValueError(name)


def noisy_copies(P: np.ndarray, noise, n_draws: int, seed: int) -> np.ndarray:
    """(n_draws, k, 3) copies of P with noise drawn from ``noise``."""
    rng = np.random.default_rng(seed)
    if isinstance(noise, IsotropicNoise):
        return P + rng.normal(size=(n_draws,) + P.shape) * noise.point_noise_std_m
    b = P / np.linalg.norm(P, axis=1, keepdims=True)
    return P + rng.normal(size=(n_draws, len(P), 1)) * noise.range_noise_std_m * b


def svd_normals(P: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(n, 3) last right singular vectors of the centred (n, k, 3) matrices, signed like ``reference``."""
    D = P - P.mean(axis=1, keepdims=True)
    n = np.linalg.svd(D, full_matrices=False)[2][:, 2, :]
    return n * np.sign(n @ reference)[:, None]


def monte_carlo_cov(P: np.ndarray, noise, n_draws: int = N_DRAWS, seed: int = 0) -> np.ndarray:
    """(3, 3) empirical covariance of the normal of P under ``noise``."""
    ref = local_pca(P[None]).normals[0]
    return np.cov(svd_normals(noisy_copies(P, noise, n_draws, seed), ref).T)


def mc_agreement(name: str, noise, seed: int = 0) -> dict:
    """Predicted (at the noise-free neighbourhood) vs Monte Carlo normal covariance."""
    P = case(name)
    pred = normal_covariance(P[None], noise, noise_free_gaps=False)
    emp = monte_carlo_cov(P, noise, seed=seed)
    w, Q = np.linalg.eigh(emp)
    return {
        "pred_max": float(pred.max_variance_rad2[0]),
        "emp_max": float(w[2]),
        "ratio": float(w[2] / pred.max_variance_rad2[0]),
        "axis_cos": float(abs(Q[:, 2] @ pred.eigenvectors[0, :, 2])),
        "frobenius_rel": float(np.linalg.norm(emp - pred.cov_rad2[0]) / np.linalg.norm(pred.cov_rad2[0])),
    }


NOISES = {"isotropic": IsotropicNoise(point_noise_std_m=SIGMA_M), "range": RangeNoise(range_noise_std_m=SIGMA_M)}


CASES = ["plane", "edge", "corner"]
SEEDS = {(c, m): 100 * i + j for i, c in enumerate(CASES) for j, m in enumerate(NOISES)}


@pytest.mark.parametrize("name", CASES)
@pytest.mark.parametrize("model", list(NOISES))
def test_predicted_covariance_matches_monte_carlo(name, model):
    r = mc_agreement(name, NOISES[model], seed=SEEDS[name, model])
    assert abs(r["ratio"] - 1.0) < 0.20, r
    # The direction of largest uncertainty agrees too (within ~18 deg).
    assert r["axis_cos"] > 0.95, r


@pytest.mark.parametrize("name", CASES)
@pytest.mark.parametrize("model", list(NOISES))
def test_prediction_from_noisy_data_matches_monte_carlo(name, model):
    """In use the covariance is evaluated at the observed, noisy neighbourhood (with the
    noise-free gaps): its median over noisy draws still matches the Monte Carlo."""
    noise = NOISES[model]
    r = mc_agreement(name, noise, seed=SEEDS[name, model])
    P = noisy_copies(case(name), noise, 300, seed=SEEDS[name, model] + 7)
    predicted = np.median(normal_covariance(P, noise).max_variance_rad2)
    assert abs(predicted / r["emp_max"] - 1.0) < 0.20, (predicted, r)


@pytest.mark.parametrize("name", ["plane", "edge", "corner"])
def test_jacobian_matches_finite_differences_of_the_full_function(name):
    """dn/dp_j in closed form = central differences of raw points -> centring -> SVD -> normal.

    The centring is inside the differenced function, so this also shows that the
    mean's dependence on the points adds nothing; and the Jacobians sum to zero
    (translating all points leaves the normal unchanged).
    """
    P = case(name)
    J = normal_jacobians(P[None])[0]  # (k, 3, 3)
    ref = local_pca(P[None]).normals[0]
    eps = 1e-6
    fd = np.zeros_like(J)
    for j in range(len(P)):
        for c in range(3):
            Pp, Pm = P.copy(), P.copy()
            Pp[j, c] += eps
            Pm[j, c] -= eps
            n = svd_normals(np.stack([Pp, Pm]), ref)
            fd[j, :, c] = (n[0] - n[1]) / (2 * eps)
    scale = np.abs(J).max()
    assert np.abs(J - fd).max() < 1e-6 * max(scale, 1.0)
    assert np.abs(J.sum(axis=0)).max() < 1e-9 * max(scale, 1.0)


def test_isotropic_closed_form():
    """Sigma = s^2 I gives C = s^2 diag((lambda_l + lambda_2) / (lambda_l - lambda_2)^2) in the PCA frame."""
    P = case("edge")[None]
    pca = local_pca(P)
    lam = pca.scatter_eigenvalues[0]
    nc = normal_covariance(P, IsotropicNoise(SIGMA_M), noise_free_gaps=False)
    expect = SIGMA_M**2 * (lam[:2] + lam[2]) / (lam[:2] - lam[2]) ** 2
    np.testing.assert_allclose(np.diag(nc.tangent_cov_rad2[0]), expect, rtol=1e-9)
    assert abs(nc.tangent_cov_rad2[0, 0, 1]) < 1e-9 * expect.max()


@pytest.mark.parametrize("noise_free_gaps", [False, True])
def test_fast_paths_equal_the_general_contraction(noise_free_gaps):
    """Each model's shortcut = sum_j J_j Sigma_j J_j^T with the full per-point covariance."""
    rng = np.random.default_rng(5)
    P = np.stack([case(c) for c in ("plane", "edge", "corner")])
    P = P + rng.normal(size=P.shape) * 0.01  # generic (noisy) neighbourhoods, too
    for noise in (
        IsotropicNoise(0.03),
        RangeNoise(0.02),
        RangeNoise(0.02, angular_noise_std_rad=np.radians(0.1)),
    ):
        fast = normal_covariance(P, noise, noise_free_gaps=noise_free_gaps)
        general = normal_covariance_from_point_covariances(
            P, point_covariances(P, noise), noise_free_gaps=noise_free_gaps
        )
        np.testing.assert_allclose(fast.cov_rad2, general.cov_rad2, rtol=1e-9, atol=1e-15)
        # ... and = the literal sum over the explicit Jacobians (paper's Eq. 1, transposes fixed).
        J = normal_jacobians(P)
        Sig = point_covariances(P, noise)
        literal = np.einsum("mjab,mjbc,mjdc->mad", J, Sig, J)
        if not noise_free_gaps:
            np.testing.assert_allclose(fast.cov_rad2, literal, rtol=1e-9, atol=1e-15)


def test_covariance_structure():
    """Rank 2 and tangent: Cov[n] n = 0; Q orthonormal; Cov = Q diag(eig) Q^T; eig ascending."""
    rng = np.random.default_rng(2)
    P = np.stack([case(c) for c in ("plane", "edge", "corner")]) + rng.normal(size=(3, 20, 3)) * 0.005
    nc = normal_covariance(P, RangeNoise(0.02))
    n = nc.normals
    assert np.abs(np.einsum("mij,mj->mi", nc.cov_rad2, n)).max() < 1e-12 * nc.max_variance_rad2.max()
    Q = nc.eigenvectors
    np.testing.assert_allclose(np.einsum("mji,mjk->mik", Q, Q), np.broadcast_to(np.eye(3), (3, 3, 3)), atol=1e-12)
    rebuilt = np.einsum("mij,mj,mkj->mik", Q, nc.eigenvalues_rad2, Q)
    np.testing.assert_allclose(rebuilt, nc.cov_rad2, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(Q[:, :, 0], n, atol=1e-12)
    assert np.all(np.diff(nc.eigenvalues_rad2, axis=1) >= 0)
    np.testing.assert_allclose(nc.max_std_rad, np.sqrt(nc.eigenvalues_rad2[:, 2]))


def test_degenerate_and_invalid_neighbourhoods_are_rejected():
    line = np.zeros((1, 10, 3))
    line[0, :, 0] = 10.0
    line[0, :, 1] = np.linspace(-0.5, 0.5, 10)  # collinear: the normal is undefined
    same = np.full((1, 10, 3), 5.0)  # all points identical
    nanpt = case("plane")[None].copy()
    nanpt[0, 3, 1] = np.nan
    for P in (line, same, nanpt):
        for noise in NOISES.values():
            keep, nc = normal_covariance_filter(P, noise, c_tau_rad2=1e9)
            assert not keep[0]
    keep, _ = normal_covariance_filter(case("plane")[None], NOISES["range"], c_tau_rad2=1e9)
    assert keep[0]


def single_ring_ground(k=20, range_m=30.0, seed=0):
    """k returns of one ring on flat ground (grazing incidence), SALO-like azimuth step, with range noise."""
    el = np.arctan2(-1.9, range_m)
    az = np.radians(0.08) * (np.arange(k) - k / 2)
    b = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.full(k, np.sin(el))], axis=1)
    true = b * (1.9 / -b[:, 2])[:, None]
    rng = np.random.default_rng(seed)
    return true, true + rng.normal(size=(k, 1)) * SIGMA_M * b, el


def test_single_ring_grazing_neighbourhood_is_unresolved():
    """Range noise alone spreads one scan line into a 'plane' containing the beams.

    The plain linearisation at that noisy matrix then predicts almost no normal
    noise, while the estimated normal is tilted from the ground's by about the
    beam elevation. With the noise-free gaps the second axis is explained by the
    noise and the point is rejected.
    """
    true, noisy, el = single_ring_ground()
    P = noisy[None]
    plain = normal_covariance(P, NOISES["range"], noise_free_gaps=False)
    tilt = angle_between_normals_rad(plain.normals, np.array([[0.0, 0.0, 1.0]]))[0]
    assert tilt > 0.5 * abs(el)  # the fit is dragged towards the beams (elevation -3.6 deg)
    assert plain.max_std_rad[0] < np.radians(0.5)  # ... yet the plain model is confident
    resolved = normal_covariance(P, NOISES["range"])
    assert np.isinf(resolved.max_variance_rad2[0])
    assert not ncf_keep(resolved)[0]
    # A neighbourhood whose extent the noise does not explain is unaffected.
    Q = case("plane")[None]
    a = normal_covariance(Q, NOISES["range"], noise_free_gaps=False).max_variance_rad2
    b = normal_covariance(Q, NOISES["range"]).max_variance_rad2
    assert np.isfinite(b[0]) and abs(b[0] / a[0] - 1) < 0.2


def test_noise_free_gaps_do_not_change_the_isotropic_model():
    rng = np.random.default_rng(4)
    P = np.stack([case(c) for c in ("plane", "edge", "corner")]) + rng.normal(size=(3, 20, 3)) * 0.01
    a = normal_covariance(P, NOISES["isotropic"], noise_free_gaps=False)
    b = normal_covariance(P, NOISES["isotropic"], noise_free_gaps=True, gap_significance_z=0.0)
    np.testing.assert_allclose(a.cov_rad2, b.cov_rad2, rtol=1e-12)


def test_noise_models_validate():
    with pytest.raises(ValueError):
        IsotropicNoise(-0.01)
    with pytest.raises(ValueError):
        RangeNoise(0.02, angular_noise_std_rad=-1.0)
    with pytest.raises(ValueError):
        normal_covariance(np.zeros((3, 2, 3)), NOISES["range"])


def test_range_noise_from_sensor():
    from simlidar.sensor import load_preset

    s = load_preset("vlp16").with_overrides(angular_jitter_deg=0.05)
    noise = RangeNoise.from_sensor(s)
    assert noise.range_noise_std_m == s.range_noise_std_m
    assert noise.angular_noise_std_rad == pytest.approx(np.radians(0.05))


# ---------------------------------------------------------------- simulated scan


def small_world():
    """Ground, five buildings, a sphere, a pole and a car around the origin."""
    import trimesh

    from simlidar.world import World

    parts = []
    g = trimesh.creation.box((200, 200, 1.0))
    g.apply_translation((0, 0, -0.5))
    parts.append((g, "ground"))
    for c, s in [
        ((15, 8, 3), (6, 4, 6)),
        ((22, -10, 4), (8, 6, 8)),
        ((-14, 5, 2.5), (5, 9, 5)),
        ((-8, -16, 5), (20, 3, 10)),
        ((35, 2, 6), (3, 20, 12)),
    ]:
        b = trimesh.creation.box(s)
        b.apply_translation(c)
        parts.append((b, "building"))
    sph = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    sph.apply_translation((10, -4, 2.0))
    parts.append((sph, "object"))
    pole = trimesh.creation.cylinder(radius=0.3, height=6, sections=32)
    pole.apply_translation((6, 6, 3))
    parts.append((pole, "pole"))
    car = trimesh.creation.box((4.5, 1.8, 1.5))
    car.apply_transform(trimesh.transformations.rotation_matrix(0.5, (0, 0, 1)))
    car.apply_translation((-6, -5, 0.75))
    parts.append((car, "vehicle"))
    V, F, ids, labels, base = [], [], [], [], 0
    for i, (m, lab) in enumerate(parts):
        V.append(m.vertices)
        F.append(m.faces + base)
        ids.append(np.full(len(m.faces), i))
        labels.append(lab)
        base += len(m.vertices)
    return World(np.vstack(V), np.vstack(F), np.concatenate(ids), labels, source="ncf test world")


@pytest.fixture(scope="module")
def simulated_scan():
    from simlidar.sensor import load_preset
    from simlidar.sweep import SweepSimulator
    from simlidar.trajectory import SampledTrajectory

    sensor = load_preset("salo32").with_overrides(range_noise_std_m=SIGMA_M)
    T = np.eye(4)
    T[2, 3] = 1.9  # roof height
    sim = SweepSimulator(small_world(), sensor, seed=7, motion_distortion=False, threads=2)
    return sensor, sim.sweep(SampledTrajectory(np.array([0.0]), T[None]), 0.0)


@pytest.mark.parametrize("model", ["isotropic", "range"])
def test_kept_normals_are_better_than_rejected_ones_on_a_simulated_scan(simulated_scan, model):
    """At the error-budget c_tau (a 3 deg 1-sigma tilt, see ncf.DEFAULT_C_TAU_RAD2), NCF
    keeps points whose estimated normals are closer to the mesh truth than those it rejects."""
    sensor, scan = simulated_scan
    rng = np.random.default_rng(0)
    query = rng.choice(len(scan), size=15000, replace=False)
    est = estimate_normals(scan.xyz, k=20, query_points=scan.xyz[query])
    noise = IsotropicNoise(SIGMA_M) if model == "isotropic" else RangeNoise.from_sensor(sensor)
    keep, nc = normal_covariance_filter(scan.xyz[est.neighbour_indices], noise, DEFAULT_C_TAU_RAD2, pca=est)
    err = angle_between_normals_rad(est.normals, scan.normal[query])
    assert 0.02 < keep.mean() < 0.98  # a real split, not all or nothing
    assert np.median(err[keep]) < np.median(err[~keep])


def test_beam_covariance_matches_the_general_propagation():
    """Per-neighbour beams (a map's points, seen from different places): the closed form equals
    the general first-order propagation with Sigma_j = sigma^2 b_j b_j^T."""
    from odometry.ncf import normal_covariance_along_beams, normal_covariance_from_point_covariances

    rng = np.random.default_rng(11)
    M, k = 50, 12
    base = rng.normal(size=(M, 1, 3)) * 10
    P = base + rng.normal(size=(M, k, 3)) * [0.5, 0.4, 0.05]
    origins = rng.normal(size=(M, k, 3)) * 8  # each neighbour measured from its own place
    b = P - origins
    b /= np.linalg.norm(b, axis=2, keepdims=True)
    sigma = 0.03
    fast = normal_covariance_along_beams(P, b, sigma)
    slow = normal_covariance_from_point_covariances(P, sigma**2 * b[..., :, None] * b[..., None, :])
    ok = np.isfinite(slow.cov_rad2).all(axis=(1, 2))
    assert ok.sum() > 40
    assert np.allclose(fast.cov_rad2[ok], slow.cov_rad2[ok], rtol=1e-9, atol=1e-15)
    assert np.array_equal(np.isfinite(fast.eigenvalues_rad2[:, 2]), np.isfinite(slow.eigenvalues_rad2[:, 2]))
