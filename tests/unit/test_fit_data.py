"""Reading measured records for ``braidsim fit``, and the one-line refusals of bad input
(exit 2, nothing written)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from braidsim.errors import InputError
from braidsim.fit import make_record, parse_fit_spec, read_record
from braidsim.fit.data import detect_pulses, noise_estimate


def _csv(path: Path, header: str, rows: np.ndarray) -> Path:
    np.savetxt(path, rows, delimiter=",", header=header, comments="")
    return path


def test_csv_units_in_brackets_are_converted_to_si(tmp_path):
    t = np.arange(1, 6) * 0.1  # ms
    x = np.array([0.0, 0.5, 1.0, 1.5, 2.0])  # mm
    a = np.array([-3.0, -3.0, 100.0, -3.0, -3.0])
    p = _csv(tmp_path / "r.csv", "t [ms],x [mm],acceleration [m/s^2],other [N]", np.c_[t, x, a, a])
    rec = read_record(p)
    assert np.allclose(rec.t, t * 1e-3)
    assert np.allclose(rec.columns["x"], x * 1e-3)
    assert np.allclose(rec.columns["acceleration"], a)
    assert set(rec.columns) == {"x", "acceleration"}
    assert rec.sample_interval == pytest.approx(1e-4)


def test_xarray_and_netcdf_records(tmp_path):
    xr = pytest.importorskip("xarray")
    t = np.linspace(0.0, 0.01, 11)
    ds = xr.Dataset(
        {"x": ("t", np.linspace(0, 2, 11), {"units": "mm"})}, coords={"t": ("t", t, {"units": "s"})}
    )
    rec = read_record(ds)
    assert rec.columns["x"][-1] == pytest.approx(2e-3)
    p = tmp_path / "r.nc"
    ds.to_netcdf(p, engine="h5netcdf")
    assert np.allclose(read_record(p).columns["x"], rec.columns["x"])


@pytest.mark.parametrize(
    ("header", "rows", "words"),
    [
        ("time,x", [[0, 1], [1, 2], [2, 3]], "no column t"),
        ("t,x", [[0, 1], [2, 2], [1, 3]], "not strictly increasing at row 2"),
        ("t,x", [[0, 1], [1, 1], [1, 3]], "not strictly increasing"),
        ("t,x", [[0, 1], [1, math.nan], [2, 3]], "column x has a missing"),
        ("t,x [N]", [[0, 1], [1, 2], [2, 3]], "unit [N] does not match the quantity 'x'"),
        ("t [m],x", [[0, 1], [1, 2], [2, 3]], "unit [m] does not match the quantity 't'"),
        # (an accelerometer's g: pint's g is the gram)
        ("t,acceleration [g]", [[0, 1], [1, 2], [2, 3]], "write [g0] for standard gravity"),
        # (pandas renamed the second "x.1", which was then ignored)
        ("t,x,x", [[0, 1, 1], [1, 2, 2], [2, 3, 3]], "column 'x' appears twice"),
        # (pandas took the first column for an index: every column shifted, a NaN at row 1)
        ("t,x", [[0, 1, 9], [1, 2, 9], [2, 3, 9]], "more fields than the header's 2"),
        ("t,y", [[0, 1], [1, 2], [2, 3]], "no measured column"),
        ("t,x", [[-1, 1], [1, 2], [2, 3]], "allowed times >= 0"),
        # (a glitch of 1e308: the noise estimate's differences overflowed, then the
        # time-scale check raised OverflowError, an internal error)
        ("t,acceleration", [[0, 1], [1, 1e308], [2, 3]], "column acceleration has 1e+308"),
        ("t,acceleration", [[0, 1], [1, -1e200], [2, 3]], "allowed magnitudes up to 1e+100"),
        # (finite as written, beyond the float range once converted to SI)
        ("t,x [km]", [[0, 1], [1, 1e306], [2, 3]], "column x has inf m at row 1"),
        ("t,peak_force", [[0, 1], [1, 1e150]], "column peak_force has 1e+150 N"),
    ],
)
@pytest.mark.filterwarnings("error")
def test_bad_records_are_named_in_one_line(tmp_path, header, rows, words):
    p = _csv(tmp_path / "r.csv", header, np.array(rows, dtype=float))
    with pytest.raises(InputError) as err:
        read_record(p)
    assert words in str(err.value)
    assert "\n" not in str(err.value)


def test_noise_estimate_and_pulses_on_a_known_signal():
    rng = np.random.default_rng(3)
    t = np.arange(20_000) * 1e-4
    y = 0.5 * t**2 + rng.normal(0.0, 2.0, t.size)  # smooth motion + white noise
    assert noise_estimate(y) == pytest.approx(2.0, rel=0.03)
    pulses = np.zeros_like(t)
    for t0 in (0.3, 0.8, 1.5):
        k = np.searchsorted(t, t0)
        pulses[k + 1 : k + 4] = [500.0, 1000.0, 500.0]
    onsets, _ = detect_pulses(t, pulses + rng.normal(0, 2.0, t.size), 2.0)
    assert np.allclose(onsets, [0.30005, 0.80005, 1.50005], atol=1.1e-4)


def test_spec_refuses_bad_entries():
    base = {"scenario": "paper-3.1", "fit": {"free": {"track.clearance": ["2 mm", "4 mm"]}}}
    assert parse_fit_spec(base).free[0].start == pytest.approx(3e-3)
    bad = [
        ({"free": {"track.clearence": [0.002, 0.004]}}, "did you mean 'track.clearance'"),
        ({"free": {"track.clearance": ["4 mm", "2 mm"]}}, "not an interval"),
        ({"free": {"track.clearance": ["2 s", "4 mm"]}}, "wrong unit"),
        ({"free": {"contact.track.model": [0, 1]}}, "not a numeric scenario key"),
        ({"free": {"track.clearance": [0.002, 0.004]}, "quantity": "v"}, "fit.quantity"),
        ({"free": {"track.clearance": [0.002, 0.004]}, "laws": ["hunt"]}, "not a contact law"),
        ({"free": {"track.clearance": [0.002, 0.004]}, "profile": ["initial.x"]}, "not a free"),
        ({"free": {}}, "no free parameter"),
        # (solver settings: the refusal came from the sensitivities, "sensitivity: ...")
        ({"free": {"simulation.duration": ["0.1 s", "0.2 s"]}}, "fit.free: 'simulation.duration"),
        ({"free": {"simulation.rtol": [1e-8, 1e-6]}}, "setting of the solver"),
    ]
    for fit, words in bad:
        with pytest.raises(InputError, match=words.replace("(", r"\(")):
            parse_fit_spec({"scenario": "paper-3.1", "fit": fit})


def test_api_arguments_of_the_wrong_type_are_named():
    # (each raised TypeError)
    from braidsim.fit import fit

    rec = {"t": [0.001, 0.002, 0.003], "acceleration": [0.0, 9.0, 0.0]}
    for free in ([1, 2], None):
        with pytest.raises(InputError, match=r"^free: .* allowed a mapping \{key: \[low, high\]\}"):
            fit("paper-3.1", rec, free=free, quantity="acceleration")
    free = {"track.clearance": ["2.5 mm", "3.5 mm"]}
    with pytest.raises(InputError, match=r"^overrides: list is not allowed; allowed a mapping"):
        fit("paper-3.1", rec, free, quantity="acceleration", overrides=[1])
    with pytest.raises(InputError, match=r"^data\[0\]: a tuple of 3 items is not allowed"):
        fit("paper-3.1", [(rec, {}, 1)], free, quantity="acceleration")
    for table in ([1], None):
        with pytest.raises(InputError, match=r"^fit spec: table is a .* allowed a mapping"):
            parse_fit_spec(table)


def test_make_record_checks_lengths():
    with pytest.raises(InputError, match="3 values for 4 times"):
        make_record([0, 1, 2, 3], {"x": [0, 1, 2]})


def test_a_series_csv_of_braidsim_run_is_read_as_a_record(tmp_path) -> None:
    """`braidsim run --csv` repeats a sample time in its start and end rows (kind 5, 6): the
    record keeps the last row of each time, as series.nc does (the CSV was refused: "column
    t is not strictly increasing at row 1")."""
    import braidsim
    from braidsim.fit.data import read_record

    res = braidsim.simulate("paper-3.1", 0.01, sample_interval=1e-4)
    (path,) = [p for p in res.to_csv(tmp_path) if p.name == "series.csv"]
    rec = read_record(path)
    ds = res.to_xarray()
    # (the CSV keeps 10 significant digits)
    assert rec.t.size == ds["t"].size
    np.testing.assert_allclose(rec.t, ds["t"].values, rtol=1e-9, atol=0)
    np.testing.assert_allclose(rec.columns["x"], ds["x"].values, rtol=1e-9, atol=1e-18)
