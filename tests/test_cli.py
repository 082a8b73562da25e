"""The command line: exit statuses, messages on stderr, and no tracebacks for user errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from softgrains.cli import main

EXAMPLE = Path(__file__).parents[1] / "examples" / "free_disk.toml"


def run_cli(*args: str | Path) -> tuple[int, str, str]:
    """Run ``python -m softgrains ARGS`` in a fresh interpreter: (status, stdout, stderr).
    The timeout only guards against a hang: on a fresh clone each interpreter compiles the
    Numba kernels from cold caches, and two cases run in parallel beside the other test
    worker took more than 120 s (session 24's fresh-clone CI)."""
    done = subprocess.run(
        [sys.executable, "-m", "softgrains", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    return done.returncode, done.stdout, done.stderr


def test_check_example_via_python_m() -> None:
    status, out, err = run_cli("check", EXAMPLE)
    assert status == 0, err
    assert "disk" in out and "21 x 21 = 441 nodes" in out and "100 steps" in out


@pytest.mark.parametrize(
    ("setting", "key"),
    [
        ("grid.cel_size=0.05", "[grid.cel_size]: unknown key; did you mean 'cell_size'?"),
        ('simulation.dt="0.001"', "[simulation.dt]"),
        ("materials.rubber.young=-1", "[materials.rubber.young]"),
        ("materials.rubber.poisson=0.5", "[materials.rubber.poisson]"),
        ("simulation.dt=0", "[simulation.dt]"),
        ("bodies.0.center=[0.9, 0.5]", "[bodies.0.center]"),
        ("bodies.0.material=steel", "[bodies.0.material]"),
        ("simulation.steps=100", "[simulation.steps]"),
        ("grid.cell_size=1e-6", "[grid.cell_size]"),
        ("samples.count=30", "[samples]: unknown key"),
    ],
)
def test_check_invalid_case_exits_2_naming_the_key(
    setting: str, key: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check", str(EXAMPLE), "--set", setting]) == 2
    err = capsys.readouterr().err
    assert err.startswith("softgrains: error: ")
    assert key in err
    assert "Traceback" not in err


def test_invalid_case_in_a_real_process_has_no_traceback(tmp_path: Path) -> None:
    case = tmp_path / "bad.toml"
    case.write_text(EXAMPLE.read_text().replace("poisson = 0.3", "poisson = 0.5"))
    for args in (["check", case], ["run", case, "--out", tmp_path / "out"]):
        status, _, err = run_cli(*args)
        assert status == 2
        assert "[materials.rubber.poisson] = 0.5: must be in (-1, 0.5)" in err
        assert "Traceback" not in err


def test_toml_syntax_error_and_missing_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[grid\n")
    assert main(["check", str(bad)]) == 2
    assert "line 1" in capsys.readouterr().err
    assert main(["check", str(tmp_path / "missing.toml")]) == 2
    assert "not found" in capsys.readouterr().err


def test_run_with_an_invalid_case_exits_2_before_simulating(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    status = main(["run", str(EXAMPLE), "--out", str(tmp_path), "--set", "bodies.0.radius=-1"])
    assert status == 2
    assert "[bodies.0.radius] = -1: must be > 0" in capsys.readouterr().err


def test_resume_without_a_checkpoint_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", str(EXAMPLE), "--out", str(tmp_path), "--resume"]) == 2
    assert "no checkpoint to resume from" in capsys.readouterr().err


def test_plot_of_a_missing_directory_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["plot", str(tmp_path / "nothing")]) == 2
    assert "no such run directory" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [[], ["bogus"], ["check"], ["run", "a.toml", "--frobnicate"]])
def test_bad_arguments_exit_2(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    assert "softgrains" in capsys.readouterr().err


def test_bad_override_syntax_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(EXAMPLE), "--set", "simulation.dt"]) == 2
    assert "expected KEY=VALUE" in capsys.readouterr().err


def test_help_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    assert "check" in capsys.readouterr().out


def test_info(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    for expected in (
        "softgrains",
        "python",
        "numpy",
        "scipy",
        "numba",
        "pydantic",
        "threads",
        "CPUs",
        "GPU:",
    ):
        assert expected in out


def test_run_several_cases_in_parallel_into_one_folder(tmp_path: Path) -> None:
    """`softgrains run A.toml B.toml --out DIR`: each case in DIR/<name>, both complete,
    each gets its figures; one failing case gives exit 3 and does not stop the other."""
    text = EXAMPLE.read_text()
    (tmp_path / "a.toml").write_text(text)
    (tmp_path / "b.toml").write_text(text.replace("end_time = 0.1", "end_time = 0.005"))
    out = tmp_path / "runs"
    status, stdout, stderr = run_cli("run", tmp_path / "a.toml", tmp_path / "b.toml",
                                     "--out", out, "--set", "simulation.end_time=0.005")
    assert status == 0, stderr
    for name in ("a", "b"):
        assert (out / name / "summary.json").is_file()
        assert (out / name / "figures" / "energy.png").is_file()
    assert "a.toml: done" in stdout and "b.toml: done" in stdout
    # b's disk pushed out of the grid fails; a completes
    (tmp_path / "b.toml").write_text(text.replace("velocity = [", "velocity = [200.0, 0.0] #["))
    status, stdout, _ = run_cli("run", tmp_path / "a.toml", tmp_path / "b.toml", "--out", out,
                                "--set", "simulation.end_time=0.005")
    assert status == 3 and "a.toml: done" in stdout and "b.toml: FAILED" in stdout


def test_same_file_names_are_refused(tmp_path: Path) -> None:
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "a.toml").write_text(EXAMPLE.read_text())
    (tmp_path / "a.toml").write_text(EXAMPLE.read_text())
    status, _, stderr = run_cli("run", tmp_path / "a.toml", tmp_path / "x" / "a.toml")
    assert status == 2 and "same file name" in stderr
