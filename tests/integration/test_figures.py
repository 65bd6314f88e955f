"""The report figures: nothing on the frame, every panel labelled, small laws visible, alt text,
titles that name the overrides, one colour meaning across the machine figures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def report():
    from braidsim.paper.report import compute_report

    return compute_report()


def _outcomes(report, key):
    return [o for o in report.outcomes if o.item.run == key]


def test_fig16_shows_the_initial_peaks_and_labels_every_panel(report) -> None:
    from braidsim.paper.figures import paper_figure

    spec = report.values.runs["3.4a"]
    res = report.results[("3.4a", "calibrated")]
    outs = _outcomes(report, "3.4a")
    fig = paper_figure(res, spec, "stiffness_force", 16, outs)
    axes = [a for a in fig.axes if a.get_title(loc="left")]
    assert [a.get_title(loc="left")[:3] for a in axes] == ["(a)", "(b)", "(c)"]
    assert all(a.get_ylabel() for a in axes)  # (b) and (c) too
    lo, hi = res.ranges_dict("track", res.window_index(0.0, 0.1))["stiffness_force"]
    paper = [o.item.value for o in outs if o.item.quantity == "stiffness_force"]
    for a in axes[:2]:  # whole run and the first impacts: both peaks and the paper's values
        y0, y1 = a.get_ylim()
        assert y0 < min(lo, *paper) and y1 > max(hi, *paper)
        assert a.get_xlim()[0] < 0.0  # the peak at t = 0 is off the frame
    assert axes[1].get_xlim()[1] < 0.05  # a zoom on the first impacts


def test_table1_shows_the_elastic_laws(report) -> None:
    from braidsim.paper.figures import table1_figure
    from braidsim.paper.report import table1_rows

    rows = table1_rows(report)
    fig = table1_figure(rows)
    fig.canvas.draw()
    ax = fig.axes[0]  # contact force
    assert all(a.get_yscale() == "symlog" for a in fig.axes)
    hertz = next(r for r in rows if r["quantity"] == "contact_force" and "Hertz" in r["label"])
    y_zero = ax.transData.transform((0, 0.0))[1]
    y_min = ax.transData.transform((0, float(hertz["ours_min"])))[1]
    height = ax.bbox.height
    assert y_zero - y_min > 0.05 * height  # ~40 N is visibly below zero on a 6 kN axis
    big = max(abs(float(r["ours_min"])) for r in rows if r["quantity"] == "contact_force")
    assert ax.get_ylim()[0] < -big


def test_report_images_have_alt_text(report, tmp_path) -> None:
    from braidsim.paper.report import html_report, markdown_report

    files = ["figures/fig16_F_kg.png", "figures/added_3.3_impacts.png", "figures/table1.png"]
    (tmp_path / "figures").mkdir()
    for f in files:
        (tmp_path / f).write_bytes(b"\x89PNG\r\n")
    report.figures = {"3.4": [files[0]], "3.5": [files[2]], "added": [files[1]]}
    try:
        md = markdown_report(report)
        page = html_report(report, tmp_path)
    finally:
        report.figures = {}
    import re

    alts = re.findall(r"!\[([^\]]*)\]\(figures/", md)
    assert len(alts) == 3 and all(len(a) > 60 for a in alts), alts
    assert "Figure 16 of the paper" in alts[0]
    html_alts = re.findall(r'<img [^>]*alt="([^"]*)"', page)
    assert page.count("data:image/png;base64,") == 3  # embedded: the page stands alone
    assert len(html_alts) == 3 and all(len(a) > 60 for a in html_alts)


def test_lyapunov_title_names_the_overrides(capsys, tmp_path, monkeypatch) -> None:
    from braidsim.analysis import plots
    from braidsim.cli import main

    titles = []
    real = plots.plot_lyapunov

    def spy(est, title=None, **kw):
        titles.append(title)
        return real(est, title, **kw)

    monkeypatch.setattr(plots, "plot_lyapunov", spy)
    argv = ["lyapunov", "paper-3.4b", "--set", "track.clearance=2.5 mm", "--transient-cycles"]
    with pytest.raises(SystemExit) as exc:
        main([*argv, "2", "--cycles", "4", "--out", str(tmp_path / "ly")])
    assert exc.value.code in (0, None), capsys.readouterr().err
    assert titles and "track.clearance" in titles[0] and "2.5" in titles[0]


def test_machine_figures_share_colours_and_start_at_zero() -> None:
    from matplotlib.colors import to_hex

    from braidsim.machine import load_machine_spec, run_machine
    from braidsim.machine.animation import GROUP_COLOURS
    from braidsim.machine.report import distribution_figure, peak_force_figure

    run = run_machine(
        load_machine_spec(ROOT / "examples" / "machine16.toml"),
        duration=0.2,
        workers=1,
        frames=0,
    )
    allowed = {to_hex(c) for c in GROUP_COLOURS.values()}
    fig = peak_force_figure(run)
    for ax in fig.axes:
        colours = {to_hex(line.get_color()) for line in ax.get_lines() if len(line.get_xdata())}
        assert colours and colours <= allowed
        y0, y1 = ax.get_ylim()
        top = max(float(np.max(line.get_ydata())) for line in ax.get_lines())
        assert y0 == 0.0 and y1 > top
    fig2 = distribution_figure(run)
    for ax in fig2.axes:
        y0, y1 = ax.get_ylim()
        assert y0 == 0.0 and y1 > ax.dataLim.y1


def test_paper_report_files_carry_the_version_and_date(report) -> None:
    import braidsim
    from braidsim.paper.report import markdown_report

    data = report.to_json()
    assert data["braidsim_version"] == braidsim.__version__ and data["created"][:2] == "20"
    assert f"braidsim {braidsim.__version__}, 20" in markdown_report(report)


def test_a_far_off_paper_value_does_not_flatten_the_trace(report) -> None:
    """Fig. 21: the paper's F_cg max 338954 N is 40 times ours; it is named, not plotted."""
    from braidsim.paper.figures import paper_figure

    spec = report.values.runs["3.4b"]
    res = report.results[("3.4b", "calibrated")]
    fig = paper_figure(res, spec, "damping_force", 21, _outcomes(report, "3.4b"))
    ax = fig.axes[0]
    assert ax.get_ylim()[1] < 50_000
    assert any("338954" in t.get_text() and "off scale" in t.get_text() for t in ax.texts)


def test_a_run_without_impacts_has_its_figures(tmp_path) -> None:
    """paper-3.1 over 1 ms has no contact at all: the impacts figure's empty panels took
    log ticks on a linear axis from 0, and `braidsim run --out` failed with an internal
    error ("Data cannot be log-scaled")."""
    import braidsim
    from braidsim.plotting import run_figures

    res = braidsim.simulate("paper-3.1", duration=1e-3)
    assert len(res.impacts) == 0
    paths = run_figures(res, tmp_path)
    assert {p.name for p in paths} >= {"impacts.png", "phase.png", "x.png"}
    assert all(p.stat().st_size > 0 for p in paths)
