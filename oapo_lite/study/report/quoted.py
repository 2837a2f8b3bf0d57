"""How a notebook checks the numbers its text quotes.

    quoted.check("K (max over the batch)", K, [[0, 0.0263], [0.0817, 0]], rtol=0.01)

prints ``as quoted: K (max over the batch) [[0.0, 0.0263], [0.0817, 0.0]] (to 1% relative): True``.
It returns nothing, so that a notebook cell ending with it shows that line alone (nbval runs cells
without IPython's history, where a trailing ``;`` does not hide a cell's value). A committed
notebook whose output says ``False`` there carries a wrong sentence; ``failed`` finds such lines,
and a test runs it over every committed notebook.

A check's tolerance covers the rounding of the quoted digits and must exceed, ten times over,
how far the value moves across numeric paths (ASSUMPTIONS.md, "Across machines"): nbval
compares the printed boolean on any CPU.
"""
from __future__ import annotations

import numpy as np

PREFIX = "as quoted:"


def check(what: str, value, quoted, rtol: float, atol: float = 0.0) -> None:
    """Print whether ``value`` is ``quoted`` in every entry, to ``rtol`` of the quoted number
    plus ``atol`` (numpy's ``allclose``)."""
    value, quoted = np.asarray(value, dtype=float), np.asarray(quoted, dtype=float)
    if value.shape != quoted.shape:
        raise ValueError(f"{what}: the value has shape {value.shape}, the quoted numbers {quoted.shape}")
    ok = bool(np.allclose(value, quoted, rtol=rtol, atol=atol))
    within = " + ".join(t for t in (f"{100 * rtol:g}% relative" if rtol else "", f"{atol:g}" if atol else "") if t)
    print(f"{PREFIX} {what} {quoted.tolist()} (to {within or 'the last bit'}): {ok}")


def failed(lines) -> list[str]:
    """The lines that report a quoted check which did not hold."""
    return [line for line in lines if line.startswith(PREFIX) and not line.rstrip().endswith("True")]
