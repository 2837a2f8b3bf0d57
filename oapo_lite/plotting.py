"""Figures, drawn from tidy data only (the CSV in figures/data, or a reuse matrix)."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

plt.rcParams.update({"font.size": 11, "axes.titlesize": 12, "axes.grid": True, "grid.alpha": 0.3})
YLABELS = {"frac_opt": "return / oracle optimum (below 0: step costs exceed arrival rewards)",
           "eval_return": "episode return (evaluation)", "eval_success": "win rate"}
# One colour per algorithm and per agent in every figure. The agents are named after their
# colours, so no algorithm is red, black or blue, and Fig. 1's reused / omitted are neither.
ALGO_COLORS = {"oappo": "#2ca02c", "oatrpo": "#9467bd", "mappo": "#ff7f0e", "happo": "#8c564b",
               "hatrpo": "#e377c2", "ippo": "#7f7f7f", "seac": "#bcbd22", "seps": "#17becf",
               "oappo adaptive": "#145214"}
AGENT_COLORS = {"red": "#d62728", "black": "#000000", "blue": "#1f77b4"}
REUSED, OMITTED = "#e6a100", "#9a9a9a"


def color_of(label, order=None):
    """The colour of a curve: its algorithm's (the label, or its first word, any case: "OAPPO",
    "oappo lambda=0.4"; the adaptive rule has its own), else the label's place in ``order`` on a
    sequential map (a sigma, a lambda, a reuse scheme), else None (matplotlib's next colour)."""
    name = str(label).lower()
    for key in (name, name.split()[0] if name.strip() else ""):
        if key in ALGO_COLORS:
            return ALGO_COLORS[key]
    if order is not None and label in list(order):
        k, n = list(order).index(label), len(order)
        return plt.cm.viridis(0.1 + 0.75 * k / max(n - 1, 1))
    return None


def learning_curves(df: pd.DataFrame, order=None, ax=None, title=None, y="frac_opt", ylabel=None,
                    colors: dict | None = None):
    """Fig. 3b-d, 4, App. A: every seed as a thin line and the interquartile mean over seeds
    (bold) of ``y`` against env steps. Per-seed lines rather than mean +- std: outcomes that
    split into trapped and optimal seeds have a mean that describes no run and a band that
    leaves the possible range. The title gets a line saying so. ``colors``: label -> colour,
    where a figure needs its own (else ``color_of``)."""
    from oapo_lite.verdicts import iqm

    ax = ax or plt.subplots(figsize=(6, 4))[1]
    order = order if order is not None else list(dict.fromkeys(df["label"]))
    for label in order:
        runs = df[df["label"] == label].pivot_table(index="step", columns="seed", values=y)
        color = (colors or {}).get(label) or color_of(label, order)
        line, = ax.plot(runs.index, iqm(runs.to_numpy(float), axis=1), lw=2.2, label=str(label), color=color)
        ax.plot(runs.index, runs.to_numpy(float), lw=0.6, alpha=0.35, color=line.get_color())
    if y == "frac_opt":
        ax.axhline(1.0, color="grey", ls="--", lw=1)
    seeds = df.groupby("label")["seed"].nunique()
    note = f"bold: IQM over {'/'.join(map(str, sorted(set(seeds))))} seeds; thin: each seed"
    ax.set(xlabel="environment steps", ylabel=ylabel or YLABELS.get(y, y),
           title=f"{title}\n{note}" if title else note)
    ax.legend(frameon=False)
    return ax


def final_bars(runs: pd.DataFrame, order=None, ax=None, title=None):
    """Fig. 5b: final fraction of the optimum per label: the IQM over seeds as a bar, every seed
    as a dot (trapped and optimal seeds stay visible; no std band beyond the optimum)."""
    from oapo_lite.verdicts import iqm

    ax = ax or plt.subplots(figsize=(5, 4))[1]
    order = order if order is not None else list(dict.fromkeys(runs["label"]))
    finals = [runs.loc[runs["label"] == o, "final"].to_numpy(float) for o in order]
    colors = [color_of(o, order) for o in order]
    ax.bar([str(o) for o in order], [iqm(f) for f in finals], color=colors, alpha=0.6)
    for k, f in enumerate(finals):
        ax.plot(np.full(len(f), k) + np.linspace(-0.15, 0.15, len(f)), f, "o", ms=4, color="black")
    ax.axhline(1.0, color="grey", ls="--", lw=1)
    low = min(0.0, min(f.min() for f in finals) - 0.1)
    note = f"bar: IQM over seeds; dots: each of {max(len(f) for f in finals)} seeds"
    ax.set(ylabel="final return / oracle optimum", title=f"{title}\n{note}" if title else note, ylim=(low, 1.1))
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
                    capsize=3, label=str(label), color=(colors or {}).get(label) or color_of(label))
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

    Inside the circle of radius sigma their experience is reused (amber); outside it is
    omitted (grey): colours that are no agent's name. The radial axis is log-scaled (three decades below sigma up to the
    farthest peer) so that both 0.0001 and 10 fit.
    """
    if not 0 < sigma < np.inf:
        raise ValueError(f"sigma must be a positive finite threshold to draw a circle, got {sigma!r}")
    ax = ax or plt.subplots(figsize=(4.5, 4.5))[1]
    floor = sigma / 1000
    radius = lambda d: np.log10(max(d, floor) / floor)  # noqa: E731 -- local scale only
    r_sigma = radius(sigma)
    outer = 1.35 * max(r_sigma, max(radius(d) for d in kl_row))
    ax.add_patch(plt.Circle((0, 0), r_sigma, color=REUSED, alpha=0.15))
    ax.add_patch(plt.Circle((0, 0), outer, color=OMITTED, alpha=0.08, zorder=0))
    ax.add_patch(plt.Circle((0, 0), r_sigma, fill=False, color=REUSED, lw=1.5))
    ax.plot(0, 0, "k*", ms=14)
    ax.annotate(f"{names[learner]} (learner)", (0, 0), xytext=(-8, -4), textcoords="offset points", ha="right", va="top")
    others = [j for j in range(len(names)) if j != learner]
    for k, j in enumerate(others):
        angle = 2 * np.pi * (k + 0.5) / len(others)
        r = radius(kl_row[j])
        inside = kl_row[j] <= sigma
        ax.plot(r * np.cos(angle), r * np.sin(angle), "o", ms=12, color=AGENT_COLORS.get(names[j], "grey"),
                markeredgecolor=REUSED if inside else OMITTED, markeredgewidth=3)
        ax.annotate(f"{names[j]}\nKL={kl_row[j]:.3g}", (r * np.cos(angle), r * np.sin(angle)),
                    xytext=(10, 0), textcoords="offset points", va="center")
    ax.set_xlim(-outer, outer)
    ax.set_ylim(-outer, outer)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title or f"reuse radius sigma = {sigma:g} (amber: reused, grey: omitted)")
    return ax
