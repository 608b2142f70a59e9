"""Tabulated EOS: reading, checks of malformed files, interpolation accuracy, bounds flags."""

import pathlib
import sys

import numpy as np
import pytest

from impactpipe.hydro.eos import (
    TABLE,
    EOSTableError,
    energy_from_pressure,
    pack_eos,
    pressure_sound_speed,
    read_sesame_table,
    reference_density,
    temperature,
    write_sesame_table,
)
from impactpipe.hydro.eos.tillotson import tillotson_cold_energy

DATA = pathlib.Path(__file__).parent / "data"
sys.path.insert(0, str(DATA))
from make_table import BASALT, PATH, tillotson_surfaces  # noqa: E402

EOS = pack_eos([BASALT, {"model": "table", "path": str(PATH)}, BASALT,
                {"model": "table", "path": str(PATH)}])


def analytic(rho, t):
    """(e, P, c2) of the analytic Tillotson basalt at (rho, T) with the table's temperature rule."""
    e = tillotson_cold_energy(EOS.params[0], rho) + BASALT["cv"] * (t - BASALT["T_ref"])
    p, c2, _ = pressure_sound_speed(EOS.kind[0], EOS.params[0], EOS.table, rho, e)
    return e, p, c2


def tabulated(k, rho, e):
    return pressure_sound_speed(EOS.kind[k], EOS.params[k], EOS.table, rho, e)


def test_shipped_table_reads_and_packs():
    table = read_sesame_table(PATH)
    assert table.density.shape == (60,) and table.temperature.shape == (60,)
    assert table.pressure.shape == (60, 60) and table.energy.shape == (60, 60)
    assert list(EOS.kind) == [2, TABLE, 2, TABLE]
    assert EOS.table.size == 2 * (60 + 60 + 2 * 3600)
    assert EOS.params[3, 0] == 60 + 60 + 2 * 3600   # second copy starts after the first
    assert reference_density(EOS.kind[1], EOS.params[1], EOS.table) == 2700.0


def test_table_reproduces_tillotson_within_stated_tolerance():
    """Over the grid interior: |dP| <= 2e-3 (|P| + 1 GPa), |dT| <= 3 K, c2 within 4 %."""
    rng = np.random.default_rng(7)
    rho = np.exp(rng.uniform(np.log(2160.0 * 1.001), np.log(8100.0 * 0.999), 400))
    t = rng.uniform(300.0, 20000.0, 400)
    for rho_n, t_n in zip(rho, t):
        e, p, c2 = analytic(rho_n, t_n)
        for k in (1, 3):
            p_tab, c2_tab, flag = tabulated(k, rho_n, e)
            assert flag == 0
            assert abs(p_tab - p) <= 2e-3 * (abs(p) + 1.0e9)
            assert c2_tab == pytest.approx(c2, rel=4e-2)
            assert temperature(EOS.kind[k], EOS.params[k], EOS.table, rho_n, e) == pytest.approx(
                t_n, abs=3.0)


def _rms_pressure_error(tmp_path, n):
    """RMS relative P error of an n x n table of the smooth compressed branch (P1)."""
    density = np.geomspace(3000.0, 6000.0, n)
    temps = np.linspace(300.0, 3000.0, n)
    pressure, energy = tillotson_surfaces(BASALT, density, temps)
    path = tmp_path / f"table_{n}.txt"
    write_sesame_table(path, density, temps, pressure, energy, rho_ref=2700.0)
    eos = pack_eos([{"model": "table", "path": str(path)}])
    probe_rho = np.geomspace(3050.0, 5900.0, 23)
    probe_t = np.linspace(350.0, 2950.0, 19)
    errors = []
    for rho_n in probe_rho:
        for t_n in probe_t:
            e, p, _ = analytic(rho_n, t_n)
            p_tab = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, rho_n, e)[0]
            errors.append((p_tab - p) / p)
    return float(np.sqrt(np.mean(np.square(errors))))


def test_interpolation_error_is_second_order(tmp_path):
    coarse = _rms_pressure_error(tmp_path, 9)
    fine = _rms_pressure_error(tmp_path, 17)
    assert fine < 2e-3
    assert 3.2 < coarse / fine < 5.0   # halving the spacing divides the error by ~4


def test_sound_speed_is_thermodynamic_derivative_of_the_interpolant():
    """Inside one cell, c2 matches a centred difference of the interpolated P on an isentrope."""
    for rho, e in [(3000.0, 2.0e6), (5000.0, 9.0e6), (2300.0, 1.2e7)]:
        p, c2, _ = tabulated(1, rho, e)
        h = 1.0e-7 * rho
        de = p / rho**2 * h
        fd = (tabulated(1, rho + h, e + de)[0] - tabulated(1, rho - h, e - de)[0]) / (2.0 * h)
        assert c2 == pytest.approx(fd, rel=1e-5)


def test_out_of_range_states_clamp_and_flag():
    e_mid, _, _ = analytic(4000.0, 5000.0)
    assert tabulated(1, 4000.0, e_mid)[2] == 0
    low = tabulated(1, 1000.0, analytic(2160.0, 5000.0)[0])
    edge = tabulated(1, 2160.0, analytic(2160.0, 5000.0)[0])
    assert low[2] == 1 and low[0] == pytest.approx(edge[0], rel=1e-12)
    high = tabulated(1, 20000.0, analytic(8100.0, 5000.0)[0])
    assert high[2] == 1 and high[0] == pytest.approx(tabulated(1, 8100.0, analytic(8100.0, 5000.0)[0])[0],
                                                     rel=1e-12)
    cold = tabulated(1, 4000.0, analytic(4000.0, 293.0)[0] - 1.0e6)
    assert cold[2] == 1 and cold[0] == pytest.approx(tabulated(1, 4000.0, analytic(4000.0, 293.0)[0])[0],
                                                     rel=1e-9)
    hot = tabulated(1, 4000.0, 1.0e9)
    assert hot[2] == 1 and np.isfinite(hot[0])
    assert temperature(EOS.kind[1], EOS.params[1], EOS.table, 4000.0, 1.0e9) == 20293.0


def test_energy_from_pressure_inverts_the_table():
    for rho, t in [(2500.0, 1000.0), (4000.0, 8000.0), (7000.0, 15000.0)]:
        e, _, _ = analytic(rho, t)
        p = tabulated(1, rho, e)[0]
        e_back = energy_from_pressure(EOS.kind[1], EOS.params[1], EOS.table, rho, p)
        assert e_back == pytest.approx(e, rel=1e-9)
    assert np.isnan(energy_from_pressure(EOS.kind[1], EOS.params[1], EOS.table, 4000.0, 1.0e15))


def _write_small(path, density=(1.0, 2.0, 3.0), temps=(100.0, 200.0),
                 pressure=((1.0, 2.0), (3.0, 4.0), (5.0, 6.0)),
                 energy=((10.0, 20.0), (30.0, 40.0), (50.0, 60.0))):
    write_sesame_table(path, density, temps, pressure, energy, rho_ref=2.0, comment="small test table")
    return path.read_text().splitlines()


def _rewrite(path, lines):
    path.write_text("\n".join(lines) + "\n")


def test_small_table_round_trip(tmp_path):
    path = tmp_path / "ok.txt"
    _write_small(path)
    table = read_sesame_table(path)
    assert table.rho_ref == 2.0
    assert np.array_equal(table.energy, [[10.0, 20.0], [30.0, 40.0], [50.0, 60.0]])


@pytest.mark.parametrize("edit, line, message", [
    (lambda ls: ls[:-1], 13, "file ends inside the energy block: it holds 4 of 6"),
    (lambda ls: ls + ["7.0"], 15, "unexpected value '7.0' after the energy block"),
    (lambda ls: [ls[0], "3 2", *ls[2:]], 2, "header must hold 3 values"),
    (lambda ls: [ls[0], "3 x 2.0", *ls[2:]], 2, "header n_T: 'x' is not an integer"),
    (lambda ls: [ls[0], "1 2 2.0", *ls[2:]], 2, "header n_rho: must be >= 2"),
    (lambda ls: ls[:3] + ["1 3 2"] + ls[4:], 4, "density grid not strictly increasing"),
    (lambda ls: ls[:3] + ["-1 2 3"] + ls[4:], 4, "density grid: must be > 0"),
    (lambda ls: ls[:5] + ["200 100"] + ls[6:], 6, "temperature grid not strictly increasing"),
    (lambda ls: ls[:12] + ["30 30"] + ls[13:], 13, "E not strictly increasing in T at rho=2.0"),
    (lambda ls: ls[:7] + ["1 nan"] + ls[8:], 8, "pressure block: value 'nan' is not finite"),
    (lambda ls: ls[:7] + ["1 two"] + ls[8:], 8, "pressure block: cannot read 'two'"),
])
def test_malformed_tables_raise_with_file_line_and_fault(tmp_path, edit, line, message):
    path = tmp_path / "bad.txt"
    lines = _write_small(path)
    assert lines[1] == "3 2 2.0" and lines[12].startswith("30")   # layout the edits rely on
    _rewrite(path, edit(lines))
    with pytest.raises(EOSTableError) as info:
        read_sesame_table(path)
    assert str(info.value).startswith(f"{path}:{line}: ")
    assert message in str(info.value)
    with pytest.raises(EOSTableError):
        pack_eos([{"model": "table", "path": str(path)}])


def test_empty_table_raises(tmp_path):
    path = tmp_path / "empty.txt"
    path.write_text("# nothing here\n")
    with pytest.raises(EOSTableError, match="empty table"):
        read_sesame_table(path)
