"""Lift, pressure drag and quarter-chord moment by integrating tap pressures (docs/design.md §6).

The taps are joined into one closed contour — trailing edge → lower surface → leading-edge tap →
upper surface → trailing edge — and the pressure coefficient is integrated with the trapezoidal
rule along it (Anderson, Fundamentals of Aerodynamics, 6th ed., §1.5, eqs. 1.15–1.17):

    C_n = −∮ Cp d(x/c),   C_a = ∮ Cp d(z/c),   C_m = ∮ Cp [(x/c − 1/4) d(x/c) + (z/c) d(z/c)]

(C_m positive nose-up about the quarter chord), then rotated by the angle of attack:

    C_l = C_n cos α − C_a sin α,   C_d = C_n sin α + C_a cos α   (pressure drag only).

The trailing edge is closed with a point at (1, 0) carrying the mean Cp of the last valid upper
and lower taps.

Missing taps. A tap reading that is NaN/inf, or outside the scanner's range, is excluded and the
contour is drawn through the remaining taps. The sample stays valid only while the remaining taps
still cover the section (`CoverageCriterion`):
  * no gap between consecutive valid points along the contour larger than `max_gap_rad` in the
    contour parameter φ = ±arccos(1 − 2x/c) (naca_section.py). With cosine-clustered taps equal
    steps of φ are the design spacing (0.112 rad for the 49-tap row), and a φ-gap is already
    shortest in x/c at the leading edge. Defaults: 0.35 rad (two missing taps in a row) in
    general, and `leading_edge_max_gap_rad` = 0.25 rad (one missing tap) for a gap with an end
    ahead of `leading_edge_region_x_c` = 0.1, where the suction peak carries most of the lift:
    two adjacent missing taps there cost up to 3–6 % of C_l at small α, elsewhere < 1 %. The
    gap across the leading edge counts too;
  * on each surface the last valid tap lies at x/c ≥ `trailing_edge_min_x_c` (0.9).
Otherwise the sample is invalid: coefficients NaN, valid False, and a reason code (`Coverage`).
"""

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
from numba import njit

from pressure_scanner.taps import TapLayout, load_taps

# ZOC33 module with a ±10 inH2O (±2.49 kPa) range: the default scanner full scale.
DEFAULT_SCANNER_RANGE_PA = (-2490.0, 2490.0)
_X_REF = 0.25  # moment reference, chords


class Coverage(IntEnum):
    """Why a sample is invalid (OK when valid)."""

    OK = 0
    LEADING_EDGE_GAP = 1
    UPPER_GAP = 2
    LOWER_GAP = 3
    UPPER_TRAILING_EDGE = 4
    LOWER_TRAILING_EDGE = 5
    INVALID_ALPHA = 6
    INVALID_DYNAMIC_PRESSURE = 7


_REASON_TEXT = {
    Coverage.OK: "valid",
    Coverage.LEADING_EDGE_GAP: "gap in valid taps across the leading edge is too wide",
    Coverage.UPPER_GAP: "gap in valid upper-surface taps is too wide",
    Coverage.LOWER_GAP: "gap in valid lower-surface taps is too wide",
    Coverage.UPPER_TRAILING_EDGE: "no valid upper-surface tap near the trailing edge",
    Coverage.LOWER_TRAILING_EDGE: "no valid lower-surface tap near the trailing edge",
    Coverage.INVALID_ALPHA: "angle of attack is NaN/inf",
    Coverage.INVALID_DYNAMIC_PRESSURE: "dynamic pressure is not a positive finite number",
}


@dataclass(frozen=True)
class CoverageCriterion:
    """When the valid taps still cover the section well enough to integrate (module doc).

    max_gap_rad: largest allowed step in φ between consecutive valid contour points.
    leading_edge_max_gap_rad: the same for a step with an end ahead of leading_edge_region_x_c.
    trailing_edge_min_x_c: the last valid tap of each surface must lie at or aft of this x/c.
    """

    max_gap_rad: float = 0.35
    leading_edge_max_gap_rad: float = 0.25
    leading_edge_region_x_c: float = 0.1
    trailing_edge_min_x_c: float = 0.9

    def __post_init__(self) -> None:
        for name in ("max_gap_rad", "leading_edge_max_gap_rad"):
            value = getattr(self, name)
            if not (0.0 < value < np.pi):
                raise ValueError(f"{name} must lie in (0, π), got {value}")
        if not (0.0 <= self.leading_edge_region_x_c < 1.0):
            raise ValueError("leading_edge_region_x_c must lie in [0, 1)")
        if not (0.0 < self.trailing_edge_min_x_c <= 1.0):
            raise ValueError("trailing_edge_min_x_c must lie in (0, 1]")


@dataclass(frozen=True)
class Coefficients:
    """Integrated coefficients of K samples (always arrays; K = 1 for a single sample).

    cl, cd, cm, cn, ca: (K,) lift, pressure drag, quarter-chord moment (nose-up positive),
        normal and axial force coefficients; NaN where invalid.
    valid: (K,) bool.
    excluded: (K, n_taps) bool, taps left out of the integral (non-finite or out of range).
    out_of_range: (K, n_taps) bool, the subset excluded for lying outside the scanner range.
    n_excluded: (K,) int, excluded taps per sample.
    reason: (K,) int8 `Coverage` code (OK for valid samples, excluded taps or not).
    """

    cl: np.ndarray
    cd: np.ndarray
    cm: np.ndarray
    cn: np.ndarray
    ca: np.ndarray
    valid: np.ndarray
    excluded: np.ndarray
    out_of_range: np.ndarray
    n_excluded: np.ndarray
    reason: np.ndarray
    tap_names: tuple[str, ...] = field(default=(), repr=False)

    def describe(self, k: int = 0) -> str:
        """One line for sample k: validity, reason and which taps were excluded."""
        code = Coverage(int(self.reason[k]))
        names = self.tap_names or tuple(str(i) for i in range(self.excluded.shape[1]))
        gone = [names[i] for i in np.flatnonzero(self.excluded[k])]
        ranged = [names[i] for i in np.flatnonzero(self.out_of_range[k])]
        text = "valid" if self.valid[k] else f"invalid: {_REASON_TEXT[code]}"
        if gone:
            text += f"; {len(gone)} tap(s) excluded: {', '.join(gone)}"
            if ranged:
                text += f" (out of scanner range: {', '.join(ranged)})"
        return text


def contour_weights(x_c: np.ndarray, z_c: np.ndarray) -> np.ndarray:
    """Trapezoidal weights of an ordered open polyline: (3, P) rows for C_n, C_a, C_m, so that
    e.g. C_n = weights[0] @ Cp. The caller closes the contour (first/last point)."""
    x = np.asarray(x_c, dtype=float)
    z = np.asarray(z_c, dtype=float)
    dx = np.diff(x)
    dz = np.diff(z)
    half_dx = np.zeros_like(x)
    half_dz = np.zeros_like(x)
    half_dx[:-1] += 0.5 * dx
    half_dx[1:] += 0.5 * dx
    half_dz[:-1] += 0.5 * dz
    half_dz[1:] += 0.5 * dz
    return np.stack([-half_dx, half_dz, (x - _X_REF) * half_dx + z * half_dz])


@njit(cache=True)
def _integrate_contour(
    values: np.ndarray,
    alpha: np.ndarray,
    q: np.ndarray,
    use_range: bool,
    range_low: float,
    range_high: float,
    order: np.ndarray,
    x: np.ndarray,
    z: np.ndarray,
    phi: np.ndarray,
    side: np.ndarray,
    max_gap: float,
    le_max_gap: float,
    le_region_x: float,
    te_min_x: float,
    out: np.ndarray,
    reason: np.ndarray,
    excluded: np.ndarray,
    out_of_range: np.ndarray,
    n_excluded: np.ndarray,
) -> None:
    """values (K, n): pressures [Pa] divided by q (K,) into Cp, or Cp with q = 1; order (n,)
    tap indices along the contour (lower TE → LE → upper TE). Writes out (K, 5) = cn, ca, cm,
    cl, cd, reason (K,) `Coverage` codes, excluded / out_of_range (K, n), n_excluded (K,)."""
    n = order.shape[0]
    cp = np.empty(n)
    px = np.empty(n + 2)
    pz = np.empty(n + 2)
    pc = np.empty(n + 2)
    for k in range(values.shape[0]):
        for j in range(5):
            out[k, j] = np.nan
        q_ok = np.isfinite(q[k]) and q[k] > 0.0
        count = 0
        for i in range(n):
            v = values[k, i]
            bad = not np.isfinite(v)
            if not bad and use_range and (v < range_low or v > range_high):
                out_of_range[k, i] = True
                bad = True
            if not q_ok:
                bad = True
            excluded[k, i] = bad
            cp[i] = np.nan if bad else v / q[k]
            if bad:
                count += 1
        n_excluded[k] = count
        if not q_ok:
            reason[k] = 7
            continue
        if not np.isfinite(alpha[k]):
            reason[k] = 6
            continue
        # Gather valid points, checking gaps in φ and trailing-edge cover on the way.
        m = 1
        last_phi = np.nan
        last_x = np.nan
        gap_code = 0
        last_lower = -1
        last_upper = -1
        for j in range(n):
            i = order[j]
            if excluded[k, i]:
                continue
            if m > 1 and gap_code == 0:
                limit = le_max_gap if min(last_x, x[i]) < le_region_x else max_gap
                if phi[i] - last_phi > limit:
                    if last_phi < 0.0 and phi[i] > 0.0:
                        gap_code = 1
                    elif phi[i] > 0.0:
                        gap_code = 2
                    else:
                        gap_code = 3
            last_phi = phi[i]
            last_x = x[i]
            if side[i] < 0 and last_lower < 0:
                last_lower = i  # the contour runs from the lower trailing edge forward
            if side[i] > 0:
                last_upper = i
            px[m] = x[i]
            pz[m] = z[i]
            pc[m] = cp[i]
            m += 1
        if last_upper < 0 or x[last_upper] < te_min_x:
            reason[k] = 4
            continue
        if last_lower < 0 or x[last_lower] < te_min_x:
            reason[k] = 5
            continue
        if gap_code != 0:
            reason[k] = gap_code
            continue
        reason[k] = 0
        # Trailing edge closed with the mean of the last valid upper and lower taps.
        cp_te = 0.5 * (cp[last_lower] + cp[last_upper])
        px[0] = 1.0
        pz[0] = 0.0
        pc[0] = cp_te
        px[m] = 1.0
        pz[m] = 0.0
        pc[m] = cp_te
        cn = 0.0
        ca = 0.0
        cm = 0.0
        for j in range(m):
            dx = px[j + 1] - px[j]
            dz = pz[j + 1] - pz[j]
            c_mean = 0.5 * (pc[j] + pc[j + 1])
            cn -= c_mean * dx
            ca += c_mean * dz
            cm += 0.5 * (pc[j] * (px[j] - _X_REF) + pc[j + 1] * (px[j + 1] - _X_REF)) * dx
            cm += 0.5 * (pc[j] * pz[j] + pc[j + 1] * pz[j + 1]) * dz
        cos_a = np.cos(alpha[k])
        sin_a = np.sin(alpha[k])
        out[k, 0] = cn
        out[k, 1] = ca
        out[k, 2] = cm
        out[k, 3] = cn * cos_a - ca * sin_a
        out[k, 4] = cn * sin_a + ca * cos_a


class PressureIntegrator:
    """Integrates tap pressures of one tap layout into coefficients (module docstring).

    taps: TapLayout (default: config/taps.yaml); scanner_range_pa: (low, high) readings outside
    this range are saturated and excluded; criterion: CoverageCriterion.
    """

    def __init__(
        self,
        taps: TapLayout | None = None,
        scanner_range_pa: tuple[float, float] = DEFAULT_SCANNER_RANGE_PA,
        criterion: CoverageCriterion | None = None,
    ) -> None:
        self.taps = taps if taps is not None else load_taps()
        low, high = (float(v) for v in scanner_range_pa)
        if not low < high:
            raise ValueError(
                f"scanner_range_pa must be (low, high) with low < high, got {low, high}"
            )
        self.scanner_range_pa = (low, high)
        self.criterion = criterion or CoverageCriterion()
        t = self.taps
        self._order = np.concatenate([t.lower[::-1], [t.leading_edge], t.upper]).astype(np.int64)
        self._x = np.ascontiguousarray(t.x_c, dtype=np.float64)
        self._z = np.ascontiguousarray(t.z_c, dtype=np.float64)
        self._phi = np.ascontiguousarray(t.phi, dtype=np.float64)
        self._side = np.ascontiguousarray(t.side, dtype=np.int64)

    def integrate(
        self,
        pressure_pa: np.ndarray,
        alpha_rad: np.ndarray | float,
        dynamic_pressure_pa: np.ndarray | float,
    ) -> Coefficients:
        """Coefficients from tap pressures.

        pressure_pa: (n_taps,) or (K, n_taps) gauge pressures against free-stream static [Pa].
        alpha_rad: scalar or (K,) angle of attack used to rotate (C_n, C_a) into (C_l, C_d).
        dynamic_pressure_pa: scalar or (K,) q = ½ρU²; a sample with q not positive and finite
            is invalid (Coverage.INVALID_DYNAMIC_PRESSURE), all its taps excluded.
        """
        p = self._as_samples(pressure_pa, "pressure_pa")
        k = p.shape[0]
        q = self._per_sample(dynamic_pressure_pa, k, "dynamic_pressure_pa")
        return self._run(p, self._per_sample(alpha_rad, k, "alpha_rad"), q, True)

    def integrate_cp(self, cp: np.ndarray, alpha_rad: np.ndarray | float) -> Coefficients:
        """Coefficients from pressure coefficients cp (n_taps,) or (K, n_taps); no range check."""
        c = self._as_samples(cp, "cp")
        k = c.shape[0]
        return self._run(c, self._per_sample(alpha_rad, k, "alpha_rad"), np.ones(k), False)

    def _as_samples(self, values: np.ndarray, label: str) -> np.ndarray:
        arr = np.asarray(values, dtype=np.float64)
        if arr.ndim == 1:
            arr = arr[None, :]
        if arr.ndim != 2 or arr.shape[1] != self.taps.n_taps:
            raise ValueError(
                f"{label} must have shape ({self.taps.n_taps},) or (K, {self.taps.n_taps}) "
                f"for this tap layout, got {np.shape(values)}"
            )
        return np.ascontiguousarray(arr)

    @staticmethod
    def _per_sample(value: np.ndarray | float, k: int, label: str) -> np.ndarray:
        arr = np.asarray(value, dtype=np.float64)
        if arr.ndim == 0:
            return np.full(k, float(arr))
        if arr.shape != (k,):
            raise ValueError(f"{label} must be a scalar or shape ({k},), got {arr.shape}")
        return np.ascontiguousarray(arr)

    def _run(
        self, values: np.ndarray, alpha: np.ndarray, q: np.ndarray, use_range: bool
    ) -> Coefficients:
        k, n = values.shape
        out = np.empty((k, 5))
        reason = np.empty(k, dtype=np.int8)
        excluded = np.zeros((k, n), dtype=np.bool_)
        out_of_range = np.zeros((k, n), dtype=np.bool_)
        n_excluded = np.empty(k, dtype=np.int64)
        c = self.criterion
        _integrate_contour(
            values,
            alpha,
            q,
            use_range,
            self.scanner_range_pa[0],
            self.scanner_range_pa[1],
            self._order,
            self._x,
            self._z,
            self._phi,
            self._side,
            c.max_gap_rad,
            c.leading_edge_max_gap_rad,
            c.leading_edge_region_x_c,
            c.trailing_edge_min_x_c,
            out,
            reason,
            excluded,
            out_of_range,
            n_excluded,
        )
        return Coefficients(
            cl=out[:, 3],
            cd=out[:, 4],
            cm=out[:, 2],
            cn=out[:, 0],
            ca=out[:, 1],
            valid=reason == 0,
            excluded=excluded,
            out_of_range=out_of_range,
            n_excluded=n_excluded,
            reason=reason,
            tap_names=self.taps.names,
        )


def integrate_pressures(
    pressure_pa: np.ndarray,
    alpha_rad: np.ndarray | float,
    dynamic_pressure_pa: np.ndarray | float,
    taps: TapLayout | None = None,
    *,
    scanner_range_pa: tuple[float, float] = DEFAULT_SCANNER_RANGE_PA,
    criterion: CoverageCriterion | None = None,
) -> Coefficients:
    """One-shot `PressureIntegrator(taps, scanner_range_pa, criterion).integrate(...)`."""
    integrator = PressureIntegrator(taps, scanner_range_pa, criterion)
    return integrator.integrate(pressure_pa, alpha_rad, dynamic_pressure_pa)
