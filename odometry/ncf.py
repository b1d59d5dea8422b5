"""Normal covariance filter (NCF): Sec. III-A of Kovalenko et al., "Sensor Aware Lidar Odometry" (2019).

Each point's normal is the last right singular vector of its centred k x 3
neighbourhood matrix D (``odometry.normals``). The points carry measurement
noise; this module propagates it, to first order, to the covariance of the
normal and rejects the points whose normal is too uncertain.

Derivation (numpy's SVD convention ``D = U S V^T``: the columns v_0, v_1, v_2 of
V are the right singular vectors, s_0 >= s_1 >= s_2; the paper writes
``D = U S V`` with the singular vectors as rows of its V, and its ``-V Omega``
needs them as columns, i.e. this V). Differentiating ``D = U S V^T`` and using
that ``U^T dU`` and ``V^T dV`` are antisymmetric gives, for G = U^T dD V and
l in {0, 1} (Papadopoulo & Lourakis 2000)::

    dv_2 = -sum_l v_l omega_l,
    omega_l = (s_l G_l2 + s_2 G_2l) / (s_l^2 - s_2^2)

which is the paper's ``J^(ij) = -V Omega^(ij)`` with ``G = U^T Delta^(ij) V`` and
``C_l = [s_l, s_2] / (s_l^2 - s_2^2)``. Substituting ``U = D V S^-1``
(``s_2 U_j2 = d_j . v_2`` also when s_2 = 0) removes U. With the neighbour's
centred coordinates in the PCA frame ``a_jl = d_j . v_l`` and its height off
the fitted plane ``h_j = a_j2``, the Jacobian of the normal with respect to
neighbour point p_j is::

    J_j = dn / dp_j = -sum_{l=0,1} v_l w_jl^T / (lambda_l - lambda_2),
    w_jl = a_jl v_2 + h_j v_l,            lambda_l = s_l^2

(``J_j[:, c]`` is the paper's ``J^(j,c)``). It is the eigenvector perturbation of
the scatter matrix ``D^T D`` (eigenvalues lambda_l), as it must be.

Centring. D = H P with H = I - 11^T/k, so dn/dP = (dn/dD) H. The rows of dn/dD
(over the neighbour index j) are combinations of the columns of U, and
``1^T U = 1^T D V S^-1 = 0`` because D's columns sum to zero: the mean's
dependence on the points contributes nothing to first order, and propagating
the raw points' covariance through dn/dD is exact to first order
(``tests/test_ncf.py`` checks this against finite differences of the full
raw-points -> normal function, and ``sum_j J_j = 0``).

Covariance. With independent neighbour points of covariance Sigma_j::

    Cov[n] = sum_j J_j Sigma_j J_j^T = V_t C V_t^T,   V_t = [v_0 v_1],
    C_lm = sum_j w_jl^T Sigma_j w_jm / ((lambda_l - lambda_2)(lambda_m - lambda_2))

(the paper's ``J^T Cov[D] J`` has its transposes swapped, and its
``J = xi sum J J^T`` is this covariance for Sigma_j = xi I.) Cov[n] is rank 2,
tangent to the unit sphere at n; ``Cov[n] = Q diag(0, c_minor, c_major) Q^T``
is the paper's ``Q C Q^-1`` (normal-aligned frame) and the filter rejects a
point when ``c_major >= c_tau``. Units: the normal is a unit vector, so for
small angles its tangent components are tilt angles in radians and Cov[n] is
in rad^2; ``sqrt(c_major)`` is the 1-sigma tilt of the normal in its least
certain direction (``Q[:, 2]``).

Noise models (``Sigma_j``):

- ``IsotropicNoise(point_noise_std_m=sigma)``: the paper's sphere,
  ``Sigma_j = sigma^2 I``. The paper calls its xi a standard deviation but
  writes ``Cov[D] = xi I``, i.e. uses it as a variance; here the parameter is the
  standard deviation in metres and its square is propagated. Then
  ``C = sigma^2 diag((lambda_l + lambda_2) / (lambda_l - lambda_2)^2)``.
- ``RangeNoise(range_noise_std_m=sigma_r)``: sensor-aware, Gaussian range noise
  along each neighbour's own beam, ``Sigma_j = sigma_r^2 b_j b_j^T`` with
  ``b_j = p_j / |p_j|`` (sensor at the origin of the scan's frame). Optionally
  angular noise sigma_a (rad) across the beam adds ``(sigma_a |p_j|)^2 (I - b_j b_j^T)``.
- any per-point 3 x 3 covariances: ``normal_covariance_from_point_covariances``.

Where the linearisation is taken. The paper linearises at the observed (noisy)
matrix. That is fine while the noise moves the points much less than the
neighbourhood extends along its second axis (noise << sqrt(lambda_1 - lambda_2)),
but it fails, silently, for the sensor-aware model where the noise itself makes
the second axis: a neighbourhood on a single ring (common: far ground at grazing
incidence; VLP-16-like sensors with 2 deg between rings almost everywhere) is a
line widened only by range noise along the beams, the fitted "plane" contains
the beams, the propagation says the beam noise cannot tilt it (it cannot, to
first order), and the normal is off by the beam elevation. By default
(``noise_free_gaps=True``) the gaps lambda_l - lambda_2 are therefore taken
from the noise-free scatter, estimated by subtracting the noise's expected
scatter ``N = (k-1)/k sum_j Sigma_j`` (``lambda_l - v_l^T N v_l``), and a normal
whose second gap does not exceed the noise's sampling fluctuation
(``gap_significance_z`` standard deviations) gets an infinite covariance. For
isotropic noise N is a multiple of I, the gaps are unchanged, and the
significance test only marks normals whose predicted std is already above
~16 deg (k = 20): the paper's model is untouched at any sensible c_tau.
``noise_free_gaps=False`` is the paper's plain linearisation (and the right one
for noise-free input, e.g. linearising at a known truth). Degenerate
neighbourhoods (lambda_1 = lambda_2: a line, repeated points, non-finite
input) get an infinite covariance and are rejected.

Threshold. The odometry's c_tau is its config's ``ncf.max_normal_std_deg``:
5 deg by default (c_tau = radians(5)^2 = 7.6e-3 rad^2), chosen with the other
odometry defaults on simulated city and highway sequences. The functions here
default to a tighter 3 deg (``DEFAULT_C_TAU_RAD2 = radians(3)^2 = 2.74e-3
rad^2``), the error budget of one registration: a normal tilted by delta turns
a correct match offset t along the surface into a point-to-plane residual
t delta; with matches a few decimetres apart (voxel centroids against the
previous filtered cloud, t ~ 0.3-0.4 m) a 3 deg (0.052 rad) 1-sigma tilt costs
~1.5-2 cm, about the range noise of the sensors modelled here. 3 deg is also
the threshold of a measurement on one simulated SALO 32-beam scan (2 cm range
noise, k = 20, 15,000 query points; ``tests/test_ncf.py``, ``salo experiment
ncf``): the sensor-aware predicted std is calibrated (points predicted at 2-3
deg have a median true error of 2.9 deg, 3-4 deg: 4.0, 4-6 deg: 5.7), 3 deg is
about the 12th percentile of the predicted std and keeps normals with a median
true error of 2.4 deg against 4.7 deg for the rejected. So the budget keeps the
best normals of a scan, while over whole sequences the looser 5 deg, which keeps
more points, is the odometry's choice. The kept fraction depends strongly on k
and the sensor (k = 10 keeps 3 %): choose k for the sensor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .kernels.ncf import beam_noise_moments, range_noise_moments, tangent_covariance_in_frame
from .normals import NormalEstimate, local_pca

# The error-budget c_tau (module notes, "Threshold"): a 3 deg 1-sigma tilt of the normal in its
# least certain direction, c_tau = radians(3)^2 = 2.74e-3 rad^2; the default of the functions
# here, not of the odometry (its config's ncf.max_normal_std_deg, 5 deg).
DEFAULT_MAX_NORMAL_STD_DEG = 3.0
DEFAULT_C_TAU_RAD2 = math.radians(DEFAULT_MAX_NORMAL_STD_DEG) ** 2

# The noise-free second eigen-gap must exceed the noise's scatter along v_1 by
# this many standard deviations of its sampling fluctuation (see _resolved_gaps).
DEFAULT_GAP_SIGNIFICANCE_Z = 2.0

# lambda_1 - lambda_2 below this fraction of lambda_0: the normal is not defined.
DEGENERATE_GAP = 1e-12


@dataclass(frozen=True)
class IsotropicNoise:
    """The paper's noise model: every point has covariance ``point_noise_std_m^2 * I``.

    Attributes:
        point_noise_std_m: standard deviation of each coordinate, m (the paper's xi,
            read as a standard deviation; its square is the propagated variance).
    """

    point_noise_std_m: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.point_noise_std_m) and self.point_noise_std_m >= 0):
            raise ValueError(f"point_noise_std_m must be >= 0, got {self.point_noise_std_m}")


@dataclass(frozen=True)
class RangeNoise:
    """Sensor-aware noise: Gaussian range error along each point's own beam.

    ``Cov[p_j] = range_noise_std_m^2 b_j b_j^T + (angular_noise_std_rad |p_j|)^2 (I - b_j b_j^T)``
    with ``b_j`` the unit beam direction from the sensor to p_j.

    Attributes:
        range_noise_std_m: standard deviation of the range, m.
        angular_noise_std_rad: standard deviation of the beam direction in each of
            the two directions across the beam, rad (0: range noise only).
    """

    range_noise_std_m: float
    angular_noise_std_rad: float = 0.0

    def __post_init__(self) -> None:
        for name in ("range_noise_std_m", "angular_noise_std_rad"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be >= 0, got {v}")

    @classmethod
    def from_sensor(cls, sensor) -> RangeNoise:
        """From a ``simlidar.sensor.LidarModel``: its range noise and beam jitter."""
        return cls(
            range_noise_std_m=float(sensor.range_noise_std_m),
            angular_noise_std_rad=math.radians(float(sensor.angular_jitter_deg)),
        )


NoiseModel = IsotropicNoise | RangeNoise


@dataclass(frozen=True)
class NormalCovariance:
    """First-order covariance of each point's normal.

    Attributes:
        normals: (M, 3) unit normals (v_2, oriented towards the sensor).
        axes: (M, 3, 3) the PCA frame V (columns v_0, v_1, v_2 = normal).
        tangent_cov_rad2: (M, 2, 2) C, the covariance in the (v_0, v_1) basis, rad^2.
        cov_rad2: (M, 3, 3) Cov[n] in the scan's frame, rad^2 (rank 2, n in its null space).
        eigenvalues_rad2: (M, 3) ascending: 0, minor, major (the paper's C_22), rad^2.
        eigenvectors: (M, 3, 3) Q, columns: the normal, the minor axis, the major axis.
    Degenerate neighbourhoods have infinite covariance and eigenvalues (0, inf, inf).
    """

    normals: np.ndarray
    axes: np.ndarray
    tangent_cov_rad2: np.ndarray
    cov_rad2: np.ndarray
    eigenvalues_rad2: np.ndarray
    eigenvectors: np.ndarray

    @property
    def max_variance_rad2(self) -> np.ndarray:
        """(M,) the largest eigenvalue of Cov[n], rad^2 (compared with c_tau)."""
        return self.eigenvalues_rad2[:, 2]

    @property
    def max_std_rad(self) -> np.ndarray:
        """(M,) 1-sigma tilt of the normal in its least certain direction, rad."""
        return np.sqrt(self.eigenvalues_rad2[:, 2])

    def __len__(self) -> int:
        return len(self.normals)


def _pca_frame(
    neighbourhoods: np.ndarray, pca: NormalEstimate | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(P (M,k,3), pca, a (M,k,3) centred coordinates in the PCA frame, gaps (M,2) m^2)."""
    P = np.asarray(neighbourhoods, dtype=np.float64)
    pca = _checked_pca(P, pca)
    a = np.matmul(P - pca.mean[:, None, :], pca.axes)
    lam = pca.scatter_eigenvalues
    gaps = lam[:, :2] - lam[:, 2:3]
    return P, pca, a, gaps


def _checked_pca(P: np.ndarray, pca: NormalEstimate | None) -> NormalEstimate:
    """The PCA of neighbourhoods P (M, k, 3): ``pca`` checked for shape, or computed."""
    if P.ndim != 3 or P.shape[2] != 3 or P.shape[1] < 3:
        raise ValueError(f"neighbourhoods must be (M, k, 3) with k >= 3, got {P.shape}")
    if pca is None:
        return local_pca(P)
    if len(pca) != len(P) or pca.k != P.shape[1]:
        raise ValueError(f"pca is for {len(pca)} x {pca.k} points, neighbourhoods are {P.shape[:2]}")
    return pca


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(M,) sum over the neighbour axis of x * y, both (M, k)."""
    return np.einsum("mk,mk->m", x, y)


def _sym2(c00: np.ndarray, c01: np.ndarray, c11: np.ndarray) -> np.ndarray:
    """(M, 2, 2) symmetric matrices from their three (M,) entries."""
    return np.stack([np.stack([c00, c01], axis=1), np.stack([c01, c11], axis=1)], axis=1)


def _degenerate(pca: NormalEstimate, gaps: np.ndarray) -> np.ndarray:
    """(M,) bool: the normal is not defined at these eigen-gaps (M, 2)."""
    lam0 = pca.scatter_eigenvalues[:, 0]
    tol = DEGENERATE_GAP * lam0
    return ~(gaps[:, 1] > tol) | ~(gaps[:, 0] > tol) | ~np.isfinite(lam0)


def _resolved_gaps(
    gaps: np.ndarray, noise_scatter_diag: np.ndarray, k: int, significance_z: float
) -> tuple[np.ndarray, np.ndarray]:
    """Eigen-gaps of the noise-free scatter, and which of them the noise does not explain.

    ``E[D^T D] = D_true^T D_true + N`` with ``N = (k-1)/k sum_j Sigma_j`` (centred,
    independent noise), so ``lambda_l - v_l^T N v_l`` estimates the noise-free
    eigenvalue. The noise's sample scatter along v_1 fluctuates about its mean
    with relative standard deviation ``sqrt(2 / (k - 1))`` (a scaled chi-square
    with k - 1 degrees of freedom), so the second axis counts as resolved only
    when its noise-free gap exceeds ``significance_z`` such deviations.

    Args:
        gaps: (M, 2) observed ``lambda_l - lambda_2``, m^2.
        noise_scatter_diag: (M, 3) ``v_l^T N v_l``, m^2.
    Returns:
        ((M, 2) debiased gaps, (M,) bool unresolved).
    """
    n = noise_scatter_diag
    g = gaps - (n[:, :2] - n[:, 2:3])
    margin = significance_z * math.sqrt(2.0 / max(k - 1, 1)) * n[:, 1]
    return g, ~(g[:, 1] > margin)


def normal_jacobians(neighbourhoods: np.ndarray, pca: NormalEstimate | None = None) -> np.ndarray:
    """Jacobians of each normal with respect to each of its raw neighbour points.

    Args:
        neighbourhoods: (M, k, 3) raw neighbour points, m.
        pca: their ``local_pca`` (recomputed if None).

    Returns:
        (M, k, 3, 3) ``J[m, j] = d n_m / d p_j`` (1/m), for the oriented normal
        ``pca.normals``; centring included (it contributes nothing, see the module notes).
    """
    _, pca, a, gaps = _pca_frame(neighbourhoods, pca)
    V = pca.axes
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_g = 1.0 / gaps  # (M, 2)
    h = a[:, :, 2]
    J = np.zeros(a.shape[:2] + (3, 3))
    for lidx in (0, 1):
        v_l = V[:, None, :, lidx]  # (M, 1, 3)
        w = a[:, :, lidx, None] * V[:, None, :, 2] + h[:, :, None] * v_l  # (M, k, 3)
        J -= inv_g[:, None, lidx, None, None] * v_l[..., :, None] * w[..., None, :]
    J[_degenerate(pca, gaps)] = np.nan
    return J


def point_covariances(
    neighbourhoods: np.ndarray, noise: NoiseModel, sensor_origin_m: np.ndarray | None = None
) -> np.ndarray:
    """(M, k, 3, 3) covariance of every neighbour point under ``noise``, m^2.

    ``sensor_origin_m`` (3,) is where the beams start (default: the origin).
    """
    P = np.asarray(neighbourhoods, dtype=np.float64)
    eye = np.eye(3)
    if isinstance(noise, IsotropicNoise):
        return np.broadcast_to(noise.point_noise_std_m**2 * eye, P.shape[:2] + (3, 3)).copy()
    if isinstance(noise, RangeNoise):
        alpha, beta, b = _beam_terms(P, noise, sensor_origin_m)
        bbT = b[..., :, None] * b[..., None, :]
        return alpha[..., None, None] * eye + beta[..., None, None] * bbT
    raise TypeError(f"unknown noise model {type(noise).__name__}")


def _beam_terms(
    P: np.ndarray, noise: RangeNoise, sensor_origin_m: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sigma_j = alpha_j I + beta_j b_j b_j^T for the range (+ angular) model."""
    rel = P if sensor_origin_m is None else P - np.asarray(sensor_origin_m, dtype=np.float64)
    r = np.linalg.norm(rel, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        b = rel / r[..., None]
    alpha = (noise.angular_noise_std_rad * r) ** 2
    beta = noise.range_noise_std_m**2 - alpha
    return alpha, beta, b


def _finish(pca: NormalEstimate, C: np.ndarray, bad: np.ndarray) -> NormalCovariance:
    """Rotate C (M, 2, 2) back to the scan's frame and eigen-decompose it (closed form).

    ``bad`` (M,) marks normals without a finite covariance (set to inf).
    """
    V = pca.axes
    cov, eig, Q = tangent_covariance_in_frame(np.ascontiguousarray(V), np.ascontiguousarray(C))
    if np.any(bad):
        C[bad] = np.inf
        cov[bad] = np.inf
        eig[bad, 1:] = np.inf
        Q[bad] = np.nan  # (no covariance, no principal axes)
    return NormalCovariance(
        normals=pca.normals,
        axes=V,
        tangent_cov_rad2=C,
        cov_rad2=cov,
        eigenvalues_rad2=eig,
        eigenvectors=Q,
    )


def normal_covariance(
    neighbourhoods: np.ndarray,
    noise: NoiseModel,
    pca: NormalEstimate | None = None,
    sensor_origin_m: np.ndarray | None = None,
    noise_free_gaps: bool = True,
    gap_significance_z: float = DEFAULT_GAP_SIGNIFICANCE_Z,
) -> NormalCovariance:
    """Closed-form first-order covariance of each point's PCA normal.

    Args:
        neighbourhoods: (M, k, 3) raw neighbour points in the scan's sensor frame, m
            (e.g. ``cloud[estimate.neighbour_indices]``).
        noise: ``IsotropicNoise`` (the paper's) or ``RangeNoise`` (sensor-aware).
        pca: the neighbourhoods' ``NormalEstimate`` (recomputed if None).
        sensor_origin_m: (3,) beam origin for ``RangeNoise`` (default: the origin).
        noise_free_gaps: divide by the eigen-gaps of the noise-free scatter,
            estimated as ``lambda_l - v_l^T N v_l`` with ``N = (k-1)/k sum_j Sigma_j``
            the noise's expected scatter, and give an infinite covariance where
            the second axis is not resolved above the noise (``gap_significance_z``).
            Why: the linearisation is taken at the observed, noisy matrix. With
            range noise, a neighbourhood on a single ring (k points along one scan
            line: far ground at grazing incidence) is spread across the line only
            by the noise along the beams; the fitted plane then contains the beams,
            the plain linearisation predicts almost no normal noise, and the
            normal is in fact tilted by the beam's elevation. Isotropic noise
            adds the same to every eigenvalue: the gaps do not change, only the
            significance test applies. False: the paper's plain linearisation at
            the given matrix (use it for noise-free input, e.g. a known truth).
        gap_significance_z: how many standard deviations of the noise's sample
            scatter the noise-free gap must exceed (only with ``noise_free_gaps``).

    Returns:
        ``NormalCovariance`` (rad^2). O(M k) work: the range model's sums in one compiled pass.
    """
    P = np.asarray(neighbourhoods, dtype=np.float64)
    pca = _checked_pca(P, pca)
    k = P.shape[1]
    V = pca.axes
    mean = pca.mean
    if sensor_origin_m is not None:  # put the beams' origin at 0 (the PCA is translation-invariant)
        origin = np.asarray(sensor_origin_m, dtype=np.float64)
        P, mean = P - origin, mean - origin
    lam = pca.scatter_eigenvalues
    gaps = lam[:, :2] - lam[:, 2:3]
    if isinstance(noise, IsotropicNoise):
        a = np.matmul(P - mean[:, None, :], V)  # centred, in the PCA frame: a_jl = d_j . v_l
        a0, a1, h = a[:, :, 0], a[:, :, 1], a[:, :, 2]
        var = noise.point_noise_std_m**2
        # sum_j w_jl . w_jm = sum_j (a_jl a_jm + h_j^2 delta_lm)
        hh = _dot(h, h)
        num = var * _sym2(_dot(a0, a0) + hh, _dot(a0, a1), _dot(a1, a1) + hh)
        n_diag = np.full((len(P), 3), (k - 1) * var)
    elif isinstance(noise, RangeNoise):
        # z_jl = w_jl . b_j = (a_jl PV_j2 + h_j PV_jl) / r_j, the beam b_j = PV_j / r_j in the PCA frame
        # (PV_j = V^T p_j about the sensor); Sigma_j = alpha_j I + beta_j b_j b_j^T, and
        # v_l^T Sigma_j v_l = alpha_j + beta_j (PV_jl / r_j)^2: summed in one compiled pass
        num, n_diag = range_noise_moments(np.ascontiguousarray(P), np.ascontiguousarray(mean),
                                          np.ascontiguousarray(V), float(noise.range_noise_std_m)**2,
                                          float(noise.angular_noise_std_rad)**2)
        n_diag *= (k - 1) / k
    else:
        raise TypeError(f"unknown noise model {type(noise).__name__}")
    bad = _degenerate(pca, gaps)
    if noise_free_gaps:
        gaps, unresolved = _resolved_gaps(gaps, n_diag, k, gap_significance_z)
        bad |= unresolved | _degenerate(pca, gaps)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        C = num / (gaps[:, :, None] * gaps[:, None, :])
    return _finish(pca, C, bad)


def normal_covariance_from_point_covariances(
    neighbourhoods: np.ndarray,
    point_cov_m2: np.ndarray,
    pca: NormalEstimate | None = None,
    noise_free_gaps: bool = True,
    gap_significance_z: float = DEFAULT_GAP_SIGNIFICANCE_Z,
) -> NormalCovariance:
    """First-order covariance of each normal for arbitrary per-point covariances.

    ``Cov[n] = sum_j J_j Sigma_j J_j^T``, contracted in the PCA frame (the general
    form of ``normal_covariance``, which it reproduces for the two noise models).

    Args:
        neighbourhoods: (M, k, 3) raw neighbour points, m.
        point_cov_m2: (M, k, 3, 3) covariance of each neighbour point in the same
            frame, m^2 (anything broadcastable to it, e.g. (3, 3)).
        pca: the neighbourhoods' ``NormalEstimate`` (recomputed if None).
        noise_free_gaps, gap_significance_z: as in ``normal_covariance``.
    """
    P, pca, a, gaps = _pca_frame(neighbourhoods, pca)
    k = P.shape[1]
    V = pca.axes
    Sig = np.broadcast_to(np.asarray(point_cov_m2, dtype=np.float64), P.shape[:2] + (3, 3))
    Sig_pca = np.einsum("mil,mkij,mjn->mkln", V, Sig, V)  # V^T Sigma_j V
    h = a[:, :, 2]
    W = np.zeros(P.shape[:2] + (3, 2))  # w_jl in PCA coordinates: w_j0 = (h, 0, a_0), w_j1 = (0, h, a_1)
    W[:, :, 0, 0] = h
    W[:, :, 1, 1] = h
    W[:, :, 2, :] = a[:, :, :2]
    num = np.einsum("mkil,mkij,mkjn->mln", W, Sig_pca, W)
    bad = _degenerate(pca, gaps)
    if noise_free_gaps:
        n_diag = (k - 1) / k * np.einsum("mkll->ml", Sig_pca)
        gaps, unresolved = _resolved_gaps(gaps, n_diag, k, gap_significance_z)
        bad |= unresolved | _degenerate(pca, gaps)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        C = num / (gaps[:, :, None] * gaps[:, None, :])
    return _finish(pca, C, bad)


def normal_covariance_along_beams(
    neighbourhoods: np.ndarray,
    beams: np.ndarray,
    range_noise_std_m: float,
    pca: NormalEstimate | None = None,
    noise_free_gaps: bool = True,
    gap_significance_z: float = DEFAULT_GAP_SIGNIFICANCE_Z,
) -> NormalCovariance:
    """``normal_covariance`` for range noise along given beams, one per neighbour.

    For neighbourhoods of a map, whose points were measured from different sensor
    positions: ``Sigma_j = sigma_r^2 b_j b_j^T`` with ``b_j`` the unit beam that measured
    p_j. Closed form as the ``RangeNoise`` case (O(M k), no 3 x 3 per neighbour):
    with ``c_j = V^T b_j``, ``w_jl . b_j = h_j c_jl + a_jl c_j2``.

    Args:
        neighbourhoods: (M, k, 3) points, m. beams: (M, k, 3) unit beams.
        range_noise_std_m: sigma_r, m. Other arguments as ``normal_covariance``.
    """
    P = np.asarray(neighbourhoods, dtype=np.float64)
    pca = _checked_pca(P, pca)
    k = P.shape[1]
    # (sums over each neighbourhood of z_jl z_jm and c_jl^2, c_j = V^T b_j the beam in the PCA frame)
    zz, cc = beam_noise_moments(np.ascontiguousarray(P), np.ascontiguousarray(pca.mean),
                                np.ascontiguousarray(pca.axes),
                                np.ascontiguousarray(np.broadcast_to(np.asarray(beams, dtype=np.float64), P.shape)))
    var = range_noise_std_m**2
    num = var * zz
    lam = pca.scatter_eigenvalues
    gaps = lam[:, :2] - lam[:, 2:3]
    bad = _degenerate(pca, gaps)
    if noise_free_gaps:
        n_diag = (k - 1) / k * var * cc
        gaps, unresolved = _resolved_gaps(gaps, n_diag, k, gap_significance_z)
        bad |= unresolved | _degenerate(pca, gaps)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        C = num / (gaps[:, :, None] * gaps[:, None, :])
    return _finish(pca, C, bad)


def ncf_keep(
    normal_cov: NormalCovariance | np.ndarray, c_tau_rad2: float = DEFAULT_C_TAU_RAD2
) -> np.ndarray:
    """The filter: keep a point when the largest eigenvalue of Cov[n] is below c_tau.

    Args:
        normal_cov: a ``NormalCovariance``, or (M,) largest eigenvalues, rad^2.
        c_tau_rad2: threshold on the normal's variance in its least certain
            direction, rad^2 (default ``DEFAULT_C_TAU_RAD2``, a 3 deg 1-sigma tilt, the
            error budget and measurement of the module notes; the odometry passes its
            config's ``ncf.max_normal_std_deg``, 5 deg by default).

    Returns:
        (M,) bool; non-finite variances (degenerate neighbourhoods) are rejected.
    """
    var = normal_cov.max_variance_rad2 if isinstance(normal_cov, NormalCovariance) else normal_cov
    var = np.asarray(var, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return var < c_tau_rad2


def normal_covariance_filter(
    neighbourhoods: np.ndarray,
    noise: NoiseModel,
    c_tau_rad2: float = DEFAULT_C_TAU_RAD2,
    pca: NormalEstimate | None = None,
    sensor_origin_m: np.ndarray | None = None,
    noise_free_gaps: bool = True,
    gap_significance_z: float = DEFAULT_GAP_SIGNIFICANCE_Z,
) -> tuple[np.ndarray, NormalCovariance]:
    """``normal_covariance`` then ``ncf_keep``: returns ((M,) keep mask, NormalCovariance)."""
    nc = normal_covariance(
        neighbourhoods,
        noise,
        pca=pca,
        sensor_origin_m=sensor_origin_m,
        noise_free_gaps=noise_free_gaps,
        gap_significance_z=gap_significance_z,
    )
    return ncf_keep(nc, c_tau_rad2), nc
