"""Two compaction regimes: a continuous two-segment fit of φ/φ0 against log10(σ/σ0).

VALIDATION.md C9: φ/φ0 grows with log σ in two regimes, the second steeper, with the change
near 30 σ0 (Nezamabadi et al. 2015). With x = log10(σ/σ0) and a break x_b,
    φ/φ0 ≈ a + s1 (x − x_b) + (s2 − s1) max(0, x − x_b),
fitted by least squares for every x_b on a grid; the x_b with the smallest residual wins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TwoRegimes:
    """The fit: break stress (in σ0), slopes before and after (per decade), rms residual."""

    break_ratio: float
    slope_before: float
    slope_after: float
    rms: float
    samples: int


MIN_SAMPLES_PER_SEGMENT = 5


def fit_two_regimes(stress_ratio: np.ndarray, phi_ratio: np.ndarray, lower: float = 5.0,
                    upper: float = 300.0, breaks: int = 200) -> TwoRegimes:
    """Fit φ/φ0 against log10(σ/σ0) over [lower, upper] σ0 with two joined lines; the break
    is searched over the samples' own range, with at least MIN_SAMPLES_PER_SEGMENT samples
    on each side."""
    sigma = np.asarray(stress_ratio, float)
    phi = np.asarray(phi_ratio, float)
    keep = (sigma >= lower) & (sigma <= upper) & np.isfinite(phi)
    x, y = np.log10(sigma[keep]), phi[keep]
    k = MIN_SAMPLES_PER_SEGMENT
    if x.size < 2 * k + 2:
        raise ValueError(f"{x.size} samples between {lower:g} and {upper:g} σ0: too few for "
                         "a two-regime fit")
    ordered = np.sort(x)
    best = None
    for xb in np.linspace(ordered[k], ordered[-k - 1], breaks):
        basis = np.c_[np.ones_like(x), x - xb, np.maximum(x - xb, 0.0)]
        coef = np.linalg.lstsq(basis, y, rcond=None)[0]
        sse = float(np.sum((basis @ coef - y) ** 2))
        if best is None or sse < best[0]:
            best = (sse, xb, coef)
    sse, xb, coef = best
    return TwoRegimes(float(10.0**xb), float(coef[1]), float(coef[1] + coef[2]),
                      float(np.sqrt(sse / x.size)), int(x.size))
