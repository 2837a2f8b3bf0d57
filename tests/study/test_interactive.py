"""oapo_lite.study.report.interactive: sliders with ipywidgets, one static drawing without it."""
import json
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from oapo_lite.study.report import interactive

NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"
RANGES = dict(sigma=[0.01, 0.1, 1.0, 10.0], reuse_lambda=(0.2, 1.0, 0.1), n=(1, 5))
FIRST = dict(sigma=0.01, reuse_lambda=0.2, n=1)


def recorder():
    calls = []

    def draw(**values):
        calls.append(values)
        return "drawn"

    return draw, calls


def test_fallback_draws_once_at_the_first_values(monkeypatch):
    monkeypatch.setitem(sys.modules, "ipywidgets", None)  # `import ipywidgets` now raises ImportError
    draw, calls = recorder()
    assert interactive.sliders(draw, **RANGES) == "drawn"
    assert calls == [FIRST]


def test_fallback_accepts_an_array_of_values(monkeypatch):
    monkeypatch.setitem(sys.modules, "ipywidgets", None)
    draw, calls = recorder()
    interactive.sliders(draw, sigma=np.logspace(-2, 1, 4))
    assert calls == [{"sigma": pytest.approx(0.01)}]


def test_with_ipywidgets_one_slider_per_range():
    widgets = pytest.importorskip("ipywidgets")
    draw, calls = recorder()
    panel = interactive.sliders(draw, **RANGES)
    controls = [c for c in panel.children if isinstance(c, widgets.widgets.ValueWidget)]
    assert [c.description for c in controls] == list(RANGES)
    assert all(type(c).__name__.endswith("Slider") for c in controls)
    assert isinstance(controls[0], widgets.SelectionSlider) and list(controls[0].options) == [
        ("0.01", 0.01), ("0.1", 0.1), ("1", 1.0), ("10", 10.0)]
    assert isinstance(controls[1], widgets.FloatSlider) and (controls[1].min, controls[1].max) == (0.2, 1.0)
    assert isinstance(controls[2], widgets.IntSlider)
    # the first drawing is the fallback's; moving a slider redraws with the new value
    assert calls == [FIRST]
    controls[0].value = 1.0
    assert calls[-1] == dict(FIRST, sigma=1.0)


@pytest.mark.parametrize("bad", [(1.0,), (1.0, 0.5), (0.0, 1.0, 0.0), [], "0.1", ("a", "b")])
def test_bad_ranges_are_refused_before_drawing(bad, monkeypatch):
    monkeypatch.setitem(sys.modules, "ipywidgets", None)
    draw, calls = recorder()
    with pytest.raises(ValueError, match="range 'sigma'"):
        interactive.sliders(draw, sigma=bad)
    assert calls == []


def test_no_ranges_is_refused():
    with pytest.raises(ValueError, match="at least one range"):
        interactive.sliders(lambda: None)


def test_close_values_get_distinct_labels():
    widgets = pytest.importorskip("ipywidgets")
    panel = interactive.sliders(lambda sigma: None, sigma=[0.0085, 0.00851, 0.1])
    slider = next(c for c in panel.children if isinstance(c, widgets.SelectionSlider))
    assert [label for label, _ in slider.options] == ["0.0085", "0.00851", "0.1"]


def test_committed_notebooks_carry_no_widget_state():
    """Executing a slider cell makes nbclient store the widgets' state in the notebook's metadata;
    MyST-NB would then load widget JavaScript from a CDN on that page of the (offline) book."""
    notebooks = sorted(NOTEBOOKS.glob("[0-9][0-9]_*.ipynb"))
    assert notebooks
    stored = [p.name for p in notebooks if "widgets" in json.loads(p.read_text())["metadata"]]
    assert not stored, f"drop metadata['widgets'] from {stored} after executing them"


def test_notebook_05_slider_cell_draws_statically(monkeypatch):
    """Batch runs (papermill, nbval) skip the slider cell of notebook 05, so it is run here, with
    the static fallback, on a K like the one the notebook measures."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from oapo_lite import reuse
    from oapo_lite.study.report.plotting import reuse_heatmap

    nb = json.loads((NOTEBOOKS / "05_oatrpo_oappo_eq7_9.ipynb").read_text())
    cells = [c for c in nb["cells"] if "interactive.sliders(" in "".join(c["source"])]
    assert len(cells) == 1 and {"skip-execution", "nbval-skip", "remove-cell"} <= set(cells[0]["metadata"]["tags"])
    monkeypatch.setitem(sys.modules, "ipywidgets", None)
    K3 = np.array([[0, 1.0912, 1.0655], [1.2689, 0, 0.0085], [1.2955, 0.0084, 0]])
    namespace = dict(np=np, plt=plt, reuse=reuse, reuse_heatmap=reuse_heatmap, names=["red", "black", "blue"],
                     K3=K3, cfg=SimpleNamespace(steps=48_000), cfg3=SimpleNamespace(seed=0))
    plt.close("all")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*non-interactive.*")  # plt.show() under Agg
        exec(compile("".join(cells[0]["source"]), "notebook 05, slider cell", "exec"), namespace)
    figures = [plt.figure(n) for n in plt.get_fignums()]
    assert len(figures) == 1  # one static drawing, at the first sigma and lambda
    assert figures[0].axes[0].get_title() == "M for sigma = 0.001, lambda = 0.00"
    assert 0.0084 in namespace["sigma_values"]  # the measured distances are among the slider's values
    plt.close("all")
