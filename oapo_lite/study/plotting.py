"""Figures, drawn from tidy data only (the CSV in figures/data, or a reuse matrix)."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.ticker import FuncFormatter

plt.rcParams.update({"font.size": 11, "axes.titlesize": 12, "axes.grid": True, "grid.alpha": 0.3})
YLABELS = {"frac_opt": "return / oracle optimum (below 0: step costs exceed arrival rewards)",
           "eval_return": "episode return (evaluation)", "eval_success": "win rate",
           "peer_share": "peer share: weight on other agents' experience"}
# One colour per algorithm and per agent in every figure. The agents are named after their
# colours, so no algorithm is red, black or blue, and Fig. 1's reused / omitted are neither.
ALGO_COLORS = {"oappo": "#2ca02c", "oatrpo": "#9467bd", "mappo": "#ff7f0e", "happo": "#8c564b",
               "hatrpo": "#e377c2", "ippo": "#7f7f7f", "seac": "#bcbd22", "seps": "#17becf",
               "oappo adaptive": "#145214", "oappo warm-up 10": "#98df8a",
               # the selection ablation: gated reuse is OAPPO proper; always-on and within-kind its foils
               "oappo gated": "#2ca02c", "oappo always": "#d4a017", "oappo type gated": "#1b7f79",
               "oappo type own kind": "#7fb8b3"}
# Fig. 5b's reuse schemes: no reuse is HAPPO's scheme and everyone-shares MAPPO's, so they echo them
SCHEME_COLORS = {"NR": ALGO_COLORS["happo"], "AR": ALGO_COLORS["mappo"], "UR": "#e377c2", "RR": "#17becf"}
AGENT_COLORS = {"red": "#d62728", "black": "#000000", "blue": "#1f77b4"}
# env steps in thousands or millions, never matplotlib's "1e6" offset
STEPS = FuncFormatter(lambda x, _: f"{x / 1e6:g}M" if abs(x) >= 1e6 else f"{x / 1e3:g}k" if x else "0")
REUSED, OMITTED = "#e6a100", "#9a9a9a"


def color_of(label, order=None):
    """The colour of a curve: its algorithm's (the label, or its first word, any case: "OAPPO",
    "oappo lambda=0.4"; the adaptive rule has its own) or reuse scheme's, else the label's place in ``order`` on a
    sequential map (a sigma, a lambda, a reuse scheme), else None (matplotlib's next colour)."""
    if label in SCHEME_COLORS:
        return SCHEME_COLORS[label]
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
    """Fig. 3b-d, 4, App. A: every seed as a thin line (on top) and, bold, the median over seeds
    of ``y`` against env steps (the lower middle seed where the count is even, so at every step
    a level some seed reached). Not mean +- std, nor an IQM: outcomes that split into trapped
    and optimal seeds have a mean that describes no run and a band that leaves the possible
    range. The title gets a line saying so. ``colors``: label -> colour, where a figure needs
    its own (else ``color_of``)."""
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"the runs must be a pandas DataFrame (e.g. experiments.load_figure's), got {type(df).__name__}")
    ax = ax or plt.subplots(figsize=(6, 4))[1]
    if df.empty:  # e.g. load_figure(..., skip_missing=True) with nothing on disk
        return _no_runs(ax, title)
    lacking = [c for c in ("label", "seed", "step", y) if c not in df]
    if lacking:
        raise ValueError(f"the runs lack the columns {lacking}; they need label, seed, step and {y!r}")
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
        color = (colors or {}).get(label) or color_of(label, order)
        median = np.quantile(runs.to_numpy(float), 0.5, axis=1, method="lower")
        line, = ax.plot(runs.index, median, lw=2.2, label=str(label), color=color, zorder=2)
        seeds_of[label] = (runs, line.get_color())
    for runs, color in seeds_of.values():
        ax.plot(runs.index, runs.to_numpy(float), lw=0.8, alpha=0.5, color=color, zorder=3)
    ax.xaxis.set_major_formatter(STEPS)
    if y == "frac_opt":
        ax.axhline(1.0, color="grey", ls="--", lw=1)
    seeds = df.groupby("label")["seed"].nunique()
    note = f"bold: the median of {'/'.join(map(str, sorted(set(seeds))))} seeds; thin: each seed"
    ax.set(xlabel="environment steps", ylabel=ylabel or YLABELS.get(y, y),
           title=f"{title}\n{note}" if title else note)
    ax.legend(frameon=False)
    return ax


def sweep_colors(labels, default) -> dict:
    """Colours for a sweep of one OAPPO setting (Fig. 3c's sigma, 3d's lambda): the paper's
    default keeps OAPPO's colour, the other values a sequential map without green."""
    others = [x for x in labels if x != default]
    return {default: ALGO_COLORS["oappo"]} | {x: plt.cm.plasma(0.55 * k / max(len(others) - 1, 1))
                                              for k, x in enumerate(others)}


def final_bars(runs: pd.DataFrame, order=None, ax=None, title=None):
    """Fig. 5b: final fraction of the optimum per label: every seed as a dot, and the median run's
    level as a bar (the lower middle run where the count is even: a level some run reached; a
    mean or IQM of trapped and optimal seeds describes no run)."""
    ax = ax or plt.subplots(figsize=(5, 4))[1]
    if runs.empty:
        return _no_runs(ax, title)
    order = order if order is not None else list(dict.fromkeys(runs["label"]))
    finals = [runs.loc[runs["label"] == o, "final"].to_numpy(float) for o in order]
    colors = [color_of(o, order) for o in order]
    ax.bar([str(o) for o in order], [np.quantile(f, 0.5, method="lower") for f in finals], color=colors, alpha=0.5)
    for k, f in enumerate(finals):
        ax.plot(np.full(len(f), k) + np.linspace(-0.15, 0.15, len(f)), f, "o", ms=4, color="black")
    ax.axhline(1.0, color="grey", ls="--", lw=1)
    low = min(0.0, min(f.min() for f in finals) - 0.1)
    note = f"bar: the median run; dots: each of {max(len(f) for f in finals)} seeds"
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


def across_shares(df: pd.DataFrame, order=None, ax=None, title=None):
    """Beside a figure's curves: per curve, the median over seeds of ``across_share`` (M's weight
    on the seats of other networks: the reuse Eq. 9's gate decided) against env steps. A curve
    that never reuses across networks lies at 0."""
    ax = ax or plt.subplots(figsize=(6, 3))[1]
    df = df[df["across_share"].notna()] if "across_share" in df else df.iloc[:0]
    if df.empty:
        return _no_runs(ax, title)
    order = order if order is not None else list(dict.fromkeys(df["label"]))
    for label in order:
        runs = df[df["label"] == label].pivot_table(index="step", columns="seed", values="across_share")
        ax.plot(runs.index, np.quantile(runs.to_numpy(float), 0.5, axis=1, method="lower"), lw=2, label=str(label),
                color=color_of(label, order))
    ax.xaxis.set_major_formatter(STEPS)
    ax.set(xlabel="environment steps", ylabel="weight on other\nnetworks' seats", ylim=(-0.02, None),
           title=title or "reuse across networks (median over seeds)")
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
    ax.imshow(open_share, aspect="auto", cmap="Greens", vmin=0, vmax=1, interpolation="nearest",
              extent=(steps[0] - width / 2, steps[-1] + width / 2, len(pairs) - 0.5, -0.5))
    ax.set_yticks(range(len(pairs)), [f"{names[i]} <- {names[j]}" for i, j in pairs], fontsize=7)
    ax.xaxis.set_major_formatter(STEPS)
    ax.grid(False)
    ax.set(xlabel="environment steps", title=title or f"gate open (K <= sigma = {sigma:g}): share of seeds, dark = all")
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


def episode_animation(maze, trajectories: dict, title: str | None = None, interval: int = 350,
                      figsize: tuple[float, float] | None = None, dpi: int = 72):
    """One episode per label, side by side, as a ``matplotlib.animation.FuncAnimation``.

    ``maze``: a ``Maze`` or a built-in map name. ``trajectories``: label -> where every agent
    stands at every step, ``[[seat 0, seat 1, ...] at step 0 (the start cells), at step 1, ...]``,
    each position a flat cell or a ``(row, col)`` pair. Frame k shows step k of every episode (an
    episode that ended earlier stays on its last step), so there are as many frames as the longest
    trajectory has steps. Every agent is a disc in its colour (``AGENT_COLORS``) with the path it
    has walked so far as a thin line; the seats are drawn slightly apart, so agents on one cell
    stay visible. Each panel's title (in the label's colour, ``color_of``) counts the steps and
    says how many agents are on the star.

    The figure is not pyplot's, so nothing is shown twice in a notebook. Its ``to_jshtml()``
    gives HTML that needs no network: matplotlib's own links a CDN stylesheet (Font Awesome)
    for its button icons; here that link is dropped and the icons are Unicode characters. Its
    PNG frames are stored on 64 colours, a third of the bytes (the maze has few colours).
    """
    import base64
    import io
    import re

    from matplotlib import patheffects
    from matplotlib.animation import FuncAnimation
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from oapo_lite.envs.core import as_maze
    from oapo_lite.envs.render import TERRAIN_COLOURS, TERRAIN_NAMES

    maze = as_maze(maze)
    h, w = maze.shape
    n = maze.n_agents
    paths = {}
    for label, steps in trajectories.items():
        rc = np.array([[maze.cell(p) if np.ndim(p) == 0 else tuple(p) for p in step] for step in steps], float)
        if rc.ndim != 3 or rc.shape[1:] != (n, 2) or len(rc) == 0:
            raise ValueError(f"trajectory {label!r}: every step must give the {n} agents' positions "
                             f"(a flat cell or (row, col) each), got shape {np.shape(steps)}")
        paths[label] = rc
    if not paths:
        raise ValueError("episode_animation needs at least one trajectory")
    frames = max(len(rc) for rc in paths.values())
    star = np.array(maze.cell(maze.star), float)

    title_inches = 0.25 * (title.count("\n") + 1) if title else 0.0  # room for the title's lines
    fig = Figure(figsize=figsize or (3.6 * len(paths) + 0.4, 4.0 + title_inches), dpi=dpi)
    axes = fig.subplots(1, len(paths), squeeze=False)[0]
    height = fig.get_figheight()
    fig.subplots_adjust(left=0.02, right=0.98, top=1 - (0.5 + title_inches) / height, bottom=0.55 / height,
                        wspace=0.08)
    if title:
        fig.suptitle(title)
    cmap = ListedColormap([TERRAIN_COLOURS[code] for code in sorted(TERRAIN_COLOURS)])
    offset = (np.arange(n) - (n - 1) / 2) * 0.2  # seat k sits this far right of and below its cell's centre
    colours = [AGENT_COLORS[a] for a in maze.agents]
    outline = [patheffects.withStroke(linewidth=3.2, foreground="white")]  # a black path stays visible on black cells
    panels = []
    for ax, (label, rc) in zip(axes, paths.items()):
        ax.imshow(maze.terrain, cmap=cmap, vmin=-0.5, vmax=len(TERRAIN_COLOURS) - 0.5, interpolation="nearest")
        ax.set_xticks(np.arange(-0.5, w), minor=True)
        ax.set_yticks(np.arange(-0.5, h), minor=True)
        ax.grid(False)
        ax.grid(which="minor", color="#b0b0b0", linewidth=0.6)
        ax.tick_params(which="both", length=0, labelbottom=False, labelleft=False)
        ax.plot(star[1], star[0], marker="*", markersize=20, color="gold", markeredgecolor="#8a6d00",
                linestyle="none", zorder=3)
        trails = [ax.plot([], [], color=c, lw=1.6, zorder=4, path_effects=outline)[0] for c in colours]
        discs = [ax.plot([], [], marker="o", markersize=11, color=c, markeredgecolor="white", markeredgewidth=1.5,
                         linestyle="none", zorder=5)[0] for c in colours]
        panels.append((ax, str(label), rc, trails, discs))

    def update(k: int):
        artists = []
        for ax, label, rc, trails, discs in panels:
            s = min(k, len(rc) - 1)
            for seat in range(n):
                rows, cols = rc[: s + 1, seat, 0] + offset[seat], rc[: s + 1, seat, 1] + offset[seat]
                trails[seat].set_data(cols, rows)
                discs[seat].set_data([cols[-1]], [rows[-1]])
            arrived = (rc[s] == star).all(axis=1)
            note = "every agent on the star" if arrived.all() else f"{int(arrived.sum())} of {n} on the star"
            ax.set_title(f"{label}\nstep {s} of {len(rc) - 1}: {note}", fontsize=10, color=color_of(label) or "black")
            artists += [*trails, *discs, ax.title]
        return artists

    handles = [Line2D([], [], marker="o", markersize=9, color=c, markeredgecolor="white", linestyle="none",
                      label=f"{a} agent") for a, c in {a: AGENT_COLORS[a] for a in maze.agents}.items()]
    handles.append(Line2D([], [], marker="*", markersize=13, color="gold", markeredgecolor="#8a6d00",
                          linestyle="none", label="star"))
    handles += [Patch(facecolor=TERRAIN_COLOURS[code], edgecolor="#b0b0b0", label=name)
                for code, name in TERRAIN_NAMES.items() if (maze.terrain == code).any()]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), frameon=False, fontsize=8,
               handletextpad=0.3, columnspacing=0.9)
    anim = FuncAnimation(fig, update, frames=frames, init_func=lambda: update(0), interval=interval, blit=False)

    icons = {"fa fa-minus": "&minus;", "fa fa-fast-backward": "&#9646;&#9664;", "fa fa-step-backward": "&#9665;",
             "fa fa-play fa-flip-horizontal": "&#9664;", "fa fa-pause": "&#9646;&#9646;", "fa fa-play": "&#9654;",
             "fa fa-step-forward": "&#9655;", "fa fa-fast-forward": "&#9654;&#9646;", "fa fa-plus": "+"}
    matplotlib_jshtml = anim.to_jshtml

    def smaller(match) -> str:  # one base64 PNG frame, again on 64 colours
        from PIL import Image

        out = io.BytesIO()
        frame = Image.open(io.BytesIO(base64.b64decode(match.group(1)))).convert("RGB")
        frame.quantize(64, method=Image.Quantize.FASTOCTREE).save(out, "png")
        return f"data:image/png;base64,{base64.b64encode(out.getvalue()).decode()}"

    def to_jshtml(fps=None, embed_frames=True, default_mode=None):
        html = matplotlib_jshtml(fps, embed_frames, default_mode)
        html = re.sub(r'<link rel="stylesheet"\s+href="https?://[^"]*">', "", html)
        html = re.sub(r"data:image/png;base64,([A-Za-z0-9+/=\s\\]+)", smaller, html)
        return re.sub(r'<i class="(fa [^"]*)"></i>', lambda m: icons.get(m.group(1), ""), html)

    anim.to_jshtml = to_jshtml
    return anim
