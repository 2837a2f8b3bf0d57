"""Figures, drawn from tidy data only (the CSV in figures/data, or a reuse matrix)."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

plt.rcParams.update({"font.size": 11, "axes.titlesize": 12, "axes.grid": True, "grid.alpha": 0.3})
YLABELS = {"frac_opt": "return / oracle optimum", "eval_return": "episode return (evaluation)",
           "eval_success": "win rate"}


def learning_curves(df: pd.DataFrame, order=None, ax=None, title=None, y="frac_opt", ylabel=None):
    """Fig. 3b-d, 4, App. A: mean over seeds (line) and standard deviation (band) of ``y``
    against env steps."""
    ax = ax or plt.subplots(figsize=(6, 4))[1]
    order = order if order is not None else list(dict.fromkeys(df["label"]))
    for label in order:
        g = df[df["label"] == label].groupby("step")[y]
        mean, std = g.mean(), g.std(ddof=0).fillna(0.0)
        line, = ax.plot(mean.index, mean.values, label=str(label))
        ax.fill_between(mean.index, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    if y == "frac_opt":
        ax.axhline(1.0, color="grey", ls="--", lw=1)
    ax.set(xlabel="environment steps", ylabel=ylabel or YLABELS.get(y, y), title=title)
    ax.legend(frameon=False)
    return ax


def final_bars(runs: pd.DataFrame, order=None, ax=None, title=None):
    """Fig. 5b: final fraction of the optimum per label, bars with the std over seeds."""
    ax = ax or plt.subplots(figsize=(5, 4))[1]
    order = order if order is not None else list(dict.fromkeys(runs["label"]))
    g = runs.groupby("label")["final"]
    mean, std = g.mean().reindex(order), g.std(ddof=0).reindex(order).fillna(0.0)
    ax.bar([str(o) for o in order], mean, yerr=std, capsize=4, color="tab:blue", alpha=0.8)
    ax.axhline(1.0, color="grey", ls="--", lw=1)
    ax.set(ylabel="final return / oracle optimum", title=title, ylim=(min(0, mean.min() - 0.1), 1.1))
    return ax


def interval_lines(table: pd.DataFrame, x: pd.Series, labels, metric: str, ax=None, title=None, ylabel=None,
                   colors: dict | None = None):
    """IQM over seeds of ``metric`` ("steps" or "final") with its 95% interval, per curve,
    against a layout parameter ``x`` (indexed by layout). ``table``: ``layout_study.table``;
    ``colors``: label -> colour, so that a curve keeps its colour across panels."""
    ax = ax or plt.subplots(figsize=(5, 4))[1]
    x = x.dropna()
    order = sorted(x.index, key=lambda name: x[name])
    ticks = np.arange(len(order))
    for k, label in enumerate(labels):
        rows = table.xs(label, level="label").reindex(order)
        mid, low, high = (rows[f"{metric}_{c}"].to_numpy(float) for c in ("iqm", "low", "high"))
        shift = (k - (len(labels) - 1) / 2) * 0.08  # side by side, so overlapping intervals stay readable
        ax.errorbar(ticks + shift, mid, yerr=[mid - np.fmin(low, mid), np.fmax(high, mid) - mid], marker="o",
                    capsize=3, label=str(label), color=(colors or {}).get(label))
    ax.set_xticks(ticks, [f"{x[name]:g}" if isinstance(x[name], float) else str(x[name]) for name in order])
    ax.set(title=title, ylabel=ylabel)
    return ax


def reuse_heatmap(m: np.ndarray, ax=None, title=None, names=None):
    """Fig. 2a-c: the reuse matrix, M[i, j] = P(learner i trains on agent j's experience)."""
    ax = ax or plt.subplots(figsize=(3.5, 3.5))[1]
    n = m.shape[0]
    names = names or [f"pi{i + 1}" for i in range(n)]
    ax.imshow(m, cmap="Reds", vmin=0, vmax=1)
    for i in range(n):
        for j in range(n):
            ax.text(j, i, f"{m[i, j]:.2f}", ha="center", va="center",
                    color="white" if m[i, j] > 0.6 else "black", fontsize=9)
    ax.set_xticks(range(n), names)
    ax.set_yticks(range(n), names)
    ax.set(xlabel="experience of agent j", ylabel="learner i", title=title)
    ax.grid(False)
    return ax


def policy_distance(kl_row: np.ndarray, sigma: float, names, learner: int, ax=None, title=None):
    """Fig. 1 (right): other agents placed at their KL distance from the learner.

    Inside the circle of radius sigma their experience is reused (red); outside it is
    omitted (blue). The radial axis is log-scaled (three decades below sigma up to the
    farthest peer) so that both 0.0001 and 10 fit.
    """
    if not 0 < sigma < np.inf:
        raise ValueError(f"sigma must be a positive finite threshold to draw a circle, got {sigma!r}")
    ax = ax or plt.subplots(figsize=(4.5, 4.5))[1]
    floor = sigma / 1000
    radius = lambda d: np.log10(max(d, floor) / floor)  # noqa: E731 -- local scale only
    r_sigma = radius(sigma)
    outer = 1.35 * max(r_sigma, max(radius(d) for d in kl_row))
    ax.add_patch(plt.Circle((0, 0), r_sigma, color="tab:red", alpha=0.12))
    ax.add_patch(plt.Circle((0, 0), outer, color="tab:blue", alpha=0.06, zorder=0))
    ax.add_patch(plt.Circle((0, 0), r_sigma, fill=False, color="tab:red", lw=1.5))
    ax.plot(0, 0, "k*", ms=14)
    ax.annotate(f"{names[learner]} (learner)", (0, 0), xytext=(-8, -4), textcoords="offset points", ha="right", va="top")
    others = [j for j in range(len(names)) if j != learner]
    for k, j in enumerate(others):
        angle = 2 * np.pi * (k + 0.5) / len(others)
        r = radius(kl_row[j])
        inside = kl_row[j] <= sigma
        ax.plot(r * np.cos(angle), r * np.sin(angle), "o", ms=10,
                color="tab:red" if inside else "tab:blue")
        ax.annotate(f"{names[j]}\nKL={kl_row[j]:.3g}", (r * np.cos(angle), r * np.sin(angle)),
                    xytext=(10, 0), textcoords="offset points", va="center")
    ax.set_xlim(-outer, outer)
    ax.set_ylim(-outer, outer)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title or f"reuse radius sigma = {sigma:g} (red: reused, blue: omitted)")
    return ax
