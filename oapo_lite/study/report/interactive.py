"""Sliders for the notebooks, with a static fallback.

    sliders(draw, sigma=[0.001, 0.01, 0.1, 1.0], reuse_lambda=(0.0, 1.0, 0.05))

In a Jupyter kernel with ipywidgets installed this displays one slider per keyword (each
starting at the first value of its range) and calls ``draw(**values)`` again whenever one
moves: ``ipywidgets.interactive`` with explicit sliders, so the first drawing and the static
fallback agree. Without ipywidgets (a plain kernel, a script, a test) nothing is raised:
``draw`` is called once with the first value of each range.

A range is either a tuple ``(low, high)`` or ``(low, high, step)`` of numbers, a continuous
slider from ``low`` (integer slider if all are integers), as in ``ipywidgets.interact``; or a
list (or 1-d array) of values, a slider that steps through those values in the order given,
starting at the first (``interact`` would make a drop-down of a list).

Executing a widget cell in a batch run (papermill, nbclient) stores the widgets' state in the
notebook and can hang intermittently (github.com/jupyter/nbclient/issues/312), so the notebooks tag a
slider cell ``skip-execution`` (and ``nbval-skip``, ``remove-cell``): it runs only in JupyterLab.
"""
from __future__ import annotations

from numbers import Integral, Real
from typing import Any, Callable

import numpy as np


def _checked(name: str, spec) -> tuple[str, tuple | list]:
    """("range", (low, high, step or None)) or ("values", [v, ...]); ValueError if neither."""
    if isinstance(spec, tuple):
        if len(spec) not in (2, 3) or not all(isinstance(x, Real) and not isinstance(x, bool) for x in spec):
            raise ValueError(f"range {name!r}: a tuple must be (low, high) or (low, high, step) numbers, got {spec!r}")
        low, high, step = (*spec, None) if len(spec) == 2 else spec
        if not low < high or (step is not None and not step > 0):
            raise ValueError(f"range {name!r}: needs low < high and step > 0, got {spec!r}")
        return "range", (low, high, step)
    if isinstance(spec, (list, np.ndarray)):
        if np.ndim(spec) != 1 or len(spec) == 0:
            raise ValueError(f"range {name!r}: a list of values must be non-empty and flat, got {spec!r}")
        return "values", spec.tolist() if isinstance(spec, np.ndarray) else list(spec)
    raise ValueError(f"range {name!r}: give a (low, high[, step]) tuple or a list of values, got {type(spec).__name__}")


def first_values(**ranges) -> dict[str, Any]:
    """The value each slider starts at: ``low`` of a tuple, the first entry of a list."""
    out = {}
    for name, spec in ranges.items():
        _, spec = _checked(name, spec)
        out[name] = spec[0]
    return out


def _labels(values: list) -> list[str]:
    """Short labels (3 significant digits for numbers), more digits where two would read alike."""
    numeric = all(isinstance(v, Real) and not isinstance(v, bool) for v in values)
    for digits in (3, 4, 6, 10, 17):
        labels = [f"{v:.{digits}g}" if numeric else str(v) for v in values]
        if len(set(labels)) == len(labels):
            break
    return labels


def _slider(widgets, name: str, spec):
    kind, spec = _checked(name, spec)
    common = dict(description=name, continuous_update=False)  # redraw on release: figures are slow
    if kind == "values":
        return widgets.SelectionSlider(options=list(zip(_labels(spec), spec)), value=spec[0], **common)
    low, high, step = spec
    if all(isinstance(x, Integral) for x in spec if x is not None):
        return widgets.IntSlider(min=low, max=high, step=step or 1, value=low, **common)
    return widgets.FloatSlider(min=low, max=high, step=step or (high - low) / 100, value=low, **common)


def sliders(draw: Callable[..., Any], **ranges):
    """Display sliders that redraw ``draw(**values)`` and return the ``ipywidgets.interactive``
    widget (its ``children``: one slider per range, then the output area); without ipywidgets,
    call ``draw`` once at the first value of each range and return what it returns."""
    if not ranges:
        raise ValueError("sliders needs at least one range, e.g. sigma=(0.0, 1.0)")
    start = first_values(**ranges)  # validates every range before anything is drawn
    try:
        import ipywidgets as widgets
        from IPython.display import display
    except ImportError:
        return draw(**start)
    panel = widgets.interactive(draw, **{name: _slider(widgets, name, spec) for name, spec in ranges.items()})
    display(panel)
    return panel
