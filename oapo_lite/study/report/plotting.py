"""Figures, drawn from tidy data only (the CSV in figures/data, or a reuse matrix)."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.ticker import FuncFormatter

from oapo_lite.study.report import palette
from oapo_lite.envs.render import AGENT_COLOURS
from oapo_lite.study.report.palette import OMITTED, REUSED

plt.rcParams.update({"font.size": 11, "axes.titlesize": 12, "axes.grid": True, "grid.alpha": 0.3})
YLABELS = {"frac_opt": "return / oracle optimum (below 0: step costs exceed arrival rewards)",
           "eval_return": "episode return (evaluation)", "eval_success": "win rate",
           "peer_share": "peer share: weight on other agents' experience"}
# env steps in thousands or millions, never matplotlib's "1e6" offset
STEPS = FuncFormatter(lambda x, _: f"{x / 1e6:g}M" if abs(x) >= 1e6 else f"{x / 1e3:g}k" if x else "0")


def learning_curves(df: pd.DataFrame, order=None, ax=None, title=None, y="frac_opt", ylabel=None,
                    legend: dict | None = None, x: str = "step"):
    """Fig. 3b-d, 4, App. A: every seed as a thin line (on top) and, bold, the median over seeds
    of ``y`` against env steps (the lower middle seed where the count is even, so at every step
    a level some seed reached). Not mean +- std, nor an IQM: outcomes that split into trapped
    and optimal seeds have a mean that describes no run and a band that leaves the possible
    range. The title gets a line saying so. Each curve in its colour (``palette.color``), named
    in the legend by ``legend[label]`` where given (e.g. with its seed count). ``x="cpu_s"`` draws
    them against the CPU seconds each run had spent by its own records (a seed's line at its own
    seconds, the bold one at the median seconds of each evaluation): learning per unit of compute."""
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"the runs must be a pandas DataFrame (e.g. experiments.load_figure's), got {type(df).__name__}")
    ax = ax or plt.subplots(figsize=(6, 4))[1]
    if df.empty:  # e.g. load_figure(..., skip_missing=True) with nothing on disk
        return _no_runs(ax, title)
    if x not in ("step", "cpu_s"):
        raise ValueError(f"x = {x!r} is invalid; allowed: 'step' (env steps) or 'cpu_s' (CPU seconds)")
    lacking = [c for c in ("label", "seed", "step", y, x) if c not in df]
    if lacking:
        raise ValueError(f"the runs lack the columns {lacking}; they need label, seed, step, {y!r} and {x!r}")
    if not pd.api.types.is_numeric_dtype(df[y]):
        raise ValueError(f"the runs' {y!r} column holds text (e.g. {df[y].iloc[0]!r}); allowed: numbers")
    twice = df[df.duplicated(["label", "seed", "step"])]
    if len(twice):
        raise ValueError(f"curve {twice['label'].iloc[0]!r} has two rows for seed {twice['seed'].iloc[0]} at step "
                         f"{twice['step'].iloc[0]}; a run has one row per evaluation")
    order = order if order is not None else list(dict.fromkeys(df["label"]))
    unknown = [label for label in order if label not in set(df["label"])]
    if unknown:
        raise ValueError(f"no runs of the curves {unknown} to draw; the data's curves are {list(dict.fromkeys(df['label']))}")
    seeds_of = {}
    for label in order:  # the bold medians first, every curve's seeds on top: no seed hides under another curve
        runs = df[df["label"] == label].pivot(index="step", columns="seed", values=y)
        if runs.isna().all().all():
            raise ValueError(f"curve {label!r} has no value of {y!r} to draw (every evaluation is empty)")
        at = (df[df["label"] == label].pivot(index="step", columns="seed", values=x) if x != "step"
              else pd.DataFrame(np.repeat(runs.index.to_numpy()[:, None], runs.shape[1], 1), index=runs.index))
        color = palette.color(label)
        median = np.quantile(runs.to_numpy(float), 0.5, axis=1, method="lower")
        line, = ax.plot(np.nanmedian(at.to_numpy(float), axis=1), median, lw=2.2,
                        label=str((legend or {}).get(label, label)), color=color, zorder=2, ls=palette.dashes(label))
        seeds_of[label] = (at, runs, line.get_color())
    for label, (at, runs, color) in seeds_of.items():
        ax.plot(at.to_numpy(float), runs.to_numpy(float), lw=0.8, alpha=0.5, color=color, zorder=3,
                ls=palette.dashes(label))
    if x == "step":
        ax.xaxis.set_major_formatter(STEPS)
    if y == "frac_opt":
        ax.axhline(1.0, color="grey", ls="--", lw=1)
    seeds = df.groupby("label")["seed"].nunique()
    note = f"bold: the median of {'/'.join(map(str, sorted(set(seeds))))} seeds; thin: each seed"
    ax.set(xlabel="environment steps" if x == "step" else "CPU seconds (each run's own records)",
           ylabel=ylabel or YLABELS.get(y, y), title=f"{title}\n{note}" if title else note)
    ax.legend(frameon=False)
    return ax


def final_bars(runs: pd.DataFrame, order=None, ax=None, title=None):
    """Fig. 5b: final fraction of the optimum per label: every seed as a dot, and the median run's
    level as a bar (the lower middle run where the count is even: a level some run reached; a
    mean or IQM of trapped and optimal seeds describes no run)."""
    ax = ax or plt.subplots(figsize=(5, 4))[1]
    if runs.empty:
        return _no_runs(ax, title)
    order = order if order is not None else list(dict.fromkeys(runs["label"]))
    finals = [runs.loc[runs["label"] == o, "final"].to_numpy(float) for o in order]
    colors = [palette.color(o) for o in order]
    ax.bar([str(o) for o in order], [np.quantile(f, 0.5, method="lower") for f in finals], color=colors, alpha=0.5)
    for k, f in enumerate(finals):
        ax.plot(np.full(len(f), k) + np.linspace(-0.15, 0.15, len(f)), f, "o", ms=4, color="black")
    ax.axhline(1.0, color="grey", ls="--", lw=1)
    low = min(0.0, min(f.min() for f in finals) - 0.1)
    note = f"bar: the median run; dots: each of {max(len(f) for f in finals)} seeds"
    ax.set(ylabel="final return / oracle optimum", title=f"{title}\n{note}" if title else note, ylim=(low, 1.1))
    return ax


def interval_lines(table: pd.DataFrame, x: pd.Series, labels, metric: str, ax=None, title=None, ylabel=None):
    """IQM over seeds of ``metric`` ("steps" or "final") with its 95% interval, per curve,
    against a layout parameter ``x`` (indexed by layout). ``table``: ``layout_study.table``."""
    ax = ax or plt.subplots(figsize=(5, 4))[1]
    x = x.dropna()
    order = sorted(x.index, key=lambda name: x[name])
    ticks = np.arange(len(order))
    for k, label in enumerate(labels):
        rows = table.xs(label, level="label").reindex(order)
        mid, low, high = (rows[f"{metric}_{c}"].to_numpy(float) for c in ("iqm", "low", "high"))
        shift = (k - (len(labels) - 1) / 2) * 0.08  # side by side, so overlapping intervals stay readable
        ax.errorbar(ticks + shift, mid, yerr=[mid - np.fmin(low, mid), np.fmax(high, mid) - mid], marker="o",
                    capsize=3, label=str(label), color=palette.color(label))
    ax.set_xticks(ticks, [f"{x[name]:g}" if isinstance(x[name], float) else str(x[name]) for name in order])
    ax.set(title=title, ylabel=ylabel)
    return ax


def across_shares(df: pd.DataFrame, order=None, ax=None, title=None):
    """Beside a figure's curves: per curve, the median over seeds of ``across_share`` (M's weight
    on the seats of other networks: the reuse Eq. 9's gate decided) against env steps, with a key
    (a sampled curve dashed over its weights twin). A curve that never reuses across networks lies at 0."""
    ax = ax or plt.subplots(figsize=(6, 3))[1]
    df = df[df["across_share"].notna()] if "across_share" in df else df.iloc[:0]
    if df.empty:
        return _no_runs(ax, title)
    order = order if order is not None else list(dict.fromkeys(df["label"]))
    for label in order:
        runs = df[df["label"] == label].pivot_table(index="step", columns="seed", values="across_share")
        ax.plot(runs.index, np.quantile(runs.to_numpy(float), 0.5, axis=1, method="lower"), lw=2, label=str(label),
                color=palette.color(label), ls=palette.dashes(label))
    ax.xaxis.set_major_formatter(STEPS)
    ax.set(xlabel="environment steps", ylabel="weight on other\nnetworks' seats", ylim=(-0.02, None),
           title=title or "reuse across networks (median over seeds)")
    # below the panel: a gate that never shut draws a line along the top for the whole run
    ax.legend(frameon=False, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=min(len(order), 3))
    return ax


def gate_strips(kl: pd.DataFrame, owner: list[int], sigma: float, names, ax=None, title=None):
    """When Eq. 9's gate was open, per ordered pair of seats on different networks (learner <-
    source): one strip over the evaluated env steps, its shade the share of seeds whose K[i, j]
    was within ``sigma``. ``kl``: rows with ``seed``, ``step`` and ``kl_matrix`` (one curve)."""
    ax = ax or plt.subplots(figsize=(7, 3))[1]
    kl = kl[kl["kl_matrix"].notna()]
    pairs = [(i, j) for i in range(len(owner)) for j in range(len(owner)) if owner[i] != owner[j]]
    if kl.empty or not pairs:
        return _no_runs(ax, title)
    steps = np.sort(kl["step"].unique())
    open_share = np.zeros((len(pairs), len(steps)))
    for c, step in enumerate(steps):
        ks = np.stack(kl.loc[kl["step"] == step, "kl_matrix"].to_list())  # (seeds, n, n)
        open_share[:, c] = [(ks[:, i, j] <= sigma).mean() for i, j in pairs]
    width = steps[1] - steps[0] if len(steps) > 1 else 1.0
    image = ax.imshow(open_share, aspect="auto", cmap="Greens", vmin=0, vmax=1, interpolation="nearest",
                      extent=(steps[0] - width / 2, steps[-1] + width / 2, len(pairs) - 0.5, -0.5))
    ax.figure.colorbar(image, ax=ax, label=f"share of seeds with K <= {sigma:g}", fraction=0.05)
    ax.set_yticks(range(len(pairs)), [f"{names[i]} <- {names[j]}" for i, j in pairs], fontsize=7)
    ax.xaxis.set_major_formatter(STEPS)
    ax.grid(False)
    ax.set(xlabel="environment steps", title=title or f"gate open (K <= sigma = {sigma:g}): share of seeds, dark = all")
    return ax


def dose_response(dose: pd.DataFrame, where: str, final: str, speed: str):
    """A dose-response over sigma (``selection.dose``'s table), from no reuse (sigma 0) to always-on
    (inf): the final value and the steps to the level as IQMs with 95% intervals, each curve's
    point in its colour over a grey bar, and how often each gate let another network in."""
    fig, axes = plt.subplots(1, 3, figsize=(17, 4.2))
    x = np.arange(len(dose))
    ticks = ["never" if s == 0 else "always" if np.isinf(s) else f"{s:g}" for s in dose["sigma"]]
    for ax, (col, name) in zip(axes, (("final", final), ("steps", speed))):
        ax.errorbar(x, dose[col], yerr=[dose[col] - dose[f"{col}_low"], dose[f"{col}_high"] - dose[col]],
                    fmt="none", ecolor="0.3", capsize=3, zorder=1)
        ax.scatter(x, dose[col], s=70, color=[palette.color(label) for label in dose["label"]], zorder=2)
        ax.set_xticks(x, ticks)
        ax.set(xlabel="sigma (the gate's threshold on K)", ylabel=name, title=f"{where}\n{name}, IQM [95% CI]")
    axes[1].yaxis.set_major_formatter(STEPS)
    axes[2].bar(x, dose["open"].fillna(0.0), color=[palette.color(label) for label in dose["label"]])
    axes[2].set_xticks(x, ticks)
    axes[2].set(xlabel="sigma", ylabel="gate-open share", ylim=(0, 1),
                title=f"{where}\nhow often the gate let another network in")
    fig.tight_layout()
    return fig


def verdict_counts(counts: pd.DataFrame, ax=None, title=None):
    """``claims.summary``'s counts as one stacked bar per section, a colour per status
    (``palette.STATUS``), with a key below the bars."""
    ax = ax or plt.subplots(figsize=(9, 3.5))[1]
    statuses = [c for c in counts.columns if c in palette.STATUS]
    left = np.zeros(len(counts))
    for status in statuses:
        ax.barh(counts.index.astype(str), counts[status], left=left, color=palette.STATUS[status], label=status,
                edgecolor="0.35", linewidth=0.5, hatch=palette.STATUS_HATCH.get(status, ""))
        left += counts[status].to_numpy()
    ax.invert_yaxis()  # the paper's order, top to bottom
    ax.set(xlabel="claims", title=title or "the claims' verdicts per section")
    ax.legend(frameon=False, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3)
    return ax


def _no_runs(ax, title):
    """An empty frame (``load_figure(..., skip_missing=True)`` with nothing on disk) drawn as such."""
    ax.text(0.5, 0.5, "no runs on disk", ha="center", va="center", transform=ax.transAxes)
    ax.set(title=title)
    return ax


def reuse_heatmap(m: np.ndarray, ax=None, title=None, names=None):
    """Fig. 2a-c: the reuse matrix, M[i, j] = P(learner i trains on agent j's experience)."""
    m = np.asarray(m, dtype=float)
    if m.ndim != 2 or m.shape[0] != m.shape[1] or m.size == 0 or not np.isfinite(m).all():
        raise ValueError(f"M must be a square (n, n) matrix of numbers with n >= 1, got shape {m.shape}"
                         + ("" if m.size == 0 or np.isfinite(m).all() else " with NaN or inf"))
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
        ax.plot(r * np.cos(angle), r * np.sin(angle), "o", ms=12, color=AGENT_COLOURS.get(names[j], "grey"),
                markeredgecolor=REUSED if inside else OMITTED, markeredgewidth=3)
        ax.annotate(f"{names[j]}\nKL={kl_row[j]:.3g}", (r * np.cos(angle), r * np.sin(angle)),
                    xytext=(10, 0), textcoords="offset points", va="center")
    ax.set_xlim(-outer, outer)
    ax.set_ylim(-outer, outer)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title or f"reuse radius sigma = {sigma:g} (amber: reused, grey: omitted)")
    ax.text(0.5, -0.04, f"distance from the centre: log10 of KL / {floor:g} (a log scale: each ring a factor 10)",
            transform=ax.transAxes, ha="center", va="top", fontsize=8)
    for decade in range(1, int(outer) + 1):  # a faint ring per decade, so the scale can be read off
        ax.add_patch(plt.Circle((0, 0), decade, fill=False, color=OMITTED, lw=0.5, ls=":"))
    return ax
