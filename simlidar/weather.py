"""Fog, rain and snow as a lidar sees them: the receiver's power model and the weather's echoes.

Two sections of a sensor description (``simlidar.sensor.LidarModel``), both off by default:

- ``receiver``: the lidar equation's receiver and beam. When on, every echo has a
  received power (relative units, the intensity model's own)::

      p = rho * |cos a|^k * xi(R) * T(R)^2 / R^2,     T(R)^2 = exp(-2 alpha R)

  (``rho`` the surface's reflectance, ``a`` the angle of incidence, ``k`` the
  sensor's ``intensity_incidence_exponent``, ``xi`` the bistatic overlap of the
  transmitter's beam and the receiver's field of view, rising linearly from 0 at
  ``overlap_start_m`` to 1 at ``overlap_full_m``, ``alpha`` the extinction
  coefficient of the air, 0 in clear air), and an echo is detected only when
  ``p >= p_min = 0.1 / detection_range_m^2``: a 10 % Lambertian target at normal
  incidence is just detected at ``detection_range_m`` in clear air. Far, dark and
  grazing surfaces drop first.
- ``weather``: ``fog``, ``rain`` and ``snow``, each with its switch ``enabled``
  (weather needs the receiver: it acts on the received power).

Fog (Hahner et al., "Fog Simulation on Real LiDAR Point Clouds for 3D Object
Detection in Adverse Weather", ICCV 2021, from the paper's equations).
The meteorological optical range (MOR, the distance over which a beam keeps 5 %
of its power) sets ``alpha = ln(20) / MOR`` and the backscattering coefficient
``beta = beta_times_mor / MOR`` (1/(m sr); 0.046 / MOR is Hahner et al.'s). The
received power is the emitted pulse ``P0(t) = sin^2(pi t / (2 tau_H))``,
``0 <= t <= 2 tau_H``, convolved with the channel's impulse response. A surface
at ``R0`` (a hard target, Lambertian, ``beta_0 = rho cos a / pi``) gives an echo
``exp(-2 alpha R0)`` times its clear-air echo. The fog itself is a *soft target*
filling the beam up to ``R0``; with ``L = c tau_H`` its echo at pulse position
``R`` is::

    p_soft(R) = pi * beta * S(R; R0),
    S(R; R0) = integral over R' in [R - L, min(R, R0)] of sin^2(pi (R - R') / L) xi(R') exp(-2 alpha R') / R'^2 dR'

in the units of ``p`` (the hard echo's peak is its ``p``; the factor ``pi``
is the Lambertian target's). A pulse's range is reported as its peak position
minus ``L / 2`` (which puts a hard target at ``R0``). The receiver blanks echoes
reported nearer than ``min_range_m``, and a soft echo reported at or beyond
``R0`` merges into the surface's, so the soft echo's peak is taken over reported
ranges in ``[min_range_m, R0)``. Two choices of this model beyond the paper
(documented, each a key): the soft echo's peak power fluctuates from beam to
beam (the fog's patchiness and the receiver's noise) as a Gamma variable of
mean 1 and relative standard deviation ``backscatter_fluctuation`` (0: none);
and since the soft echo is
broad and flat, the receiver places it anywhere in its half-power span (the
reported ranges where ``S`` is at least half its peak), uniformly.

Rain and snow: particles per beam. The precipitation intensity (mm/h) sets an
exponential drop-size distribution ``N(D) = N0 exp(-Lambda D)`` (m^-3 mm^-1, D
in mm): for rain Marshall & Palmer (1948), ``N0 = 8000``, ``Lambda = 4.1
I^-0.21``; for snow Gunn & Marshall (1958), ``N0 = 3800 I^-0.87``, ``Lambda =
2.55 I^-0.48``, D the melted diameter, the flake's optical diameter
``flake_diameter_factor`` times it (2.15: flakes of 0.1 g/cm^3). Each particle
type adds an extinction ``alpha = pi f^2 N0 / Lambda^3 x 1e-6`` per m (the geometric cross-section
with an extinction efficiency of 2) to the air's. A
particle of optical diameter ``D`` in the beam at ``R`` (the beam a cylinder of
diameter ``w(R) = beam_exit_diameter_m + R * footprint_divergence_rad``, uniformly
lit) echoes ``p = rho_p min(1, (D / w)^2) xi(R) T(R)^2 / R^2`` (``rho_p`` the
particle's Lambertian-equivalent reflectance): it is detected when ``D >= D_min(R)
= w R sqrt(p_min / (rho_p xi T^2))`` (and ``D_min <= w``), so detectable particles
lie along the beam at the rate, per metre::

    lambda(R) = (pi / 4) w(R)^2 (N0 / Lambda) exp(-Lambda D_min(R) / f)

and a beam whose surface is at ``R0`` meets ``Poisson(mu)`` of them, ``mu =
integral of lambda over [min_range_m, R0)``, each at a range drawn from
``lambda`` and of diameter ``D_min(R) + f Exp(Lambda)`` (the exponential
distribution is memoryless). Particles occlude the surface through the
extinction (the mean of many partial occlusions), and return early.

Which echo a beam reports: the sensor's ``return_mode`` over its detected echoes
(the surface's, the fog's, the particles'): ``strongest`` (Hahner et al.'s rule:
a false return replaces the surface's when its echo is stronger), ``first`` or
``last``. A beam none of whose echoes is detected returns nothing (a dropout).

``WeatherModel`` holds the tables one sensor needs; ``WeatherModel.select`` picks
each beam's echo for a block of rays from the block's own generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from paramspec import Params, param, section

SPEED_OF_LIGHT_M_S = 299_792_458.0
# The receiver's threshold is stated as the range of a target of this reflectance (datasheets quote 10 %).
DETECTION_REFLECTANCE = 0.1
# What a return is, per the truth's ``weather`` field.
KINDS = ("surface", "fog", "rain", "snow")
SURFACE, FOG, RAIN, SNOW = range(4)
# Drop-size distributions N(D) = N0 exp(-Lambda D), N0 in m^-3 mm^-1, Lambda in 1/mm, rate I in mm/h.
MARSHALL_PALMER_N0 = 8000.0  # rain (Marshall & Palmer 1948)
MARSHALL_PALMER_LAMBDA = (4.1, -0.21)  # Lambda = 4.1 I^-0.21
GUNN_MARSHALL_N0 = (3800.0, -0.87)  # snow, melted diameters (Gunn & Marshall 1958): N0 = 3800 I^-0.87
GUNN_MARSHALL_LAMBDA = (2.55, -0.48)  # Lambda = 2.55 I^-0.48
# Table steps: pulse positions and surface ranges of the fog's echo, ranges of the particles' rate, m.
_FOG_STEP_M = 0.01
_PARTICLE_STEP_M = 0.01


@dataclass(frozen=True)
class ReceiverParams(Params):
    """the receiver's power model: detection threshold, pulse, near-range overlap, beam footprint (off: ideal)

    Off, every hit within max_range_m returns; on, an echo is detected when its received power reaches the
    power of a 10 % target at ``detection_range_m`` (``simlidar.weather``).
    """

    section_name = "receiver"
    enabled: bool = param(False, "received power decides which echoes are detected (weather needs it)")
    detection_range_m: float = param(100.0, "clear-air range at which a 10 % Lambertian target at normal incidence "
                                     "is just detected: echoes weaker than that target's are lost", above=0.0)
    pulse_width_s: float = param(2e-8, "tau_H: half-power width of the emitted pulse (sin^2 pulse of length "
                                 "2 tau_H); the fog's echo spreads over c tau_H", above=0.0, max=1e-6)
    overlap_start_m: float = param(1.0, "the receiver sees none of the beam nearer than this; the overlap rises "
                                   "linearly to 1 at overlap_full_m", min=0.0)
    overlap_full_m: float = param(10.0, "range from which the receiver sees the whole beam", above=0.0)
    beam_exit_diameter_m: float = param(0.01, "diameter of the beam where it leaves the sensor (the footprint that "
                                        "rain and snow particles intercept)", above=0.0)
    footprint_divergence_deg: float = param(0.17, "full angle by which the beam's footprint widens with range",
                                            min=0.0, max=5.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.overlap_start_m > self.overlap_full_m:
            raise self.error(f"must be <= overlap_full_m ({self.overlap_start_m} > {self.overlap_full_m})",
                             "overlap_start_m")

    @property
    def min_power(self) -> float:
        """p_min: the weakest received power detected (relative units of ``p``)."""
        return DETECTION_REFLECTANCE / self.detection_range_m**2

    def overlap(self, r: np.ndarray) -> np.ndarray:
        """xi(r): the share of the beam the receiver sees at range r (m), in [0, 1]."""
        a, b = self.overlap_start_m, self.overlap_full_m
        if b <= a:
            return (np.asarray(r, dtype=float) >= b).astype(float)
        return np.clip((np.asarray(r, dtype=float) - a) / (b - a), 0.0, 1.0)

    def footprint_m(self, r: np.ndarray) -> np.ndarray:
        """w(r): the beam's diameter at range r (m), m."""
        return self.beam_exit_diameter_m + np.asarray(r, dtype=float) * math.radians(self.footprint_divergence_deg)


@dataclass(frozen=True)
class FogParams(Params):
    """fog: two-way attenuation and the fog's own backscatter near the sensor (Hahner et al., ICCV 2021)"""

    section_name = "fog"
    enabled: bool = param(False, "fog on the beams")
    mor_m: float = param(100.0, "meteorological optical range (visibility): alpha = ln(20) / mor_m", above=0.0)
    beta_times_mor: float = param(0.046, "backscattering coefficient beta (1/(m sr)) times mor_m (0.046: Hahner et "
                                  "al.'s)", unit="1/sr", min=0.0)
    backscatter_fluctuation: float = param(0.5, "relative standard deviation of the fog echo's peak power from beam "
                                           "to beam (Gamma, mean 1: the fog's patchiness and the receiver's noise; "
                                           "0: none)", min=0.0, max=10.0)

    @property
    def alpha_per_m(self) -> float:
        """Extinction coefficient, 1/m (0 when off)."""
        return math.log(20.0) / self.mor_m if self.enabled else 0.0

    @property
    def beta_per_m_sr(self) -> float:
        """Backscattering coefficient, 1/(m sr)."""
        return self.beta_times_mor / self.mor_m


@dataclass(frozen=True)
class RainParams(Params):
    """rain: drops along the beam (Marshall-Palmer sizes): extinction, early returns"""

    section_name = "rain"
    enabled: bool = param(False, "rain on the beams")
    rate_mm_h: float = param(5.0, "precipitation intensity", unit="mm/h", above=0.0, max=500.0)
    drop_reflectance: float = param(0.02, "Lambertian-equivalent reflectance of a drop's echo (water reflects about "
                                    "2 % at normal incidence)", above=0.0, max=1.0)

    def distribution(self) -> tuple[float, float]:
        """(N0 m^-3 mm^-1, Lambda 1/mm) of Marshall & Palmer at this rate."""
        a, b = MARSHALL_PALMER_LAMBDA
        return MARSHALL_PALMER_N0, a * self.rate_mm_h**b


@dataclass(frozen=True)
class SnowParams(Params):
    """snow: flakes along the beam (Gunn-Marshall sizes): extinction, early returns"""

    section_name = "snow"
    enabled: bool = param(False, "snow on the beams")
    rate_mm_h: float = param(1.0, "precipitation intensity, melted water equivalent", unit="mm/h", above=0.0,
                             max=100.0)
    flake_reflectance: float = param(0.3, "Lambertian-equivalent reflectance of a flake's echo (a loose aggregate of "
                                     "ice crystals: less than snow cover's 0.8 in the near infrared)", above=0.0,
                                     max=1.0)
    flake_diameter_factor: float = param(2.15, "a flake's optical diameter over its melted diameter (2.15: flakes of "
                                         "0.1 g/cm^3)", min=1.0, max=10.0)

    def distribution(self) -> tuple[float, float]:
        """(N0 m^-3 mm^-1, Lambda 1/mm) of Gunn & Marshall at this rate (melted diameters)."""
        (n0, n_exp), (a, b) = GUNN_MARSHALL_N0, GUNN_MARSHALL_LAMBDA
        return n0 * self.rate_mm_h**n_exp, a * self.rate_mm_h**b


@dataclass(frozen=True)
class Weather(Params):
    """fog, rain and snow as the lidar sees them (off by default; needs the receiver's power model)"""

    section_name = "weather"
    fog: FogParams = section(FogParams)
    rain: RainParams = section(RainParams)
    snow: SnowParams = section(SnowParams)

    @property
    def on(self) -> bool:
        return self.fog.enabled or self.rain.enabled or self.snow.enabled

    def to_dict(self) -> dict:
        """The sub-sections that differ from their defaults (``{}``: clear air)."""
        from dataclasses import asdict

        return {name: asdict(getattr(self, name)) for name in ("fog", "rain", "snow")
                if getattr(self, name) != type(getattr(self, name))()}


def particle_extinction_per_m(n0: float, lam: float, diameter_factor: float = 1.0) -> float:
    """alpha (1/m) of particles with N(D) = n0 exp(-lam D) (m^-3 mm^-1, 1/mm), optical diameter f D:
    ``integral N(D) * 2 * pi (f D)^2 / 4 dD = pi f^2 n0 / lam^3`` (mm^2 m^-3 = 1e-6 / m)."""
    return math.pi * diameter_factor**2 * n0 / lam**3 * 1e-6


# ---------------------------------------------------------------- the fog's echo
@dataclass(frozen=True)
class FogEcho:
    """The fog's echo against the range ``R0`` of the beam's surface, tabulated.

    r0: (K,) surface ranges, m, a step apart from min_range (the last row: no surface within reach).
    peak: (K,) pi beta max S: the echo's peak power (units of ``p``), 0 where none can be reported.
    lo, hi: (K,) the half-power span of the echo in reported range, m.
    """

    r0: np.ndarray
    peak: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def row(self, r0: np.ndarray) -> np.ndarray:
        """(n,) table row of each surface range (inf: none), the nearest tabulated range not above it."""
        step = self.r0[1] - self.r0[0]
        idx = np.floor((np.asarray(r0, dtype=float) - self.r0[0]) / step)
        return np.clip(np.nan_to_num(idx, posinf=len(self.r0) - 1), -1, len(self.r0) - 1).astype(np.int64)


def soft_response(receiver: ReceiverParams, alpha: float, positions: np.ndarray, r0: np.ndarray,
                  step_m: float = 0.002) -> np.ndarray:
    """S(R; R0) (1/m) at pulse positions ``positions`` for surfaces at ``r0`` (broadcast), by cumulative sums.

    ``sin^2(pi (R - R') / L) = (1 - cos(2 pi R / L) cos(2 pi R' / L) - sin(2 pi R / L) sin(2 pi R' / L)) / 2``,
    so S is three running integrals of ``g(R') = xi(R') exp(-2 alpha R') / R'^2`` read at the window's
    ends (trapezoids on a ``step_m`` grid).
    """
    L = SPEED_OF_LIGHT_M_S * receiver.pulse_width_s
    positions, r0 = np.broadcast_arrays(np.asarray(positions, float), np.asarray(r0, float))
    hi = np.minimum(positions, r0)
    lo = np.maximum(positions - L, 0.0)
    top = float(np.nanmax(np.where(np.isfinite(hi), hi, 0.0), initial=0.0)) + step_m
    x = np.arange(0.0, top + step_m, step_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(x > 0, receiver.overlap(x) * np.exp(-2.0 * alpha * x) / np.maximum(x, 1e-12) ** 2, 0.0)
    k = 2.0 * math.pi / L

    def cumulative(f: np.ndarray) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * step_m)])

    G, C, Sn = cumulative(g), cumulative(g * np.cos(k * x)), cumulative(g * np.sin(k * x))

    def between(F: np.ndarray) -> np.ndarray:
        return np.interp(hi, x, F) - np.interp(lo, x, F)

    s = 0.5 * between(G) - 0.5 * (np.cos(k * positions) * between(C) + np.sin(k * positions) * between(Sn))
    return np.where(hi > lo, np.maximum(s, 0.0), 0.0)


def fog_echo(receiver: ReceiverParams, fog: FogParams, alpha: float, min_range_m: float) -> FogEcho:
    """Tabulate the fog's echo (``FogEcho``) for surfaces from ``min_range_m`` outwards (alpha: the air's whole
    extinction, 1/m, fog and particles)."""
    L = SPEED_OF_LIGHT_M_S * receiver.pulse_width_s
    half = 0.5 * L
    # Without a surface: reported ranges from min_range outwards, far enough that the echo has fallen below half.
    far = max(receiver.overlap_full_m, min_range_m) + 4.0 * L + 1.0
    while True:
        rep = np.arange(min_range_m, far, _FOG_STEP_M)
        s_free = soft_response(receiver, alpha, rep + half, np.inf)
        if s_free.max() <= 0 or s_free[-1] < 0.5 * s_free.max():
            break
        far *= 2.0
    # A surface beyond the free echo's half-power span (and half a pulse) leaves the span as it is: the last row.
    top = s_free.max()
    hi_free = rep[np.flatnonzero(s_free >= 0.5 * top)[-1]] if top > 0 else min_range_m
    r0 = np.arange(min_range_m, hi_free + half + 2 * _FOG_STEP_M, _FOG_STEP_M)
    cols = np.arange(min_range_m, r0[-1], _FOG_STEP_M)  # reported ranges of the echo in front of a surface
    s = soft_response(receiver, alpha, cols[None, :] + half, r0[:, None])
    s[cols[None, :] >= r0[:, None]] = 0.0  # reported at or beyond the surface: merged into its echo
    rows = [s[j] for j in range(len(r0))] + [s_free]
    cols_of = [cols] * len(r0) + [rep]
    peak, lo, hi = np.zeros(len(rows)), np.zeros(len(rows)), np.zeros(len(rows))
    for j, (row, c) in enumerate(zip(rows, cols_of, strict=True)):
        best = row.max(initial=0.0)
        if best > 0:
            above = np.flatnonzero(row >= 0.5 * best)
            peak[j], lo[j], hi[j] = math.pi * fog.beta_per_m_sr * best, c[above[0]], c[above[-1]]
    return FogEcho(np.append(r0, np.inf), peak, lo, hi)


# ---------------------------------------------------------------- particles
@dataclass(frozen=True)
class ParticleRate:
    """Detectable particles of one kind along a beam, tabulated against range.

    kind: RAIN or SNOW. r: (K,) ranges from min_range, m. cumulative: (K,) mu(r), the expected number
    of detectable particles between min_range and r. d_min: (K,) their least optical diameter at r, mm.
    lam: Lambda, 1/mm (melted). factor: optical over melted diameter. reflectance: rho_p.
    """

    kind: int
    r: np.ndarray
    cumulative: np.ndarray
    d_min: np.ndarray
    lam: float
    factor: float
    reflectance: float


def particle_rate(kind: int, n0: float, lam: float, factor: float, reflectance: float, receiver: ReceiverParams,
                  alpha: float, min_range_m: float, max_range_m: float) -> ParticleRate:
    """The rate ``lambda(R)`` of detectable particles along a beam (module doc), integrated from min_range_m."""
    r = np.arange(min_range_m, max_range_m + _PARTICLE_STEP_M, _PARTICLE_STEP_M)
    w = receiver.footprint_m(r)
    gain = reflectance * receiver.overlap(r) * np.exp(-2.0 * alpha * r)
    with np.errstate(divide="ignore"):
        d_min = w * r * np.sqrt(receiver.min_power / gain)  # m
    rate = np.where(d_min <= w, 0.25 * math.pi * w**2 * (n0 / lam) * np.exp(-lam * 1e3 * d_min / factor), 0.0)
    end = int(np.flatnonzero(rate > 0)[-1]) + 2 if (rate > 0).any() else 2  # none detectable beyond
    r, rate, w, d_min = r[:end], rate[:end], w[:end], d_min[:end]
    cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * _PARTICLE_STEP_M)])
    return ParticleRate(kind, r, cumulative, np.where(np.isfinite(d_min), d_min * 1e3, np.inf), lam, factor,
                        reflectance)


# ---------------------------------------------------------------- one sensor's weather
@dataclass
class Echoes:
    """What the beams of a block report (r of the block's n rays).

    ray: (r,) ray index within the block. kind: (r,) uint8, ``KINDS``. hit: (r,) index of the ray's surface
    hit in the block's hits, -1 without one. range_m: (r,) reported range before noise, m (a surface's: its
    echo range as given). power: (r,) received power (units of ``p``). gain: (r,) the surface's overlap x
    two-way transmission (1 for weather echoes).
    """

    ray: np.ndarray
    kind: np.ndarray
    hit: np.ndarray
    range_m: np.ndarray
    power: np.ndarray
    gain: np.ndarray


class WeatherModel:
    """The receiver and weather tables of one sensor (``LidarModel`` with ``receiver.enabled``)."""

    def __init__(self, sensor):
        rec, wx = sensor.receiver, sensor.weather
        self.receiver, self.weather, self.mode = rec, wx, sensor.return_mode
        self.min_range_m, self.max_range_m = sensor.min_range_m, sensor.max_range_m
        self.p_min = rec.min_power
        rates = []
        if wx.rain.enabled:
            rates.append((RAIN, *wx.rain.distribution(), 1.0, wx.rain.drop_reflectance))
        if wx.snow.enabled:
            rates.append((SNOW, *wx.snow.distribution(), wx.snow.flake_diameter_factor, wx.snow.flake_reflectance))
        self.alpha = wx.fog.alpha_per_m + sum(particle_extinction_per_m(n0, lam, f) for _, n0, lam, f, _ in rates)
        self.fog = fog_echo(rec, wx.fog, self.alpha, self.min_range_m) if wx.fog.enabled else None
        self.particles = [particle_rate(kind, n0, lam, f, rho, rec, self.alpha, self.min_range_m, self.max_range_m)
                          for kind, n0, lam, f, rho in rates]

    def gain(self, r: np.ndarray) -> np.ndarray:
        """xi(r) T(r)^2: what the overlap and the air leave of an echo from range r (m)."""
        return np.exp(-2.0 * self.alpha * r) * self.receiver.overlap(r)

    def select(self, rng: np.random.Generator, n_rays: int, hit_ray: np.ndarray, hit_range: np.ndarray,
               hit_echo: np.ndarray, hit_power: np.ndarray) -> Echoes:
        """Each ray's reported echo (``Echoes``) among its detected ones (module doc).

        n_rays: rays in the block. hit_ray: (m,) ray of each surface hit; hit_range: (m,) its true range, m;
        hit_echo: (m,) the range its echo reports (the beam's echo of a divergent beam), m; hit_power: (m,)
        its clear-air power ``rho |cos a|^k / R^2``. Draws from ``rng`` in a fixed order.
        """
        n = n_rays
        r0 = np.full(n, np.inf)
        r0[hit_ray] = hit_range
        hit_gain = self.gain(hit_range)
        hard = hit_power * hit_gain
        seen = hard >= self.p_min
        kind = np.full(n, -1, np.int64)
        rng_m = np.full(n, np.nan)
        power = np.zeros(n)
        kind[hit_ray[seen]] = SURFACE
        rng_m[hit_ray] = hit_echo
        power[hit_ray[seen]] = hard[seen]
        if self.fog is not None:
            row = self.fog.row(r0)
            peak = np.where(row >= 0, self.fog.peak[np.maximum(row, 0)], 0.0)
            s = self.weather.fog.backscatter_fluctuation
            if s > 0:
                shape = 1.0 / s**2
                peak = peak * rng.gamma(shape, 1.0 / shape, n)
            ok = np.flatnonzero(peak >= self.p_min)
            if len(ok):
                lo, hi = self.fog.lo[row[ok]], self.fog.hi[row[ok]]
                where = lo + (hi - lo) * rng.random(len(ok))
                self._compete(kind, rng_m, power, ok, FOG, where, peak[ok])
        for table in self.particles:
            mu = np.interp(np.minimum(r0, table.r[-1]), table.r, table.cumulative)
            count = rng.poisson(mu)
            rays = np.flatnonzero(count)
            if len(rays) == 0:
                continue
            each = np.repeat(rays, count[rays])
            r = np.interp(rng.random(len(each)) * mu[each], table.cumulative, table.r)
            d = np.interp(r, table.r, table.d_min) + table.factor * rng.exponential(1.0 / table.lam, len(each))
            w = self.receiver.footprint_m(r) * 1e3  # mm
            p = table.reflectance * np.minimum(1.0, (d / w) ** 2) * self.gain(r) / r**2
            keep = p >= self.p_min  # (all but draws on the edge of a table cell where detection begins)
            each, r, p = each[keep], r[keep], p[keep]
            if len(each) == 0:
                continue
            # one echo per ray: the one the return mode would pick among the particles
            key = {"strongest": p, "first": -r, "last": r}[self.mode]
            starts = np.flatnonzero(np.append(True, each[1:] != each[:-1]))  # ``each`` is sorted by ray
            best = np.repeat(np.maximum.reduceat(key, starts), np.diff(np.append(starts, len(each))))
            top = np.flatnonzero(key == best)
            pick = top[np.append(True, each[top][1:] != each[top][:-1])]
            self._compete(kind, rng_m, power, each[pick], table.kind, r[pick], p[pick])
        rays = np.flatnonzero(kind >= 0)
        hit_of_ray = np.full(n, -1, np.int64)
        hit_of_ray[hit_ray] = np.arange(len(hit_ray))
        hit = hit_of_ray[rays]
        kinds = kind[rays].astype(np.uint8)
        gain = np.ones(len(rays))
        surface = kinds == SURFACE
        gain[surface] = hit_gain[hit[surface]]
        return Echoes(rays, kinds, hit, rng_m[rays], power[rays], gain)

    def _compete(self, kind, rng_m, power, rays, new_kind, new_range, new_power) -> None:
        """Let echoes of ``new_kind`` at ``rays`` take the place of the rays' current ones per the return mode."""
        current = kind[rays]
        if self.mode == "strongest":
            wins = new_power > power[rays]
        elif self.mode == "first":
            wins = (current < 0) | (new_range < rng_m[rays])
        else:  # last: a weather echo is nearer than the ray's surface, so it wins only where nothing else was seen
            wins = (current < 0) | (new_range > rng_m[rays]) & (current != SURFACE)
        won = rays[wins]
        kind[won], rng_m[won], power[won] = new_kind, new_range[wins], new_power[wins]


__all__ = ["DETECTION_REFLECTANCE", "FOG", "KINDS", "RAIN", "SNOW", "SURFACE", "Echoes", "FogEcho", "FogParams",
           "ParticleRate", "RainParams", "ReceiverParams", "SnowParams", "Weather", "WeatherModel", "fog_echo",
           "particle_extinction_per_m", "particle_rate", "soft_response"]
