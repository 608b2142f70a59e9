"""`impactpipe qstar` over run directories with known M_lr/M_T(Q)."""

import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from impactpipe.pipeline.cli import main
from impactpipe.pipeline.config import load_config
from impactpipe.storage import write_text_atomic
from impactpipe.pipeline.stages import resolved_yaml

BASE = Path(__file__).parent / "configs" / "sweep_base.yaml"
QSTAR = 1790.0


def make_run(directory: Path, velocity: float, offset: float = 0.0) -> None:
    """A finished run on the exact line M_lr/M_T = 1 - Q / (2 QSTAR), moved by ``offset``."""
    config = load_config(BASE, overrides={"scene.impact.velocity": velocity})
    q = 0.5 * (830.0 / 1.0e4) ** 3 * velocity ** 2
    directory.mkdir(parents=True)
    write_text_atomic(directory / "config.resolved.yaml", resolved_yaml(config))
    (directory / "summary.json").write_text(json.dumps({"Q": q, "M_lr_over_M_T": 1 - 0.5 * q / QSTAR + offset,
                                                        "N_lr": 1000}))


def test_qstar_command_fits_runs(tmp_path):
    runs = []
    for v in (1500.0, 2000.0, 2500.0, 3000.0):
        make_run(tmp_path / f"v{v:.0f}", v)
        runs.append(str(tmp_path / f"v{v:.0f}"))
    result = CliRunner().invoke(main, ["qstar", *runs, "--out", str(tmp_path / "fit")])
    assert result.exit_code == 0, result.output
    line = next(l for l in result.output.splitlines() if "Q*_D =" in l)
    assert abs(float(line.split("Q*_D = ")[1].split()[0]) - QSTAR) / QSTAR < 1e-3
    v_crit = np.sqrt(2 * QSTAR / (830.0 / 1.0e4) ** 3)
    line = next(l for l in result.output.splitlines() if l.startswith("critical velocity"))
    assert abs(float(line.split()[3]) - v_crit) / v_crit < 1e-3
    assert (tmp_path / "fit" / "qstar.csv").is_file() and (tmp_path / "fit" / "qstar.png").stat().st_size > 0


def test_qstar_reports_the_scatter_of_replicated_runs(tmp_path):
    """Two runs per speed, +-0.02 about the line: the fit reports their standard deviation
    (0.02 sqrt(2) = 0.028) and gets an error bar from two speeds."""
    runs = []
    for v in (1500.0, 3000.0):
        for offset in (-0.02, 0.02):
            make_run(tmp_path / f"v{v:.0f}{offset:+.2f}", v, offset)
            runs.append(str(tmp_path / f"v{v:.0f}{offset:+.2f}"))
    result = CliRunner().invoke(main, ["qstar", *runs, "--out", str(tmp_path / "fit")])
    assert result.exit_code == 0, result.output
    line = next(l for l in result.output.splitlines() if l.startswith("replicates:"))
    assert "2 Q values run more than once" in line and "at the same Q = 0.028" in line
    assert "no error bar" not in next(l for l in result.output.splitlines() if "Q*_D =" in l)
    assert "# replicates: 2 Q values" in (tmp_path / "fit" / "qstar.csv").read_text()


def test_qstar_moves_to_a_common_velocity(tmp_path):
    runs = []
    for v in (1500.0, 2000.0, 2500.0, 3000.0):
        make_run(tmp_path / f"v{v:.0f}", v)
        runs.append(str(tmp_path / f"v{v:.0f}"))
    result = CliRunner().invoke(main, ["qstar", *runs, "--out", str(tmp_path / "fit"), "--common-velocity", "5000"])
    assert result.exit_code == 0, result.output
    line = next(l for l in result.output.splitlines() if l.startswith("Q*_D at 5000"))
    v_crit = np.sqrt(2 * QSTAR / (830.0 / 1.0e4) ** 3)
    expected = QSTAR * (5000.0 / v_crit) ** (2 - 3 * 0.45)
    assert abs(float(line.split("=")[-1].split()[0]) - expected) / expected < 1e-3


def test_qstar_warns_when_runs_do_not_bracket(tmp_path):
    runs = []
    for v in (1000.0, 1200.0, 1400.0):
        make_run(tmp_path / f"v{v:.0f}", v)
        runs.append(str(tmp_path / f"v{v:.0f}"))
    result = CliRunner().invoke(main, ["qstar", *runs, "--out", str(tmp_path / "fit")])
    assert result.exit_code == 0
    assert "do not bracket" in result.output


def test_qstar_rejects_unfinished_run(tmp_path):
    make_run(tmp_path / "a", 2000.0)
    (tmp_path / "a" / "summary.json").write_text("{}")
    result = CliRunner().invoke(main, ["qstar", str(tmp_path / "a")])
    assert result.exit_code == 2 and "lacks Q, M_lr_over_M_T, N_lr" in result.output
