"""The study's plots: one colour per curve in every figure, and no notebook picks its own."""
import pandas as pd
import pytest

from oapo_lite.envs import render
from oapo_lite.study.catalogue import figures
from oapo_lite.study.report import palette, plotting


def test_split_outcomes_are_drawn_by_a_level_some_seed_reached_with_every_seed_on_top():
    import matplotlib.pyplot as plt
    import pandas as pd

    # three seeds trapped at -0.03, two at 0.98: an IQM (0.30) or a mean (0.37) describes no run
    levels = {0: -0.03, 1: -0.03, 2: -0.03, 3: 0.98, 4: 0.98}
    df = pd.DataFrame([dict(label="AR", seed=s, step=t, frac_opt=level * t / 2) for s, level in levels.items()
                       for t in (0, 1, 2)])
    ax = plotting.learning_curves(df, ["AR"])
    bold, *seeds = ax.get_lines()[:6]
    assert list(bold.get_ydata()) == [0.0, -0.015, -0.03]  # the median seed, step by step
    assert all(line.get_zorder() > bold.get_zorder() for line in seeds)
    assert bold.get_color() == palette.color("AR")
    bars = plotting.final_bars(pd.DataFrame(dict(label="AR", seed=list(levels), final=list(levels.values()))))
    assert [b.get_height() for b in bars.patches] == [-0.03]
    even = pd.DataFrame(dict(label="NR", seed=range(4), final=[0.0, 0.0, 1.0, 1.0]))
    assert [b.get_height() for b in plotting.final_bars(even).patches] == [0.0]  # the lower middle run, not 0.5
    plt.close("all")


def test_curves_against_cpu_seconds_put_each_seed_at_its_own_seconds_and_the_median_at_theirs():
    import matplotlib.pyplot as plt
    import pandas as pd

    # three seeds of one curve, the same win rates, at 1, 2 and 4 CPU seconds per evaluation
    df = pd.DataFrame([dict(label="happo", seed=s, step=t, eval_success=t / 2, cpu_s=t * rate)
                       for s, rate in enumerate((1.0, 2.0, 4.0)) for t in (0, 1, 2)])
    ax = plotting.learning_curves(df, y="eval_success", x="cpu_s")
    bold, *seeds = ax.get_lines()[:4]
    assert list(bold.get_xdata()) == [0.0, 2.0, 4.0] and list(bold.get_ydata()) == [0.0, 0.5, 1.0]
    assert [list(line.get_xdata()) for line in seeds] == [[0.0, 1.0, 2.0], [0.0, 2.0, 4.0], [0.0, 4.0, 8.0]]
    assert ax.get_xlabel().startswith("CPU seconds")
    with pytest.raises(ValueError, match="x = 'wall' is invalid"):
        plotting.learning_curves(df, y="eval_success", x="wall")
    plt.close("all")


def _figure_curves(figure) -> list[str]:
    """A grid figure's curves as the figures name them (a sweep's value as "sigma = 0.1")."""
    sweep = {"fig3c": "sigma", "fig3d": "lambda"}.get(figure.id)
    return [f"{sweep} = {label:g}" if sweep else str(label) for label, _ in figure.curves]


def test_two_curves_of_a_figure_never_share_a_colour_and_a_curve_keeps_its_own():
    tuning = ("fig_sweep_2s3z", "fig_a2c_smax", "fig_a2c_2s3z")  # drawn as tables, a row per setting
    for figure in (f for f in figures.GRID if f.id not in tuning):
        names = list(dict.fromkeys(_figure_curves(figure)))
        colours = [palette.color(n) for n in names]  # every curve has one: a missing one raises
        assert len(set(colours)) == len(colours), (figure.id, names, colours)
    # the paper's sigma and lambda are OAPPO itself; every other colour is one curve's, and none an agent's
    shared = {c for c in palette.PALETTE.values() if list(palette.PALETTE.values()).count(c) > 1}
    assert shared == {palette.OAPPO}
    assert {k for k, c in palette.PALETTE.items() if c == palette.OAPPO} == {"oappo", "sigma = 0.1", "lambda = 0.7"}
    assert not set(palette.PALETTE.values()) & set(render.AGENT_COLOURS.values())
    # no curve is red, blue or black, the mazes' agents' colours, which the rule tells apart
    assert {name: palette.forbidden(c) for name, c in render.AGENT_COLOURS.items()} == \
        {"red": "red", "black": "black", "blue": "blue"}
    assert {name: c for name, c in palette.PALETTE.items() if palette.forbidden(c)} == {}
    with pytest.raises(ValueError, match="no colour for the curve 'a new curve'; add it to"):
        palette.color("a new curve")


def test_every_status_has_its_own_colour_in_the_count_figure_and_the_bars_add_up():
    from oapo_lite.study.judge.records import Status

    assert set(palette.STATUS) == {s.value for s in Status}
    assert len(set(palette.STATUS.values())) == len(palette.STATUS)
    assert {s: c for s, c in palette.STATUS.items() if palette.forbidden(c)} == {}
    counts = pd.DataFrame({"reproduced": [2, 0], "not run": [1, 3], "resting on one seed": [1, 0]}, index=["6.1", "6.3"])
    ax = plotting.verdict_counts(counts)
    widths = {}
    for bar in ax.patches:  # one bar per section and status, stacked left to right
        widths[bar.get_y()] = widths.get(bar.get_y(), 0) + bar.get_width()
    assert sorted(widths.values()) == [3, 3]  # "resting on one seed" is no status: not drawn
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["reproduced", "not run"]


def test_a_dose_response_draws_each_curve_in_its_colour_and_the_open_share_as_bars():
    import matplotlib.colors as mcolors
    import numpy as np

    labels = ["happo", "oappo sigma=0.035", "oappo always"]
    dose = pd.DataFrame({"label": labels, "sigma": [0.0, 0.035, np.inf], "open": [np.nan, 0.25, 1.0],
                         "final": [0.9, 0.95, 0.96], "final_low": [0.8, 0.9, 0.94], "final_high": [0.95, 0.97, 0.97],
                         "steps": [5e5, 4e5, 4.2e5], "steps_low": [4e5, 3e5, 4e5], "steps_high": [6e5, 5e5, 5e5]})
    fig = plotting.dose_response(dose, "2s3z", "final win rate", "env steps to 80%")
    final, steps, share = fig.axes
    points = final.collections[-1]
    assert [mcolors.to_hex(c) for c in points.get_facecolors()] == [palette.color(label) for label in labels]
    assert np.allclose(points.get_offsets()[:, 1], dose["final"])
    assert [b.get_height() for b in share.patches] == [0.0, 0.25, 1.0]  # no reuse: a gate never open
    assert [t.get_text() for t in share.get_xticklabels()] == ["never", "0.035", "always"]


def test_no_notebook_picks_a_colour_of_its_own():
    """Inline plots take every curve's colour from the palette: no colour map or colour cycle of
    matplotlib's, no literal colour."""
    import re

    import nbformat

    from oapo_lite.study.runs.reproduce import NOTEBOOKS

    own = re.compile(r"plt\.cm\.|color=\"#|color=\"(tab|C)\d|ALGO_COLORS|sweep_colors")  # an image may take a cmap
    for path in sorted(NOTEBOOKS.glob("[0-9]*.ipynb")):
        for cell in nbformat.read(path, as_version=4).cells:
            if cell.cell_type == "code":
                assert not own.search(cell.source), (path.name, own.search(cell.source).group())


def test_no_notebook_draws_a_line_in_a_default_colour():
    """Every line, bar, dot or band a notebook draws names its colour (the palette's, an agent's, or a
    grey): matplotlib's colour cycle would give two figures' curves colours that mean nothing."""
    import ast

    import nbformat

    from oapo_lite.study.runs.reproduce import NOTEBOOKS

    drawn = {"plot", "bar", "barh", "scatter", "errorbar", "fill_between", "hist", "stackplot"}
    bare = []
    for path in sorted(NOTEBOOKS.glob("[0-9]*.ipynb")):
        for k, cell in enumerate(nbformat.read(path, as_version=4).cells):
            if cell.cell_type != "code":
                continue
            code = "\n".join(line for line in cell.source.splitlines() if not line.lstrip().startswith(("%", "!")))
            for node in ast.walk(ast.parse(code)):
                if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in drawn
                        and not {kw.arg for kw in node.keywords} & {"color", "c", "colors"}):
                    bare.append(f"{path.name}, cell {k}: {ast.unparse(node)[:80]}")
    assert not bare, bare
