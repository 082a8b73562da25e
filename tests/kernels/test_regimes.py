"""The two-regime fit of a compaction curve (observe/regimes.py)."""

import numpy as np
import pytest

from softgrains.observe.regimes import fit_two_regimes


@pytest.mark.parametrize("true_break", [12.0, 30.0, 80.0])
def test_fit_finds_the_break_and_slopes_of_a_noisy_two_segment_curve(true_break):
    """φ/φ0 = 1 + 0.12 (x − x_b) below the break, slope 0.30 above (x = log10 σ/σ0), with
    noise of 0.005 (the scatter of the example runs' bursts): break within 20%, slopes
    within 0.03."""
    rng = np.random.default_rng(7)
    sigma = np.geomspace(5.0, 300.0, 300)
    x, xb = np.log10(sigma), np.log10(true_break)
    phi = 1.1 + 0.12 * (x - xb) + 0.18 * np.maximum(x - xb, 0.0)
    fit = fit_two_regimes(sigma, phi + rng.normal(0.0, 0.005, sigma.size))
    assert fit.break_ratio == pytest.approx(true_break, rel=0.2)
    assert fit.slope_before == pytest.approx(0.12, abs=0.03)
    assert fit.slope_after == pytest.approx(0.30, abs=0.03)
    assert fit.rms == pytest.approx(0.005, rel=0.3)


def test_too_few_samples_is_a_clear_error():
    with pytest.raises(ValueError, match="too few"):
        fit_two_regimes(np.array([10.0, 20.0, 30.0]), np.array([1.0, 1.1, 1.2]))


def test_a_straight_line_has_no_spurious_break_at_its_end():
    """Data that stop at 60 σ0 on one straight line: both slopes stay the line's (the break
    is searched inside the samples, each side keeping some)."""
    rng = np.random.default_rng(3)
    sigma = np.geomspace(5.0, 60.0, 80)
    phi = 1.0 + 0.15 * np.log10(sigma) + rng.normal(0.0, 0.003, sigma.size)
    fit = fit_two_regimes(sigma, phi)
    assert fit.slope_before == pytest.approx(0.15, abs=0.05)
    assert fit.slope_after == pytest.approx(0.15, abs=0.1)
