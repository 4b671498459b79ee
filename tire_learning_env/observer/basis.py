"""Soft-clipping activation basis of the neural tire-force approximator (SPEC §2, eqs. 9, 14, 30).

Each axle ``i`` has ``N`` activations of its slip angle,

    sigma_ij(a) = a + (1/lam) ln( (1 + exp(-lam (a - b_lo_ij))) / (1 + exp(lam (a - b_hi_ij))) )   (eq. 30)

a smooth clip of ``a`` to ``[b_lo, b_hi]`` (a constant ``b`` when ``b_lo == b_hi``: the
bias member), and the nonlinear axle force is approximated by

    f_i(a) = gamma_i sum_j W_ij sigma_ij(a)                                                       (eq. 14)

A basis reports what the LMI synthesis needs: the value bounds ``[b_lo, b_hi]`` of every
activation and the bounds of its slope ``d sigma / d a`` (``0`` and
``tanh(lam (b_hi - b_lo) / 4)``, reached at the midpoint).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..params import ParameterError, VehicleParams

__all__ = ["SoftClipBasis", "paper_basis", "two_sided_basis", "imu_basis", "make_basis", "BASIS_PRESETS"]


def _softplus(x: NDArray) -> NDArray:
    """``ln(1 + exp(x))`` without overflow."""
    return np.logaddexp(0.0, x)


def _sigmoid(x: NDArray) -> NDArray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


@dataclass(frozen=True)
class SoftClipBasis:
    """Per-axle soft-clipping activations with scales and a weight bound.

    Parameters
    ----------
    lower, upper : array_like, shape (2, N)
        ``b_lo``, ``b_hi`` of every activation [rad], row 0 front, row 1 rear.
        ``b_lo == b_hi`` makes a constant (bias) member.
    sharpness : float
        ``lam`` [1/rad]: corner sharpness.
    scale : array_like, shape (2,)
        ``gamma`` per axle [N/rad per unit weight].
    weight_bounds : tuple of (float or array (2, N))
        ``(W_lo, W_hi)``: weights are kept in ``[W_lo, W_hi]`` by projection (eq. 10 has
        the symmetric ``|W| <= W_max``).
    name : str
        Preset name.
    offset : array_like (2, N), optional
        Constant subtracted from each activation (default 0). ``"zero_slip"`` subtracts
        ``sigma_ij(0)`` from every non-constant member, so only the bias acts at zero
        slip and each segment's weight acts on its own segment and beyond: a shifted
        soft clip, with the same slopes (the LMI is unchanged).
    """

    lower: NDArray
    upper: NDArray
    sharpness: float
    scale: NDArray
    weight_bounds: tuple
    name: str = "custom"
    offset: NDArray | str | None = None

    def __post_init__(self) -> None:
        lo = np.asarray(self.lower, dtype=float)
        hi = np.asarray(self.upper, dtype=float)
        if lo.ndim != 2 or lo.shape[0] != 2 or lo.shape != hi.shape:
            raise ParameterError(f"basis bounds must both have shape (2, N), got {lo.shape} and {hi.shape}")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ParameterError("basis bounds must be finite")
        if np.any(lo > hi):
            raise ParameterError("basis lower bounds must not exceed upper bounds")
        sc = np.asarray(self.scale, dtype=float).reshape(-1)
        if sc.shape != (2,) or np.any(~(sc > 0)):
            raise ParameterError(f"basis scale (gamma) must be two positive values, got {self.scale!r}")
        if not (math.isfinite(self.sharpness) and self.sharpness > 0):
            raise ParameterError(f"basis sharpness (lambda) must be > 0, got {self.sharpness!r}")
        try:
            wlo = np.broadcast_to(np.asarray(self.weight_bounds[0], dtype=float), lo.shape).copy()
            whi = np.broadcast_to(np.asarray(self.weight_bounds[1], dtype=float), lo.shape).copy()
        except (TypeError, ValueError, IndexError) as exc:
            raise ParameterError(f"basis weight_bounds must be (W_lo, W_hi) scalars or (2, N) arrays: {exc}") from exc
        if not (np.all(np.isfinite(wlo)) and np.all(np.isfinite(whi)) and np.all(wlo <= 0) and np.all(whi >= 0)):
            raise ParameterError("basis weight_bounds need finite W_lo <= 0 <= W_hi (zero weights must be admissible)")
        object.__setattr__(self, "weight_bounds", (wlo, whi))
        if isinstance(self.offset, str):
            if self.offset != "zero_slip":
                raise ParameterError(f"basis offset must be an array or 'zero_slip', got {self.offset!r}")
            lam = self.sharpness
            raw = (np.logaddexp(0.0, lam * lo) - np.logaddexp(0.0, -lam * hi)) / lam  # sigma(0), eq. 30
            off = np.where(lo == hi, 0.0, raw)
        else:
            off = np.zeros_like(lo) if self.offset is None else np.broadcast_to(np.asarray(self.offset, float), lo.shape).copy()
        object.__setattr__(self, "offset", off)
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)
        object.__setattr__(self, "scale", sc)

    # -- sizes ---------------------------------------------------------------------------
    @property
    def n_per_axle(self) -> int:
        """``N``, activations per axle."""
        return self.lower.shape[1]

    @property
    def n_weights(self) -> int:
        """``2 N``: the length of the stacked weight vector ``w`` (eq. 17, front first)."""
        return 2 * self.n_per_axle

    # -- evaluation ----------------------------------------------------------------------
    def activations(self, alpha: ArrayLike, axle: int) -> NDArray:
        """``sigma_ij(alpha)`` for axle ``i`` (0 front, 1 rear), shape ``alpha.shape + (N,)`` (eq. 30)."""
        a = np.asarray(alpha, dtype=float)[..., None]
        lam = self.sharpness
        lo, hi = self.lower[axle], self.upper[axle]
        return a + (_softplus(-lam * (a - lo)) - _softplus(lam * (a - hi))) / lam - self.offset[axle]

    def slopes(self, alpha: ArrayLike, axle: int) -> NDArray:
        """``d sigma_ij / d alpha``, shape ``alpha.shape + (N,)``."""
        a = np.asarray(alpha, dtype=float)[..., None]
        lam = self.sharpness
        return _sigmoid(lam * (a - self.lower[axle])) - _sigmoid(lam * (a - self.upper[axle]))

    def nonlinear_force(self, alpha: ArrayLike, weights: ArrayLike, axle: int) -> NDArray:
        """``gamma_i sum_j W_ij sigma_ij(alpha)`` [N] with ``weights`` the full ``w`` (2N,) (eq. 14)."""
        w = np.asarray(weights, dtype=float).reshape(2, self.n_per_axle)[axle]
        return self.scale[axle] * self.activations(alpha, axle) @ w

    def nonlinear_slope(self, alpha: ArrayLike, weights: ArrayLike, axle: int) -> NDArray:
        """``d f_i / d alpha`` [N/rad]."""
        w = np.asarray(weights, dtype=float).reshape(2, self.n_per_axle)[axle]
        return self.scale[axle] * self.slopes(alpha, axle) @ w

    # -- bounds for the LMI --------------------------------------------------------------
    @property
    def value_bounds(self) -> tuple[NDArray, NDArray]:
        """``(b_lo, b_hi)`` minus the offset, each (2, N): the bounds of ``sigma_ij`` (eq. 11)."""
        return self.lower - self.offset, self.upper - self.offset

    @property
    def slope_bounds(self) -> tuple[NDArray, NDArray]:
        """``(0, tanh(lam (b_hi - b_lo)/4))``, each (2, N): bounds of ``d sigma/d alpha`` (eq. 12)."""
        return np.zeros_like(self.lower), np.tanh(self.sharpness * (self.upper - self.lower) / 4.0)

    @property
    def weight_lower(self) -> NDArray:
        """``W_lo`` (2, N)."""
        return self.weight_bounds[0]

    @property
    def weight_upper(self) -> NDArray:
        """``W_hi`` (2, N)."""
        return self.weight_bounds[1]

    @property
    def weight_range(self) -> float:
        """Largest ``(W_hi - W_lo)/2`` over the weights (a natural unit for priors)."""
        return float(np.max(self.weight_upper - self.weight_lower) / 2.0)

    def prior_correlation(self, length: float = 0.0, symmetry: float = 0.0) -> NDArray:
        """Prior correlation of the weights, (2N, 2N), block-diagonal per axle.

        Smooth-curve prior for slope-segment bases: weights of segments ``k`` apart (in
        segment index, same side of zero) correlate as ``exp(-k / length)``, mirror
        segments (same ``|slip|``, other side) as ``symmetry`` times that; constant
        members are uncorrelated. ``length = 0`` gives the identity (independent weights).
        """
        N = self.n_per_axle
        corr = np.eye(N)
        if length > 0:
            mid = 0.5 * (self.lower[0] + self.upper[0])
            const = self.lower[0] == self.upper[0]
            order = np.argsort(np.abs(mid))
            rank = np.empty(N)
            # rank of |centre| among the members of the same side (0 = next to zero slip)
            for side in (-1, 1):
                idx = [j for j in order if not const[j] and np.sign(mid[j]) == side]
                rank[idx] = np.arange(len(idx))
            for i in range(N):
                for j in range(N):
                    if i == j or const[i] or const[j]:
                        continue
                    c = math.exp(-abs(rank[i] - rank[j]) / length)
                    corr[i, j] = c if np.sign(mid[i]) == np.sign(mid[j]) else symmetry * c
        return np.kron(np.eye(2), corr)

    def slope_prior(self, length: float, symmetry: float = 0.0) -> NDArray:
        """Prior correlation (2N, 2N) of the weights as samples of a smooth slope function.

        The weights of slip segments are deviations of the curve's slope on their segment;
        a Gaussian process with squared-exponential kernel over slip, of length scale
        ``length`` [rad], correlates segments by their slip distance (narrow segments near
        zero move together, so the slope there is informed by the whole neighbourhood), and
        ``symmetry`` in [0, 1) adds the mirror term ``exp(-(a_i + a_j)^2 / 2 length^2)``
        (a tire curve is nearly odd: left and right turns share their slope). Constant
        (bias) members are independent. Block-diagonal per axle; unit diagonal.
        """
        N = self.n_per_axle
        out = np.zeros((2 * N, 2 * N))
        for i in (0, 1):
            lo, hi = self.lower[i], self.upper[i]
            const = lo == hi
            mid = 0.5 * (lo + hi)
            if length > 0:
                d = mid[:, None] - mid[None, :]
                m = mid[:, None] + mid[None, :]
                K = (np.exp(-0.5 * (d / length) ** 2) + symmetry * np.exp(-0.5 * (m / length) ** 2)) / (1.0 + symmetry)
                norm = np.sqrt(np.diag(K))
                K = K / np.outer(norm, norm)
            else:
                K = np.eye(N)
            K[const, :] = 0.0
            K[:, const] = 0.0
            K[const, const] = 1.0
            out[i * N : (i + 1) * N, i * N : (i + 1) * N] = K + 1e-6 * np.eye(N)
        return out

    def force_slope_bounds(self, margin: float = 0.01) -> NDArray:
        """Bounds ``[[lo_f, hi_f], [lo_r, hi_r]]`` [N/rad] of ``d f_i/d alpha`` over all admissible weights.

        Since ``sigma' >= 0`` and ``W_lo <= W <= W_hi``,
        ``gamma_i min_a sum_j W_lo_ij sigma'_ij(a) <= d f_i/d a <= gamma_i max_a sum_j W_hi_ij sigma'_ij(a)``:
        the paper's Lipschitz polytope from the activation slope bounds and the weight
        bounds (eqs. 10-12, 25), evaluated on a 1e-5 rad grid (``sigma'`` is Lipschitz
        with constant ``lam/4``, so the grid error is below ``lam 1.25e-6`` per activation)
        and widened by ``margin`` (relative). Activations that do not overlap in slip
        contribute one at a time, which keeps the box tight.
        """
        a = np.arange(float(self.lower.min()) - 0.1, float(self.upper.max()) + 0.1, 1e-5)
        out = np.empty((2, 2))
        for i in (0, 1):
            sl = self.slopes(a, i)  # (n, N)
            lo = self.scale[i] * float(np.min(sl @ self.weight_lower[i]))
            hi = self.scale[i] * float(np.max(sl @ self.weight_upper[i]))
            pad = margin * max(abs(lo), abs(hi)) + self.scale[i] * self.sharpness * 1.25e-6 * self.n_per_axle
            out[i] = (lo - pad, hi + pad)
        return out

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "lower": self.lower.tolist(),
            "upper": self.upper.tolist(),
            "sharpness": self.sharpness,
            "scale": self.scale.tolist(),
            "weight_bounds": [self.weight_lower.tolist(), self.weight_upper.tolist()],
            "offset": self.offset.tolist(),
        }


def paper_basis() -> SoftClipBasis:
    """The paper's basis (Sec. IV): one-sided bounds, ``lam = 300``, ``gamma = 5000``, ``|W| <= 50``.

    Flat below +0.005 rad (up to the soft corner): it cannot represent a force for
    negative slip. Its weight box gives a slope box of about +/-3.4 times the nominal
    axle stiffness, which makes the certified gains high-bandwidth (fine for the paper's
    noise-free 1 kHz camera, noise-sensitive otherwise).
    """
    lower = [[0.005, 0.005, 0.005, 0.1], [0.005, 0.005, 0.005, 0.1]]
    upper = [[0.02, 0.05, 0.08, 0.1], [0.01, 0.03, 0.08, 0.1]]
    return SoftClipBasis(np.array(lower), np.array(upper), 300.0, np.array([5000.0, 5000.0]), (-50.0, 50.0), "paper")


def two_sided_basis(
    vehicle: VehicleParams | None = None,
    breakpoints: Sequence[float] = (0.002, 0.0045, 0.008, 0.013, 0.02, 0.031, 0.05, 0.09, 0.2),
    sharpness: float = 5000.0,
    slope_range: tuple[float, float] = (-0.8, 0.6),
    bias_level: float = 0.01,
    bias_bound: float = 0.5,
) -> SoftClipBasis:
    """Default basis: one soft clip per slip segment on each side of zero, plus a bias.

    With breakpoints ``0 < b_1 < ... < b_K`` the activations are ``clip(a, b_{k-1}, b_k)``
    and ``clip(a, -b_k, -b_{k-1})`` (``b_0 = 0``): each moves only on its own segment, so
    a weight is the change of the curve's *slope* on that segment, left and right turns
    are learned separately, and segments the driving never excites keep the nominal
    slope. The scale ``gamma_i = 2 C_i`` (nominal axle stiffness) makes a weight a
    dimensionless stiffness fraction; ``slope_range = (W_lo, W_hi)`` bounds it, so the
    learned curve's slope stays within ``(1 + W_lo, 1 + W_hi)`` times nominal, which is
    exactly the box the gain LMIs certify (tight, because segments do not overlap).
    Every segment activation is shifted to vanish at zero slip (``offset="zero_slip"``),
    so a weight acts only from its segment outwards and only the bias acts at zero.
    The bias member is the constant ``bias_level`` [rad] with weight in
    ``+/- bias_bound`` (an offset force such as a crosswind or a road bank).
    """
    vehicle = vehicle or VehicleParams()
    b = np.asarray(breakpoints, dtype=float)
    if b.ndim != 1 or len(b) == 0 or np.any(np.diff(np.r_[0.0, b]) <= 0):
        raise ParameterError("breakpoints must be increasing positive slip angles [rad]")
    edges = np.r_[0.0, b]
    lo_neg, hi_neg = -edges[1:][::-1], -edges[:-1][::-1]
    row_lo = list(lo_neg) + list(edges[:-1]) + [bias_level]
    row_hi = list(hi_neg) + list(edges[1:]) + [bias_level]
    n_seg = 2 * len(b)
    w_lo = np.array([slope_range[0]] * n_seg + [-bias_bound])
    w_hi = np.array([slope_range[1]] * n_seg + [bias_bound])
    scale = np.array([2.0 * vehicle.Cf, 2.0 * vehicle.Cr])
    return SoftClipBasis(
        np.array([row_lo, row_lo]), np.array([row_hi, row_hi]), sharpness, scale,
        (np.vstack([w_lo, w_lo]), np.vstack([w_hi, w_hi])), "two_sided", offset="zero_slip",
    )  # fmt: skip


def without_bias(basis: SoftClipBasis, name: str | None = None) -> SoftClipBasis:
    """The basis without its constant (bias) members.

    With ``(a_y, r)`` only, a force offset at zero slip cannot be told apart from a
    sideslip offset (shifting both axle curves by the same slip leaves every measured force
    and the known slip difference ``delta - L r / vx`` unchanged), so IMU-only estimation
    imposes ``F(0) = 0`` instead of learning it.
    """
    keep = ~np.all(basis.lower == basis.upper, axis=0)
    return SoftClipBasis(
        basis.lower[:, keep], basis.upper[:, keep], basis.sharpness, basis.scale,
        (basis.weight_lower[:, keep], basis.weight_upper[:, keep]), name or f"{basis.name}_no_bias",
        offset=basis.offset[:, keep],
    )  # fmt: skip


def imu_basis(vehicle: VehicleParams | None = None, slope_fractions: tuple[float, float] = (0.1, 1.5)) -> SoftClipBasis:
    """The two-sided segment basis without the bias member, learned slope in
    ``slope_fractions`` times nominal (IMU-only estimation; see :func:`without_bias`)."""
    lo, hi = slope_fractions
    full = two_sided_basis(vehicle, slope_range=(lo - 1.0, hi - 1.0), bias_bound=0.0)
    return without_bias(full, "imu_two_sided")


BASIS_PRESETS = {"paper": paper_basis, "two_sided": two_sided_basis, "imu_two_sided": imu_basis}


def make_basis(name: str | SoftClipBasis, vehicle: VehicleParams | None = None) -> SoftClipBasis:
    """A preset by name (``two_sided`` default, ``paper``, ``imu_two_sided``) or the basis itself."""
    if isinstance(name, SoftClipBasis):
        return name
    if name not in BASIS_PRESETS:
        raise ParameterError(f"unknown basis preset {name!r}; presets are {sorted(BASIS_PRESETS)}")
    return paper_basis() if name == "paper" else BASIS_PRESETS[name](vehicle)
