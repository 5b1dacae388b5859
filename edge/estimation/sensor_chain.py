"""Sensor-chain estimator: effusivity, contact resistance and object temperature from the moment of contact.

ISSUE #10 §3.  The default method (:mod:`edge.estimation.estimate`) fits e with
T0 fixed at the pre-heating baseline and takes the thermopile reading as the
object's face flux.  Three things in the real chain bias it: a contact
resistance R_c, an object at a temperature other than the probe's, and the
thermopile averaging the flux through its sensing layer.  This module models
the chain in 1-D from the contact instant t = 0 on:

* the sensing layer (thickness L, conductivity k, diffusivity alpha; the
  calibration) is a known slab between the thermopile and the contact.  The
  thermopile reads its depth-averaged flux q_m = (1/L) int q dz = k (T_top -
  T_bot) / L, and its quadrupole gives, in the Laplace domain (layer uniform
  at the probe's temperature at contact, gamma = sqrt(s / alpha)),

      phi_face = A(s) q_m - B(s) theta_b,
      A = gamma L / sinh(gamma L),   B = k gamma tanh(gamma L / 2),

  theta_b the probe-side face temperature (the thermocouple's junction)
  minus the probe's temperature at contact;
* the contact: theta_b = theta_obj_face + R_c phi_face;
* the object, semi-infinite, effusivity e, initial temperature T_obj0:
  theta_obj_face = (T_obj0 - T_p0) + (1/e) Duhamel(phi_face);
* the thermocouple's first-order bead lag tau (calibration).

Given phi_face the model is linear in (T_obj0 - T_p0, R_c, 1/e), so each
Gauss-Newton step is an exact linear least-squares solve.  phi_face depends
on theta_b through the small storage term B; it is computed from the
measured thermocouple (the fitted theta_b cannot follow the contact
transient's first samples, and using it biased e; see ``n_iterations``).  Uncertainties: the
least-squares covariance scaled by the residual variance, inflated for the
residuals' lag-1 autocorrelation (model error is smooth, not white).

Everything is NumPy; the slab kernels are inverted once per (grid,
calibration) with Talbot and cached.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from edge.physics.fluxmodel import duhamel_apply
from edge.physics.integrators import causal_convolution, causal_convolution_columns
from edge.physics.laplace import talbot_invert
from edge.physics.memo import BoundedMemo
from edge.physics.probe import DEFAULT_STACK

__all__ = ["DiskFitter", "ProfilePoint", "SensorChainCalibration", "SensorChainResult", "chain_design", "chain_point", "chain_theta",
           "chain_with_theta", "face_flux", "fit_sensor_chain", "refine_factor", "simulate_chain"]


@dataclass(frozen=True)
class SensorChainCalibration:
    """Parameters of the chain below the thermopile (from calibration; nominal defaults from the stack).

    Parameters
    ----------
    sensing_thickness_m : float
        Thickness of the layer between the thermopile plane and the object (m).
    k_W_mK : float
        Its conductivity (W/m/K).
    alpha_m2_s : float
        Its diffusivity (m^2/s).
    tc_tau_s : float
        Thermocouple bead time constant (s); 0 for none.
    flux_scale : float
        True depth-averaged flux per unit of the reading (nominal sensitivity / true sensitivity):
        the reading is the thermopile voltage over the *nominal* sensitivity, so a thermopile 3 %
        more sensitive than its datasheet needs 1/1.03.
    """

    sensing_thickness_m: float = DEFAULT_STACK.sensing_thickness_m
    k_W_mK: float = DEFAULT_STACK.material.k_W_mK
    alpha_m2_s: float = DEFAULT_STACK.material.k_W_mK / (DEFAULT_STACK.material.rho_kg_m3
                                                          * DEFAULT_STACK.material.c_J_kgK)
    tc_tau_s: float = 0.0
    flux_scale: float = 1.0

    def __post_init__(self) -> None:
        for name in ("sensing_thickness_m", "k_W_mK", "alpha_m2_s", "flux_scale"):
            v = getattr(self, name)
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")
        if not (self.tc_tau_s >= 0 and math.isfinite(self.tc_tau_s)):
            raise ValueError(f"tc_tau_s must be finite and >= 0, got {self.tc_tau_s!r}")


def chain_theta(chain: "SensorChainCalibration") -> np.ndarray:
    """The calibration's parameter vector theta = (ln flux_scale, ln sensing_thickness_m, tc_tau_s, ln sensing_k_W_mK)."""
    c = chain
    return np.array([math.log(c.flux_scale), math.log(c.sensing_thickness_m), c.tc_tau_s, math.log(c.k_W_mK)])


def chain_with_theta(chain: "SensorChainCalibration", theta) -> "SensorChainCalibration":
    """``chain`` with parameters ``theta`` (see :func:`chain_theta`): a bead lag below 0 is 0 (it cannot lead);
    the layer's rho c is kept, so alpha follows k."""
    from dataclasses import replace  # noqa: PLC0415 - the module imports only dataclass

    th = np.asarray(theta, dtype=np.float64)
    k = float(math.exp(th[3]))
    rho_c = chain.k_W_mK / chain.alpha_m2_s
    return replace(chain, flux_scale=float(math.exp(th[0])), sensing_thickness_m=float(math.exp(th[1])),
                   tc_tau_s=float(max(th[2], 0.0)), k_W_mK=k, alpha_m2_s=k / rho_c)


@dataclass(frozen=True)
class SensorChainResult:
    """Fitted chain: values, standard uncertainties (k = 1) and fit quality."""

    e_W_s05_m2K: float
    u_e_W_s05_m2K: float
    R_c_m2K_W: float
    u_R_c_m2K_W: float
    T_obj0_C: float
    u_T_obj0_C: float
    correlation: np.ndarray        # 3 x 3 of (T_obj0, R_c, 1/e)
    normalised_residual: float     # rms residual / stated thermocouple noise
    rms_residual_K: float
    n_iterations: int
    n_fitted: int = 0              # samples the least squares weighted
    residual_inflation: float = 1.0   # (1 + rho) / (1 - rho) of the residuals' lag-1 autocorrelation rho
    #: u(ln e) the stated white thermocouple noise alone gives with (T_obj0, R_c) fitted alongside: the
    #: fit's u without its residual's excess over that noise (u(e) / e is this times
    #: sqrt(s^2 inflation) / noise); and the same with T_obj0 and R_c known (their cost: the ratio).
    u_ln_e_noise: float = math.nan
    u_ln_e_noise_nuisance_known: float = math.nan


#: Ramp responses R(i dt), i = 1 .. n of the longest grid asked for, by (dt, layer).  Talbot inverts per time:
#: a shorter grid's kernels are a longer one's prefix (same numbers), a longer grid inverts only its new times.
#: A calibration's touches and a touch's candidate contact instants share one inversion per chain (keyed by
#: n with 8 entries, a walk-through's nine touches evicted each other at every Gauss-Newton trial).
_KERNELS = BoundedMemo(64)


def _ramp_kernels(key: tuple, n: int, dt_s: float, ramp) -> tuple[np.ndarray, ...]:
    """Kernels K_1 .. K_n (read-only) of the ramp responses ``ramp(t)`` (a tuple of arrays), kept per ``key``.

    K_m = (R(m dt) - R((m-1) dt)) / dt with R(0) = 0; see :data:`_KERNELS`.
    """
    hit = _KERNELS.get(key)
    if hit is None or hit[0][0].size < n:
        have = 0 if hit is None else hit[0][0].size
        # dt * i for i = have + 1 .. n: the same times as dt * arange(1, n + 1)[have:].
        new = ramp(dt_s * np.arange(have + 1, n + 1))
        Rs, Ks = [], []
        for j, Rn in enumerate(new):
            R_prev = np.zeros(1) if hit is None else hit[0][j][-1:]
            R = np.real(Rn)
            K = np.diff(np.concatenate((R_prev, R))) / dt_s
            if hit is not None:
                R, K = np.concatenate((hit[0][j], R)), np.concatenate((hit[1][j], K))
            Rs.append(R)
            Ks.append(K)
        hit = _KERNELS.put(key, (tuple(Rs), tuple(Ks)))
    return tuple(K[:n] for K in hit[1])


def _slab_kernels(n: int, dt_s: float, L_m: float, k_W_mK: float, alpha_m2_s: float):
    """Convolution kernels g_A, g_B (length n) of A(s) and B(s) for inputs linear between samples.

    For x linear between samples with x(0) = 0, y_i = sum_j (x_j - x_{j-1}) K_{i-j+1} with
    K_m = (R(m dt) - R((m-1) dt)) / dt, R the ramp response L^-1[H / s^2] (kept: :data:`_KERNELS`).
    """
    def F(s):
        g = np.sqrt(s / alpha_m2_s)
        gL = g * L_m
        # gL / sinh(gL) and tanh(gL/2) written to stay finite for large |gL| (Talbot's nodes).
        ex = np.exp(-gL)
        A = 2.0 * gL * ex / (1.0 - ex * ex)
        B = k_W_mK * g * (1.0 - ex) / (1.0 + ex)
        return A / s**2, B / s**2

    key = ("slab", float(dt_s), float(L_m), float(k_W_mK), float(alpha_m2_s))
    return _ramp_kernels(key, int(n), float(dt_s), lambda t: talbot_invert(F, t))


_erfc = np.frompyfunc(math.erfc, 1, 1)


@lru_cache(maxsize=16)
def _disk_kernel(n: int, dt_s: float, radius_m: float, alpha_m2_s: float) -> np.ndarray:
    """Kernel (as :func:`_slab_kernels`) of the disk's lateral loss at its centre, in units of the Duhamel column.

    A uniform flux on a disk of radius a over a half-space heats the centre as
    theta(s) = phi(s) (1 - exp(-a sqrt(s / alpha))) / (e sqrt(s)): the 1-D response less the 1-D
    response at depth a.  The latter's ramp response is 8 t^1.5 i^3erfc(a / (2 sqrt(alpha t))) / e
    (Carslaw & Jaeger 2.9), with i^n erfc from its recurrence.
    """
    t = dt_s * np.arange(1, n + 1)
    u = radius_m / (2.0 * np.sqrt(alpha_m2_s * t))
    ec = _erfc(u).astype(np.float64)
    i1 = np.exp(-u * u) / math.sqrt(math.pi) - u * ec
    i2 = (ec - 2.0 * u * i1) / 4.0
    i3 = np.maximum((i1 - 2.0 * u * i2) / 6.0, 0.0)   # cancellation below 1e-17 where u is large
    R = np.concatenate(([0.0], 8.0 * t**1.5 * i3))
    K = np.diff(R) / dt_s
    K.flags.writeable = False
    return K


def _apply(K: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Kernel K (from :func:`_slab_kernels`) applied to x (its first value taken as 0: from contact)."""
    d = np.diff(x, prepend=0.0)
    d[0] = 0.0
    return causal_convolution(K, d)


def _lag(x: np.ndarray, dt_s: float, tau_s: float) -> np.ndarray:
    """First-order lag of columns x (n, m), exact for x linear between samples, starting at 0.

    The recursion y_i = a y_(i-1) + b x_i + (1 - a - b) x_(i-1), y_0 = 0 (a = exp(-dt/tau),
    b = 1 - tau (1 - a) / dt) as one causal convolution per column with its impulse response
    h_0 = b, h_k = a^(k-1) (a b + 1 - a - b), less the b a^i x_0 that y_0 = 0 leaves out: the
    profile over alpha lags a column per point, and a Python loop over the samples was most of its cost.
    """
    if tau_s <= 0:
        return x
    a = math.exp(-dt_s / tau_s)
    b = 1.0 - tau_s * (1.0 - a) / dt_s
    n = x.shape[0]
    with np.errstate(under="ignore"):
        p = a ** np.arange(n, dtype=np.float64)       # underflows to 0 within a few hundred samples
    h = np.empty(n)
    h[0] = b
    h[1:] = (a * b + 1.0 - a - b) * p[:-1]
    y = causal_convolution_columns(h, x) - b * np.outer(p, x[0])
    y[0] = 0.0
    return y


#: Columns of the causal system per block in :func:`simulate_chain`.
SIMULATE_BLOCK = 128


def simulate_chain(t_s, q_m_W_m2, *, e_W_s05_m2K: float, R_c_m2K_W: float, T_obj0_C: float, T_probe0_C: float,
                   calibration: SensorChainCalibration = SensorChainCalibration()) -> np.ndarray:
    """Thermocouple reading of the 1-D chain driven by a thermopile record (the self-consistency forward model).

    The model is implicit in theta_b (phi_face depends on it through B): (I + B Z) phi = A q with
    Z = R_c + D / e, a causal (lower-triangular) system, solved by blocked forward substitution --
    :data:`SIMULATE_BLOCK` columns of I + B Z at a time, each block applied to unit vectors by FFT:
    O(n^2 log n) time, O(n block) memory (the calibration's noise-bias correction runs it on every
    reference touch, where a dense n x n system grew as n^3 in time and n^2 in memory).
    Fixed-point iteration diverges on low-effusivity objects, where B (R_c + D / e) exceeds 1.
    """
    t, q = np.asarray(t_s, float), np.asarray(q_m_W_m2, float) * calibration.flux_scale
    n = t.size
    dt = float(t[1] - t[0])
    KA, KB = _slab_kernels(n, dt, calibration.sensing_thickness_m, calibration.k_W_mK, calibration.alpha_m2_s)
    size = 1 << (2 * n - 1).bit_length()
    KB_f = np.fft.rfft(KB, size)

    def Z(x: np.ndarray) -> np.ndarray:
        return R_c_m2K_W * x + duhamel_apply(x, dt) / e_W_s05_m2K

    def B(x: np.ndarray) -> np.ndarray:
        # _apply on each column of x (n, m): the kernel on the column's increments, the first taken as 0.
        d = np.diff(x, axis=0, prepend=0.0)
        d[0] = 0.0
        return np.fft.irfft(KB_f[:, None] * np.fft.rfft(d, size, axis=0), size, axis=0)[:n]

    c = T_obj0_C - T_probe0_C
    r = _apply(KA, q)     # B of the constant c is 0: only increments enter it
    phi = np.zeros(n)
    for j0 in range(0, n, SIMULATE_BLOCK):
        j1 = min(n, j0 + SIMULATE_BLOCK)
        E = np.zeros((n, j1 - j0))
        E[np.arange(j0, j1), np.arange(j1 - j0)] = 1.0
        cols = E + B(Z(E))                       # columns j0..j1 of I + B Z (zero above the diagonal)
        phi[j0:j1] = np.linalg.solve(cols[j0:j1], r[j0:j1])
        r[j1:] -= cols[j1:] @ phi[j0:j1]
    theta = c + Z(phi)
    return T_probe0_C + _lag(theta[:, None], dt, calibration.tc_tau_s)[:, 0]


#: Largest half-width (s) of the moving average applied to the measured theta_b before the
#: storage term B acts on it.  B ~ k sqrt(s / alpha) is a half-derivative: it turns the thermocouple's
#: white noise into flux noise growing with frequency (10 mK at 20 Hz becomes ~50 W/m^2, more than
#: a foam's whole face flux), and that noise, shared with the fitted temperature, biases R_c and e.
#: Averaging 2h + 1 samples cuts it about (2h + 1)-fold at the top of the band.  (On FaithfulWorld
#: foam and cork records at 20 Hz, 0.15 / 0.25 / 0.5 s: normalised residual 4.5 / 3.7 / 3.0, e error
#: -1.1 / -0.9 / -0.9 %; without it 8-10 and -2.7 %.)
SMOOTH_HALF_WIDTH_s = 0.5
#: The half-width grows by one sample every SMOOTH_GROWTH samples from a segment's start: a moving
#: average bends a curved theta_b by ~h^2 theta''/6, and theta_b is most curved just after contact
#: and heater-on (growth 3: R_c -5e-6..-9e-6 m^2K/W on noise-free FaithfulWorld records; 6: see git log).
SMOOTH_GROWTH = 6


def _smooth_from_contact(x: np.ndarray, h_max: int, breaks: tuple[int, ...] = (),
                         growth: int = SMOOTH_GROWTH) -> np.ndarray:
    """Centred moving average whose half-width grows from 0 at each segment's start to ``h_max``.

    Segments start at contact (sample 0) and at each of ``breaks`` (the heater switching: theta_b's
    slope jumps there, and an average across it would bend it by far more than the noise it removes).
    Within a segment the half-width is j // ``growth`` at its j-th sample -- narrow where a transient is fast,
    wide where theta_b is smooth -- and shrinks symmetrically toward the segment's end.
    """
    n = x.size
    if h_max <= 0 or n < 3:
        return x
    out = x.copy()
    edges = [0] + sorted(b for b in set(breaks) if 0 < b < n) + [n]
    c = np.concatenate(([0.0], np.cumsum(x)))
    for a, b in zip(edges[:-1], edges[1:]):
        i = np.arange(a, b)
        h = np.minimum(np.minimum((i - a) // growth, h_max), b - 1 - i)
        out[a:b] = (c[i + h + 1] - c[i - h]) / (2 * h + 1)
    return out


@dataclass(frozen=True)
class _Prepared:
    t: np.ndarray
    y: np.ndarray          # thermocouple minus the probe's temperature at contact
    fit: np.ndarray        # samples the least squares weights
    dt: float
    Tp0: float
    phiA: np.ndarray       # A(s) applied to the scaled thermopile reading
    KB: np.ndarray
    theta: np.ndarray      # first-pass theta_b: the measured thermocouple, its bead lag undone
    stride: int = 1        # the record's samples are every stride-th of the (refined) grid
    kkey: tuple = ()       # (dt, L, k, alpha) of the slab kernels (see _applied)


#: Largest step (s) of the grid the chain's convolutions run on.  Their kernels take every input as
#: linear between samples; at contact the face's temperature jumps and at heater-on the thermopile's
#: reading rises as sqrt(t), so at the device's 10 Hz the first interval's input was wrong by a sixth
#: of a sample's flux and e came out -10 % at 0.5 s, -1.4 % at 1 s of heating (-13 / -5.5 / -2 % at
#: 0.5 / 1 / 2 s with the object 2 K off the probe), noise-free, on the faithful world's 1-D limit
#: (ISSUE #34 item 5: the short-window errors).  Sampled coarser than this, the record is refined
#: (by :func:`refine_factor`): a step at contact, a sqrt rise from heater-on over the interval holding
#: it, linear elsewhere; only the recorded samples are fitted.  Refined to 20 ms at 10 Hz:
#: -1 / -0.7 / -0.5 % (object 0.5 K off) and +0.0 / -0.4 / -0.4 % (2 K off) on those records.
#: 5 ms (was 20 ms, under which the precision board's 50-Hz records ran unrefined, the contact taken
#: at a sample): on the calibrated hand-touch bench (bench/asbuilt_calibrated_bench.py, 8 drawn paper
#: probes x 20 solids) the median |e error| where R_c <= 3e-5 went 3.3 -> 2.9 % at 0.5 s (90th
#: percentile 11.8 -> 8.7 %), 1.8 -> 1.7 % at 1 s, 1.2 -> 1.3 % at 2 s (p90 2.7 -> 2.4 %); the chain's
#: estimate costs ~2x the CPU on a 50-Hz record (0.015 -> 0.03 s).
REFINE_DT_s = 0.005
#: At most this many fine steps per recorded interval: a 10-Hz record keeps the 20-ms grid it was
#: validated on (and its cost); a 50-Hz one runs at 5 ms.
MAX_REFINE = 5


def refine_factor(dt_s: float, refine_dt_s: float | None = REFINE_DT_s) -> int:
    """Fine steps per recorded interval ``dt_s`` (1: the record runs on its own samples).

    ceil(dt / refine_dt_s), at most :data:`MAX_REFINE`; None: 1.
    """
    if refine_dt_s is None:
        return 1
    return min(MAX_REFINE, max(1, int(math.ceil(dt_s / refine_dt_s - 1e-9))))


def _refine(t: np.ndarray, x: np.ndarray, m: int, breaks_s: tuple[float, ...], k: int = 0) -> np.ndarray:
    """``x`` on the grid ``m`` times finer than ``t`` (see :data:`REFINE_DT_s`); contact after fine point ``k``."""
    dt_f = (t[1] - t[0]) / m
    tf = t[0] + dt_f * np.arange((t.size - 1) * m + 1)
    xf = np.interp(tf, t, x)
    xf[1:k + 1] = x[0]                  # still in air up to the contact ...
    xf[k + 1:m] = x[1]                  # ... then the change happens at its instant
    for b in breaks_s:
        tb = t[0] + b
        j = int(np.searchsorted(t, tb, side="right"))
        if not 1 <= j < t.size or j == 1:
            continue
        lo, hi = (j - 1) * m, j * m
        f = np.clip((tf[lo + 1:hi] - max(tb, t[j - 1])) / (t[j] - max(tb, t[j - 1])), 0.0, 1.0)
        xf[lo + 1:hi] = x[j - 1] + (x[j] - x[j - 1]) * np.sqrt(f)
    return xf


def _prepare(t_s, T_tc_C, q_m_W_m2, cal: SensorChainCalibration, T_probe0_C, fit_start_s,
             breaks_s: tuple[float, ...] = (), smooth_s: float = SMOOTH_HALF_WIDTH_s,
             smooth_growth: int = SMOOTH_GROWTH, refine_dt_s: float | None = REFINE_DT_s,
             contact_frac: float = 0.0) -> _Prepared:
    t = np.asarray(t_s, dtype=np.float64)
    T = np.asarray(T_tc_C, dtype=np.float64)
    q = np.asarray(q_m_W_m2, dtype=np.float64) * cal.flux_scale
    if t.ndim != 1 or t.size < 8 or T.shape != t.shape or q.shape != t.shape:
        raise ValueError("t_s, T_tc_C and q_m_W_m2 must be 1-D of one length >= 8")
    dt = float(t[1] - t[0])
    # np.allclose(np.diff(t), dt, rtol=1e-6, atol=1e-9) written out: a fit calls this thousands of times.
    if not (dt > 0 and bool(np.all(np.abs(np.diff(t) - dt) <= 1e-9 + 1e-6 * dt))):
        raise ValueError("t_s must be uniform and increasing")
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(q))):
        raise ValueError("records must be finite")
    if np.count_nonzero(t - t[0] >= fit_start_s) < 4:
        # Three parameters need four samples; none at all divided the residual by zero (ISSUE #35 fuzz run:
        # a 0.7-s touch without its contact in air asked for the late fit from 1 s).
        raise ValueError(f"fit_start_s = {fit_start_s:g} s leaves fewer than 4 samples to fit (the record ends "
                         f"{t[-1] - t[0]:.3g} s after contact)")
    m = refine_factor(dt, refine_dt_s)
    recorded = np.ones(t.size, dtype=bool)
    if m > 1:
        # The contact lies within the record's first interval, ``contact_frac`` of it after sample 0: the
        # refined record starts at that instant (the last fine point in air).
        k = min(max(int(round(contact_frac * m)), 0), m - 1)
        T, q = _refined(t, T, m, breaks_s, k), _refined(t, q, m, breaks_s, k)
        dt = dt / m
        t = t[0] + dt * np.arange(T.size)
        recorded = (np.arange(t.size) + k) % m == 0
        breaks_s = tuple(b - k * dt for b in breaks_s)
    Tp0 = float(T[0]) if T_probe0_C is None else float(T_probe0_C)
    kkey = (float(dt), float(cal.sensing_thickness_m), float(cal.k_W_mK), float(cal.alpha_m2_s))
    KA, KB = _slab_kernels(t.size, *kkey)
    y = T - Tp0
    breaks = tuple(int(round(b / dt)) for b in breaks_s)
    theta = _memo(("theta", y.tobytes(), dt, float(cal.tc_tau_s), int(round(smooth_s / dt)), breaks, smooth_growth),
                  lambda: _theta_b(y, dt, cal.tc_tau_s, int(round(smooth_s / dt)), breaks, smooth_growth))
    return _Prepared(t, y, ((t - t[0]) >= fit_start_s) & recorded, dt, Tp0, _applied(kkey, 0, KA, q), KB, theta, m,
                     kkey)


def _theta_b(y: np.ndarray, dt: float, tau_s: float, h: int, breaks: tuple[int, ...], growth: int) -> np.ndarray:
    """First-pass theta_b: the measured thermocouple ``y`` (from the probe's temperature at contact), its bead
    lag undone, smoothed (:func:`_smooth_from_contact`)."""
    # The measured thermocouple stands in for theta_b (the bead lag and noise only enter
    # through the small storage term B).
    theta = y.copy()
    if tau_s > 0:
        # The bead lags the junction: undo it (theta = y + tau dy/dt) for the storage term only.
        theta = y + tau_s * np.gradient(y, dt)
        theta[0] = 0.0
    return _smooth_from_contact(theta, h, breaks, growth)


#: Pieces of a design by their exact inputs (read-only, the same numbers): a calibration rebuilds every touch's
#: design per trial of the probe's parameters, and the refined record depends on none, theta_b on the bead
#: lag, the A-term on the flux scale and layer, the storage term on the layer and lag.
_memo = BoundedMemo(256)
#: Whole designs (:func:`chain_design`) by their exact inputs.
_DESIGNS = BoundedMemo(128)


def _refined(t: np.ndarray, x: np.ndarray, m: int, breaks_s: tuple[float, ...], k: int) -> np.ndarray:
    """``_refine(t, x, m, breaks_s, k)[k:]``, kept (:data:`_memo`)."""
    return _memo(("refine", t.tobytes(), x.tobytes(), m, tuple(breaks_s), k),
                 lambda: _refine(t, x, m, breaks_s, k)[k:])


def _applied(kkey: tuple, which: int, K: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``_apply(K, x)`` for the slab kernel ``which`` (0: A, 1: B) of :func:`_slab_kernels` ``(x.size, *kkey)``, kept."""
    return _memo(("apply", which, kkey, x.tobytes()), lambda: _apply(K, x))


def _disk_loss(phi: np.ndarray, dt: float, disk) -> np.ndarray | None:
    """The disk's lateral loss in the object's face-temperature column (None for 1-D: no disk)."""
    if disk is None or not math.isfinite(disk[0]):
        return None
    return _apply(_disk_kernel(phi.shape[0], dt, float(disk[0]), float(disk[1])), phi)


def _response(phi: np.ndarray, dt: float, disk) -> np.ndarray:
    """The object's face-temperature column: Duhamel(phi), less the disk's lateral loss when ``disk`` = (a, alpha)."""
    d = duhamel_apply(phi, dt)
    loss = _disk_loss(phi, dt, disk)
    return d if loss is None else d - loss


def _ar1_inflation(r: np.ndarray) -> float:
    """(1 + rho) / (1 - rho) of the residuals' lag-1 autocorrelation rho (in [0, 0.95]): smooth model
    error makes residuals correlated, and their effective number smaller."""
    rho = float(np.clip((r[1:] @ r[:-1]) / max(float(r @ r), 1e-300), 0.0, 0.95))
    return (1.0 + rho) / (1.0 - rho)


def face_flux(t_s, T_tc_C, q_m_W_m2, calibration: SensorChainCalibration = SensorChainCalibration(), *,
              breaks_s: tuple[float, ...] = ()) -> np.ndarray:
    """The flux into the object's face (W/m^2) the chain infers from a record that starts at contact.

    phi = A q_m - B theta_b (first pass): what :func:`fit_sensor_chain` regresses on.  Used to see
    the probe leave the object -- the face flux then falls to about nothing while the heater runs.
    """
    c = _prepare(t_s, T_tc_C, q_m_W_m2, calibration, None, 0.0, breaks_s)
    return (c.phiA - _applied(c.kkey, 1, c.KB, c.theta))[::c.stride]


def chain_design(t_s, T_tc_C, q_m_W_m2, calibration: SensorChainCalibration = SensorChainCalibration(), *,
                 T_probe0_C: float | None = None, fit_start_s: float = 0.3,
                 breaks_s: tuple[float, ...] = (), disk: tuple[float, float] | None = None,
                 smooth_growth: int = SMOOTH_GROWTH, contact_frac: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The first-pass linear model of :func:`fit_sensor_chain` on its fitted samples: ``y ~ X @ (dT_obj0, R_c, 1/e)``.

    For calibration, where e is known and the chain's parameters are sought: (X, y), X of shape (m, 3)
    with columns 1, phi_face and Duhamel(phi_face), each through the bead lag.  ``smooth_growth``:
    see :data:`SMOOTH_GROWTH`; ``contact_frac``: see :func:`fit_sensor_chain`.
    """
    key = ("design", *(np.asarray(x, dtype=np.float64).tobytes() for x in (t_s, T_tc_C, q_m_W_m2)), calibration,
           T_probe0_C, fit_start_s, tuple(breaks_s), None if disk is None else tuple(disk), smooth_growth, contact_frac)

    def design() -> tuple[np.ndarray, np.ndarray]:
        c = _prepare(t_s, T_tc_C, q_m_W_m2, calibration, T_probe0_C, fit_start_s, breaks_s,
                     smooth_growth=smooth_growth, contact_frac=contact_frac)
        phi = c.phiA - _applied(c.kkey, 1, c.KB, c.theta)
        X = _lag(np.column_stack((np.ones_like(c.t), phi, _response(phi, c.dt, disk))), c.dt, calibration.tc_tau_s)
        return X[c.fit], c.y[c.fit]
    # Kept (read-only): a calibration's leave-one-out refits and its second pass start from designs it
    # has built already (43 % of the self-check tests' designs were repeats).
    return _DESIGNS(key, design)


def fit_sensor_chain(t_s, T_tc_C, q_m_W_m2, *, T_probe0_C: float | None = None,
                     calibration: SensorChainCalibration = SensorChainCalibration(),
                     fit_start_s: float = 0.3, noise_T_K: float = 0.01, n_iterations: int = 1,
                     breaks_s: tuple[float, ...] = (), disk: tuple[float, float] | None = None,
                     smooth_s: float = SMOOTH_HALF_WIDTH_s, refine_dt_s: float | None = REFINE_DT_s,
                     contact_frac: float = 0.0) -> SensorChainResult:
    """Fit (e, R_c, T_obj0) to a record that starts at the moment of contact.

    Parameters
    ----------
    t_s : array (n,)
        Uniform times from contact (t_s[0] = 0 is the contact instant), s.
    T_tc_C : array (n,)
        Thermocouple reading (probe side of the contact), degC.
    q_m_W_m2 : array (n,)
        Thermopile reading (its voltage over the nominal sensitivity; positive into the object), W/m^2;
        ``calibration.flux_scale`` turns it into the depth-averaged flux.
    T_probe0_C : float, optional
        Probe temperature at contact (default: the first thermocouple sample, which the bead lag
        still holds at the probe's temperature).
    calibration : SensorChainCalibration
        Sensing layer and thermocouple lag.
    fit_start_s : float
        Samples before this are modelled (the convolutions start at contact) but not fitted:
        the contact transient's first samples are not linear between samples.
    noise_T_K : float
        Stated thermocouple noise (K), only to normalise the residual.
    breaks_s : tuple of float
        Times from contact where the heater switched (its slope jumps there: no smoothing across).
    disk : (radius_m, alpha_m2_s), optional
        The heated contact is a disk of that radius on an object of that diffusivity: the object's
        response loses heat sideways (see :func:`_disk_kernel`).  Default: 1-D (an infinite disk).
    smooth_s : float
        Largest half-width of the moving average on theta_b in the storage term (0: none; see
        :data:`SMOOTH_HALF_WIDTH_s`).
    refine_dt_s : float or None
        A record sampled coarser than this runs on a refined grid (:data:`REFINE_DT_s`); None: on its
        own samples, every input linear between them (the model of :func:`simulate_chain`).
    contact_frac : float
        On a refined grid: where within the record's first interval the contact happened (0: right
        after sample 0; :func:`edge.estimation.chain_estimate.estimate_from_contact` fits it).
    n_iterations : int
        Passes of phi_face.  The first uses the measured thermocouple as theta_b; further passes
        use the fitted theta_b, which is wrong over the unresolved contact transient and, through
        B's sqrt(s) memory, biased e by +3..5 % on FaithfulWorld records (glass, R_c 1e-4, -1 K)
        when used from t = 0.  Passes > 1 now keep the measured theta_b before ``fit_start_s``
        and the fitted one after (removing the correlated noise of the measured one): on the
        bench's cached 1-D records this helped glass/HDPE and hurt PMMA at R_c 1e-4 and
        aluminium (mixed), so the default stays 1.
    """
    c = _prepare(t_s, T_tc_C, q_m_W_m2, calibration, T_probe0_C, fit_start_s, breaks_s, smooth_s,
                 refine_dt_s=refine_dt_s, contact_frac=contact_frac)
    t, y, fit, dt, cal = c.t, c.y, c.fit, c.dt, calibration
    theta = c.theta
    for it in range(max(1, n_iterations)):
        phi = c.phiA - (_applied(c.kkey, 1, c.KB, theta) if it == 0 else _apply(c.KB, theta))
        X = np.column_stack((np.ones_like(t), phi, _response(phi, dt, disk)))
        Xl = _lag(X, dt, cal.tc_tau_s)
        p = _lstsq(Xl, y, fit)
        # Next pass: the fitted theta_b (noise-free: the measured noise, through B's sqrt(s) gain, is
        # correlated with y and biases 1/e) wherever the model follows the record; the measured
        # one over the contact transient's first samples, which the model cannot resolve.
        theta = np.where(fit, X @ p, theta)
    return _result(Xl, y, fit, p, c.Tp0, noise_T_K, it + 1)


def chain_point(t_s, T_tc_C, q_m_W_m2, *, calibration: SensorChainCalibration = SensorChainCalibration(),
                fit_start_s: float = 0.3, breaks_s: tuple[float, ...] = (), contact_frac: float = 0.0) -> ProfilePoint:
    """:func:`fit_sensor_chain`'s e and rms residual (one pass, 1-D; the same numbers) without its covariance:
    for a search comparing only those (the contact instant, :func:`edge.estimation.chain_estimate.contact_fraction`)."""
    c = _prepare(t_s, T_tc_C, q_m_W_m2, calibration, None, fit_start_s, breaks_s, contact_frac=contact_frac)
    phi = c.phiA - _applied(c.kkey, 1, c.KB, c.theta)
    Xl = _lag(np.column_stack((np.ones_like(c.t), phi, _response(phi, c.dt, None))), c.dt, calibration.tc_tau_s)
    p = _lstsq(Xl, c.y, c.fit)
    r = c.y[c.fit] - Xl[c.fit] @ p
    inv_e = p[2]
    return ProfilePoint(float(1.0 / inv_e if inv_e > 0 else float("inf")), math.sqrt(float(r @ r) / r.size),
                        int(r.size), math.nan)


def _unit_scale(Xf: np.ndarray) -> np.ndarray:
    """Column norms of the fitted columns (1 for an all-zero column): the solve runs on unit columns."""
    scale = np.sqrt(np.sum(Xf * Xf, axis=0))
    scale[scale == 0] = 1.0
    return scale


def _lstsq(Xl: np.ndarray, y: np.ndarray, fit: np.ndarray) -> np.ndarray:
    """(dT_obj0, R_c, 1/e) of the lagged columns Xl on the fitted samples (columns scaled to unit norm)."""
    Xf = Xl[fit]
    scale = _unit_scale(Xf)
    p_s, *_ = np.linalg.lstsq(Xf / scale, y[fit], rcond=None)
    return p_s / scale


def _result(Xl: np.ndarray, y: np.ndarray, fit: np.ndarray, p: np.ndarray, Tp0: float, noise_T_K: float,
            n_iterations: int) -> SensorChainResult:
    """The fit's values, their covariance (residual variance, lag-1 inflation) and quality."""
    Xf, yf = Xl[fit], y[fit]
    scale = _unit_scale(Xf)
    r = yf - Xf @ p
    m = r.size
    dof = max(1, m - 3)
    s2 = float(r @ r) / dof
    infl = _ar1_inflation(r)
    Xs = Xf / scale
    # pinv: a record without a contact step or without heating leaves a column (nearly) unused.
    cov_s = np.linalg.pinv(Xs.T @ Xs) * s2 * infl
    cov = cov_s / np.outer(scale, scale)
    sd = np.sqrt(np.diag(cov))
    sdd = np.outer(sd, sd)
    corr = np.divide(cov, sdd, out=np.zeros_like(cov), where=sdd > 0)
    inv_e, u_inv_e = p[2], sd[2]
    # The same covariance on the stated noise alone (no residual excess, no inflation), nuisances free
    # and known: which part of the fit's u is noise, which the nuisances, which the residual's excess.
    unit = np.linalg.pinv(Xs.T @ Xs) / np.outer(scale, scale)
    u_noise = noise_T_K * math.sqrt(max(float(unit[2, 2]), 0.0)) / abs(inv_e) if inv_e else math.inf
    g2 = float(Xf[:, 2] @ Xf[:, 2])
    u_known = noise_T_K / math.sqrt(g2) / abs(inv_e) if inv_e and g2 > 0 else math.inf
    e = 1.0 / inv_e if inv_e > 0 else float("inf")
    u_e = u_inv_e / inv_e**2 if inv_e > 0 else float("inf")
    rms = math.sqrt(float(r @ r) / m)
    return SensorChainResult(
        e_W_s05_m2K=float(e), u_e_W_s05_m2K=float(u_e),
        R_c_m2K_W=float(p[1]), u_R_c_m2K_W=float(sd[1]),
        T_obj0_C=float(Tp0 + p[0]), u_T_obj0_C=float(sd[0]),
        correlation=corr, normalised_residual=rms / noise_T_K, rms_residual_K=rms, n_iterations=n_iterations,
        n_fitted=int(m), residual_inflation=float(infl), u_ln_e_noise=float(u_noise),
        u_ln_e_noise_nuisance_known=float(u_known),
    )


@dataclass(frozen=True)
class ProfilePoint:
    """The part of a chain fit a profile over alpha reads: e, the residual and its lag-1 inflation."""

    e_W_s05_m2K: float
    rms_residual_K: float
    n_fitted: int
    residual_inflation: float


class DiskFitter:
    """:func:`fit_sensor_chain` (one pass) of one record for many heated disks, as a callable ``disk -> result``.

    The lateral loss only changes the object's column by ``-lag(K_disk * phi)``: phi, the 1-D
    column and their lags are made once, so a profile over the object's alpha costs one FFT
    convolution and one 3-column least squares per point (the same numbers as
    :func:`fit_sensor_chain` to rounding); :meth:`point` does without the covariance, projecting
    the object's column on the complement of the two fixed ones.  Arguments as for
    :func:`fit_sensor_chain`.
    """

    def __init__(self, t_s, T_tc_C, q_m_W_m2, *, calibration: SensorChainCalibration = SensorChainCalibration(),
                 fit_start_s: float = 0.3, noise_T_K: float = 0.01, breaks_s: tuple[float, ...] = (),
                 smooth_s: float = SMOOTH_HALF_WIDTH_s, T_probe0_C: float | None = None,
                 contact_frac: float = 0.0) -> None:
        c = _prepare(t_s, T_tc_C, q_m_W_m2, calibration, T_probe0_C, fit_start_s, breaks_s, smooth_s,
                     contact_frac=contact_frac)
        self._c, self._tau, self._noise = c, calibration.tc_tau_s, float(noise_T_K)
        self._phi = c.phiA - _applied(c.kkey, 1, c.KB, c.theta)
        self._X1 = _lag(np.column_stack((np.ones_like(c.t), self._phi, duhamel_apply(self._phi, c.dt))),
                        c.dt, self._tau)
        # Orthonormal basis of the fixed columns (T_obj0, R_c) on the fitted samples, and the record
        # with them projected out: a point of the profile then needs only dot products.
        self._Q, _ = np.linalg.qr(self._X1[c.fit][:, :2])
        yf = c.y[c.fit]
        self._yp = yf - self._Q @ (self._Q.T @ yf)

    def _column(self, disk) -> np.ndarray:
        loss = _disk_loss(self._phi, self._c.dt, disk)
        col = self._X1[:, 2]
        return col if loss is None else col - _lag(loss[:, None], self._c.dt, self._tau)[:, 0]

    def __call__(self, disk: tuple[float, float] | None = None) -> SensorChainResult:
        c = self._c
        Xl = self._X1.copy()
        Xl[:, 2] = self._column(disk)
        return _result(Xl, c.y, c.fit, _lstsq(Xl, c.y, c.fit), c.Tp0, self._noise, 1)

    def point(self, disk: tuple[float, float] | None = None) -> ProfilePoint:
        """e and the residual of the fit with ``disk``, without its covariance (the profile's inner loop)."""
        Q = self._Q
        v = self._column(disk)[self._c.fit]
        v = v - Q @ (Q.T @ v)
        v = v - Q @ (Q.T @ v)                      # twice: the projection stays orthogonal to rounding
        g = float(v @ v)
        inv_e = float(v @ self._yp) / g if g > 0 else 0.0
        r = self._yp - inv_e * v
        return ProfilePoint(1.0 / inv_e if inv_e > 0 else float("inf"), math.sqrt(float(r @ r) / r.size),
                            int(r.size), _ar1_inflation(r))
