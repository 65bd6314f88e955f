"""Pieces behind `braidsim paper`: plot thinning, whole-or-nothing directories, comparisons."""

from __future__ import annotations

import os
import shutil
import stat

import numpy as np
import pytest

from braidsim.errors import InputError
from braidsim.io import MARKER, atomic_directory, check_output_directory
from braidsim.paper.compute import compare
from braidsim.paper.findings import damping_ratio, fmt
from braidsim.paper.values import PaperItem
from braidsim.plotting import envelope


def test_envelope_keeps_every_extreme_and_thins():
    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0.0, 1.0, 200_000))
    y = rng.normal(size=t.size)
    y[123_456] = 40.0  # a single-sample spike (a 0.1 ms contact peak)
    te, ye = envelope(t, y, bins=500)
    assert te.size <= 2 * 500 + 2
    assert ye.max() == 40.0 and ye.min() == y.min()
    assert np.all(np.diff(te) >= 0)  # still in time order
    # every bin keeps its own min and max
    b = np.minimum((t * 500).astype(int), 499)
    be = np.minimum((te * 500).astype(int), 499)
    for k in (0, 17, 250, 499):
        assert ye[be == k].max() == y[b == k].max()
        assert ye[be == k].min() == y[b == k].min()
    short = np.arange(10.0)
    assert envelope(short, short, bins=500)[0] is short


def test_atomic_directory_is_whole_or_absent(tmp_path):
    out = tmp_path / "res"
    with pytest.raises(RuntimeError), atomic_directory(out, "paper report") as tmp:
        (tmp / "half.txt").write_text("half")
        raise RuntimeError("interrupted")
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary left behind
    with atomic_directory(out, "paper report") as tmp:
        (tmp / "a.txt").write_text("1")
    assert (out / "a.txt").read_text() == "1"
    assert (out / MARKER).read_text().splitlines()[0] == "paper report"
    mode = stat.S_IMODE(os.stat(out).st_mode)
    assert mode & 0o055 == 0o055 & ~_umask()  # readable like an ordinary directory
    # an earlier output of the same kind is replaced as a whole
    with atomic_directory(out, "paper report") as tmp:
        (tmp / "b.txt").write_text("2")
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, "b.txt"])
    # a failure during the replacement leaves the earlier output intact
    with pytest.raises(RuntimeError), atomic_directory(out, "paper report") as tmp:
        raise RuntimeError("x")
    assert (out / "b.txt").read_text() == "2"


def test_an_earlier_output_holding_the_users_files_is_not_replaced(tmp_path):
    """A re-run deleted what the user had put in an earlier output (``notes.txt``, another
    command's --out inside it): it is refused, naming the first such path, and the folder
    is left as it was; an output holding only what braidsim wrote is replaced whole."""
    out = tmp_path / "res"
    with atomic_directory(out, "paper report") as tmp:
        (tmp / "plots").mkdir()
        (tmp / "plots" / "a.png").write_text("1")
        (tmp / "b.txt").write_text("2")
    for mine in (out / "notes.txt", out / "plots" / "mine.png", out / "run-folder"):
        if mine.name == "run-folder":
            with atomic_directory(mine, "run") as tmp:  # another command's output in it
                (tmp / "summary.json").write_text("{}")
        else:
            mine.write_text("mine")
        with pytest.raises(InputError, match=f"but {str(mine)!r} in it was not written"):
            check_output_directory(out, "paper report")
        with (
            pytest.raises(InputError, match="choose another --out"),
            atomic_directory(out, "paper report") as tmp,
        ):
            (tmp / "c.txt").write_text("3")
        assert mine.exists() and (out / "b.txt").exists() and not (out / "c.txt").exists()
        if mine.is_dir():
            shutil.rmtree(mine)
        else:
            mine.unlink()
    # a hidden temporary left by a killed braidsim is braidsim's own
    (out / ".b.txt.braidsim-999999999-x.json").write_text("half")
    with atomic_directory(out, "paper report") as tmp:
        (tmp / "c.txt").write_text("3")
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, "c.txt"])


def test_an_earlier_output_whose_marker_lists_nothing_is_replaced_as_before(tmp_path):
    """An output of a braidsim whose marker held its kind only stays replaceable whole."""
    out = tmp_path / "res"
    out.mkdir()
    (out / MARKER).write_text("paper report\n")
    (out / "anything.txt").write_text("x")
    with atomic_directory(out, "paper report") as tmp:
        (tmp / "a.txt").write_text("1")
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, "a.txt"])


def _umask() -> int:
    m = os.umask(0o022)
    os.umask(m)
    return m


def test_foreign_directories_are_refused(tmp_path):
    d = tmp_path / "thesis"
    d.mkdir()
    (d / "chapter1.tex").write_text("x")
    with pytest.raises(InputError, match="--out"):
        check_output_directory(d, "paper report")
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(InputError, match="not a directory"):
        check_output_directory(f, "paper report")
    (tmp_path / "empty").mkdir()
    check_output_directory(tmp_path / "empty", "paper report")
    # another kind of braidsim output is not ours to replace either
    other = tmp_path / "sweep"
    other.mkdir()
    (other / MARKER).write_text("sweep store\n")
    with pytest.raises(InputError):
        check_output_directory(other, "paper report")


def _item(
    value: float, unit: str = "N", tol: float = 0.05, abs_tol: float | None = None
) -> PaperItem:
    return PaperItem(
        "x",
        "3.1",
        "Fig. 4",
        "stiffness_force" if unit == "N" else "depth",
        "min",
        value,
        unit,
        "3.1",
        "initially",
        "",
        tol,
        abs_tol,
    )


def test_compare_relative_absolute_and_units():
    c = compare(_item(-4864.4), -4895.12)
    assert c.deviation == pytest.approx(-4895.12 / -4864.4 - 1.0) and c.within
    assert not compare(_item(-1511.5), -1675.2).within
    # the paper's mm against our metres
    c = compare(_item(-3.37e-2, "mm"), -3.3807e-5)
    assert c.deviation == pytest.approx(0.0031750742, rel=1e-6) and c.within
    # a printed zero is compared absolutely
    z = compare(_item(0.0, abs_tol=0.05), -0.04)
    assert z.deviation is None and z.within
    assert not compare(_item(0.0, abs_tol=0.05), 0.06).within


def test_number_format_and_ratio():
    assert fmt(-4864.4, 6) == "-4864.4"
    assert fmt(161590.4) == "161590"
    assert fmt(-7.6452e-7 * 1e3) == "-7.6452e-4"
    assert fmt(2.4903636e10) == "2.4904e10"
    assert fmt(-0.0) == "0"
    assert fmt(9.99999e-4, 3) == "1e-3"
    assert damping_ratio((-1441.2, 1448.8), (-4864.4, 4921.4)) == pytest.approx(1448.8 / 4921.4)
