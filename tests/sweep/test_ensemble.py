"""Ensemble statistics of a compaction sweep (issue #12, item 4) on made-up members whose
curves are known: the mean, the 95% band, the stress grid, the two-regime fit."""

import csv
import json

import numpy as np
import pytest
from scipy import stats

from softgrains.sweep.ensemble import ensemble_statistics

SIGMA0 = 5e3
PHI0 = (0.70, 0.72, 0.74, 0.76)


def _phi_ratio(s):
    """Two regimes: slope 0.02 per decade up to 30 σ0, 0.08 beyond."""
    x, xb = np.log10(s), np.log10(30.0)
    return 1.0 + 0.02 * x + 0.06 * np.maximum(x - xb, 0.0)


def _member(folder, phi0, top, z0):
    """A compaction run: 5 pre-compaction rows at σ0, then σ/σ0 rising to ``top``."""
    folder.mkdir(parents=True)
    s = np.r_[np.ones(5), np.geomspace(1.01, top, 300)]
    phase = ["precompaction"] * 5 + ["compaction"] * 300
    with open(folder / "series.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "phase", "phi", "coordination", "stress_yy", "stress_yy_avg"])
        for k, (sk, ph) in enumerate(zip(s, phase, strict=True)):
            w.writerow([k, ph, phi0 * _phi_ratio(sk), z0 + np.log10(sk), sk * SIGMA0,
                        0.9 * sk * SIGMA0])
    (folder / "summary.json").write_text(json.dumps(
        {"status": "completed", "protocol": {"kind": "uniaxial-compaction", "sigma0": SIGMA0}}))


@pytest.fixture
def sweep_dir(tmp_path):
    members = []
    for mu in (0.0, 0.5):
        for seed, phi0 in enumerate(PHI0):
            name = f"friction-{mu}_seed-{seed}"
            _member(tmp_path / name, phi0, 300.0 if seed else 250.0, 4.0 + mu + seed)
            members.append({"name": name, "status": "done", "group": [str(mu)]})
    (tmp_path / "sweep.json").write_text(json.dumps(
        {"swept": ["contact.friction"], "seed_key": "simulation.seed", "members": members}))
    return tmp_path


def test_the_mean_curves_and_their_bands_are_those_of_the_members(sweep_dir):
    result = ensemble_statistics(sweep_dir)
    table = np.genfromtxt(sweep_dir / "ensemble" / "friction-0.0_wall.csv", delimiter=",",
                          names=True)
    s = table["sigma_ratio"]
    assert s[0] == pytest.approx(1.0) and s[-1] == pytest.approx(250.0)  # smallest top
    assert np.all(table["members"] == 4)
    # φ/φ0 is the same curve for every member: the mean is it, the band has no width
    assert table["phi_ratio_mean"] == pytest.approx(_phi_ratio(s), rel=1e-4)
    assert table["phi_ratio_high"] - table["phi_ratio_low"] == pytest.approx(0.0, abs=1e-4)
    # φ = φ0_i × the curve: mean φ0, band t(0.975, 3) s/√4
    phi0 = np.array(PHI0)
    half = stats.t.ppf(0.975, 3) * phi0.std(ddof=1) / 2.0
    assert table["phi_mean"] == pytest.approx(phi0.mean() * _phi_ratio(s), rel=1e-4)
    assert (table["phi_high"] - table["phi_mean"]) == pytest.approx(
        half * _phi_ratio(s), rel=1e-3)
    assert table["coordination_mean"] == pytest.approx(4.0 + 1.5 + np.log10(s), rel=1e-4)
    # against the averaged stress (0.9 of the wall's): the same curves, shifted
    avg = np.genfromtxt(sweep_dir / "ensemble" / "friction-0.0_average.csv",
                        delimiter=",", names=True)
    assert avg["phi_ratio_mean"] == pytest.approx(_phi_ratio(avg["sigma_ratio"] / 0.9),
                                                  rel=1e-4)
    group = result["groups"][0]
    assert group["label"] == "contact.friction = 0.0" and len(group["members"]) == 4
    fit = group["fit_wall"]
    assert fit["mean"]["break_ratio"] == pytest.approx(30.0, rel=0.15)
    assert fit["mean"]["slope_before"] == pytest.approx(0.02, abs=0.005)
    assert fit["mean"]["slope_after"] == pytest.approx(0.08, abs=0.01)
    assert len(fit["member_breaks"]) == 4 and fit["break_std"] < 0.2 * fit["break_mean"]
    for stress in ("wall", "average"):
        assert (sweep_dir / "ensemble" / f"ensemble_{stress}.png").stat().st_size > 10_000


def test_a_member_that_did_not_complete_is_left_out(sweep_dir):
    report = json.loads((sweep_dir / "sweep.json").read_text())
    report["members"][1]["status"] = "failed"
    (sweep_dir / "sweep.json").write_text(json.dumps(report))
    result = ensemble_statistics(sweep_dir)
    assert len(result["groups"][0]["members"]) == 3


def test_plot_of_a_sweep_folder_redraws_the_ensemble(sweep_dir, capsys):
    from softgrains.cli import main

    assert main(["plot", str(sweep_dir)]) == 0
    assert "ensemble_wall.png" in capsys.readouterr().out
    assert (sweep_dir / "ensemble" / "summary.json").is_file()
