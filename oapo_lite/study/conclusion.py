"""What the reproduction found, in sentences: every number in them, and every verb that states an
outcome, is computed here from the committed runs (the claims table, the layout study, Fig. 4's
runs, the selection ablation and the cost records), so the text changes when the data does.
Notebook 00 prints ``findings``; the README opens with ``opening`` (``write_readme`` writes it
with the claims table, a test compares them)."""
from __future__ import annotations

import sys

import pandas as pd

from oapo_lite.study import claims, costs, experiments, layout_study, readme, selection, verdicts
from oapo_lite.study.figures import GRID, figure_runs, get_figure

LAYOUT_BUDGET = "paper"  # the layout study's committed runs (5 seeds per layout and curve)
SELECTION_FIGURES = ("fig_selection_smax", "fig_selection_mamujoco")
LEAN = ("oappo lambda=0.2", "oappo lambda=0.4")  # the readings that lean on the peer (lambda < 1/2)
# the statuses under which an interval decided a claim (the others say why it could not)
DECIDED = (verdicts.REPRODUCED, verdicts.WITHIN_NOISE, verdicts.NOT, verdicts.CONTRADICTED)
# the selection ablation's claims, by the curves they compare
SELECTION_TESTS = {("oappo gated", "happo"): "gated vs never", ("oappo gated", "oappo always"): "gated vs always",
                   ("oappo always", "happo"): "always vs never",
                   ("oappo type gated", "oappo type own type"): "across types vs within"}


def _row(glance: pd.DataFrame, claim: str) -> pd.Series:
    rows = glance[glance["claim"] == claim]
    if len(rows) != 1:
        raise KeyError(f"the claims table has {len(rows)} rows for {claim!r}")
    return rows.iloc[0]


def _estimate(row: pd.Series) -> str:
    """The interval a row's reason gives (after "by the interval alone <status>:", where there)."""
    why = row["why"]
    if verdicts.INTERVAL_ALONE in why:
        why = why.split(f"{verdicts.INTERVAL_ALONE} ", 1)[1].split(": ", 1)[1]
    return why.split(": ")[0]


def mazes(glance: pd.DataFrame) -> dict:
    """The maze facts the conclusion states: OAPPO against HAPPO at the better-powered budget,
    and the layout study's runs that stayed below 95% of the optimum per curve."""
    faster = _row(glance, "OAPPO converges faster than HAPPO")
    runs = layout_study.per_run(layout_study.load(LAYOUT_BUDGET))
    below = (runs["final"] < verdicts.THRESHOLD).groupby(runs["label"]).agg(["sum", "size"])
    return {"faster": faster, "below": below, "layouts": runs["layout"].nunique()}


def smax_sharing() -> pd.DataFrame:
    """Per Fig. 4 map at ``cpu``: the final win rate (IQM) of MAPPO, of HAPPO and of the best
    OAPPO reading, and P(MAPPO reaches a 50% win rate in fewer steps than HAPPO)."""
    df = experiments.load_figure("fig4_smax", "cpu", skip_missing=True)
    rows = {}
    for env, runs in df.groupby("env", sort=False):
        ev = verdicts.Evidence(runs, metric=verdicts.WIN_RATE)
        readings = [a for a in ev.summary.index if str(a).startswith("oappo")]
        if {"mappo", "happo"} <= set(ev.summary.index) and readings:
            rows[env.removeprefix("smax:")] = {"mappo": ev.level("mappo", "final").point,
                                               "happo": ev.level("happo", "final").point,
                                               "best_oappo": max(ev.level(a, "final").point for a in readings),
                                               "p_mappo_faster": ev.improvement("mappo", "happo", "steps").point}
    return pd.DataFrame.from_dict(rows, orient="index", columns=["mappo", "happo", "best_oappo", "p_mappo_faster"])


def selection_results() -> dict[str, dict]:
    """Per env of the selection ablation: each curve's seeds on disk and the seeds planned
    (``seeds``, ``planned``), and the verdict of each of its claims by ``SELECTION_TESTS``."""
    out = {}
    for figure in SELECTION_FIGURES:
        fig = get_figure(figure)
        df = experiments.load_figure(figure, "cpu", skip_missing=True)
        for claim, v in zip(fig.claims, claims.judge(fig, df)):
            env = claim[0] if fig.claims_per_env else "HalfCheetah 2x3"
            out.setdefault(env, {})[SELECTION_TESTS[tuple(claim[-2])]] = v
        for env in dict.fromkeys(cfg.env for _, cfg in figure_runs(fig, "cpu")):
            name = env.removeprefix(fig.claims_per_env) if fig.claims_per_env else "HalfCheetah 2x3"
            labels = [label for label, kw in fig.curves if kw["env"] == env]
            on_disk = df[df["env"] == env].groupby("label")["seed"].nunique() if len(df) else pd.Series(dtype=int)
            out[name]["seeds"] = {label: int(on_disk.get(label, 0)) for label in labels}
            out[name]["planned"] = len(fig.budget("cpu", env).seeds)
            out[name]["steps"] = fig.budget("cpu", env).steps
    return out


def outcome(sel: dict) -> tuple[list[str], list[str], list[str]]:
    """From ``selection_results``: the envs where reuse (always or gated) ended above no reuse,
    those where gated reuse ended above always-on (each with its paired interval above 0), and
    those where an interval decided gated against always-on at all."""
    def status(r, k):
        return r[k].status if k in r else verdicts.NOT_RUN
    helped = [e for e, r in sel.items() if verdicts.REPRODUCED in (status(r, "gated vs never"), status(r, "always vs never"))]
    selected = [e for e, r in sel.items() if status(r, "gated vs always") == verdicts.REPRODUCED]
    tested = [e for e, r in sel.items() if status(r, "gated vs always") in DECIDED]
    return helped, selected, tested


def gate_share(v: verdicts.Verdict) -> str:
    """How often the gated curve reused across networks, from a ``verdicts.selects`` verdict's reason."""
    return "gated curve " + v.reason.rsplit("; oappo gated ", 1)[1]


def smax_share() -> str:
    """Fig. 4's ``cpu`` steps as a share of HARL's, the smallest and largest over its maps."""
    fig = get_figure("fig4_smax")
    shares = [fig.budget("cpu", env).steps / fig.budget("paper", env).steps for env in fig.envs("cpu")]
    return f"{100 * min(shares):.3g}-{100 * max(shares):.3g}%"


def unrun(glance: pd.DataFrame) -> pd.DataFrame:
    """The claims table's rows of envs with no run at ``cpu`` (one row per env)."""
    return glance[glance["verdict"] == verdicts.NOT_RUN]


def _figure_of(row: pd.Series) -> str:
    """The figure whose claims are about the env a claims-table row of an unrun env names."""
    env = row["claim"].split(":")[0]
    return next(f.id for f in GRID if f.claims_per_env and any(c[0] == env for c in f.claims))


def _maze_paragraph(glance: pd.DataFrame, counts: pd.DataFrame) -> tuple[str, dict]:
    m = mazes(glance)
    below, faster = m["below"], m["faster"]
    happo = int(below.loc["happo", "sum"])
    lean = {c: int(below.loc[c, "sum"]) for c in LEAN if c in below.index}
    rescued = below.loc["oappo", "sum"] < happo
    trapped = [c for c, n in lean.items() if n > happo]
    text = (f"On the mazes (Section 6.1, {int(counts.loc['6.1'].get(verdicts.REPRODUCED, 0))} claims reproduced, "
            f"{int(counts.loc['6.1'].get(verdicts.CONTRADICTED, 0))} contradicted), \"OAPPO converges faster than HAPPO\" "
            f"is {faster['verdict']} at {faster['budget'].split(';')[0]} ({_estimate(faster)}). On {m['layouts']} "
            f"generated layouts OAPPO (lambda = 0.7) ended below 95% of the optimum on {below.loc['oappo', 'sum']} of "
            f"{below.loc['oappo', 'size']} runs against HAPPO's {happo} of {below.loc['happo', 'size']}"
            + (": reuse rescued HAPPO's exploration failures." if rescued else ": reuse did not lower HAPPO's failures.")
            + " At " + ", at ".join(f"lambda = {c.split('=')[1]} it ended below 95% on {n} of {below.loc[c, 'size']}"
                                    for c, n in lean.items())
            + (": leaning on the peer's experience (lambda < 1/2) trapped the agents more often than no reuse, "
               "where the paper recommends lambda = 0.4." if trapped else "."))
    return text, {"m": m, "happo": happo, "lean": lean, "rescued": rescued, "trapped": trapped}


def findings(glance: pd.DataFrame | None = None) -> list[str]:
    """The conclusion, one paragraph per finding, every number from the data."""
    glance = claims.glance() if glance is None else glance
    counts = claims.summary(glance)
    maze_text, maze = _maze_paragraph(glance, counts)
    out = ["What the paper claims: agents that update one after another (HAPPO's scheme) and also learn from another "
           "agent's experience while their policies are within KL sigma (Eq. 9) learn faster than agents that use only "
           "their own experience, and avoid the local optima that full parameter sharing (MAPPO) falls into.", maze_text]
    sharing = smax_sharing()
    matched = sharing[sharing["mappo"] >= sharing["best_oappo"]] if len(sharing) else sharing
    if len(sharing):
        out.append(
            f"On SMAX (Section 6.2, Fig. 4 at a `cpu` budget of {smax_share()} of HARL's steps per map), MAPPO, which only "
            f"shares one network, ended with a final win rate IQM at or above HAPPO's on "
            f"{int((sharing['mappo'] >= sharing['happo']).sum())} of {len(sharing)} maps and at or above the best OAPPO "
            f"reading's on {len(matched)}, and reached a 50% win rate faster than HAPPO with P = "
            + ", ".join(f"{p:.2f} ({mp})" for mp, p in sharing["p_mappo_faster"].items())
            + f". {int(counts.loc['6.2'].get(verdicts.SHARING, 0))} claims of Section 6.2 are tests of parameter sharing "
            "rather than of reuse: those readings share networks and hardly reused across them.")
    sel = selection_results()
    helped, selected, tested = outcome(sel)
    if sel:
        parts = []
        for env, r in sel.items():
            seeds = ", ".join(f"{label} {n}" for label, n in r["seeds"].items())
            parts.append(f"{env} ({r['steps'] / 1e6:g}M steps; seeds on disk of {r['planned']} planned: {seeds}): " + "; ".join(
                f"{k} {v.status} ({v.estimate}" + (f"; {gate_share(v)}" if k == "gated vs always" else "") + ")"
                if v.status in DECIDED else f"{k} {v.status} ({v.reason})"
                for k, v in r.items() if k in SELECTION_TESTS.values()))
        out.append(
            "What the engines say about selective reuse, from the seed-paired ablation at equal settings (a seed gives "
            "every curve the same initial networks; final values differenced seed by seed): " + ". ".join(parts) + ". "
            + (f"Selection helped on {', '.join(selected)}." if selected else
               f"Selection was not shown to help: on none of the {len(tested)} envs where an interval decided it did "
               "gated reuse end above always-on reuse with its interval above 0.")
            + (f" Reuse itself ended above no reuse, interval above 0, on {', '.join(helped)}."
               if helped else " Reuse itself never ended above no reuse with its interval above 0."))
    paired = [(f, row) for f in SELECTION_FIGURES
              for _, row in selection.estimators(experiments.load_figure(f, "cpu", skip_missing=True), f).iterrows()]
    if paired:
        out.append("What reuse costs, from the runs' own records: Eq. 8's weights train each learner on the samples of "
                   "every seat it reuses, Algorithm 1's sampled source on one seat's, as HAPPO's learner does. "
                   + "; ".join(selection.estimator_sentence(row, f) for f, row in paired) + ".")
    never = unrun(glance)
    if len(never):
        plans = {f: costs.plan("paper", figures=(f,), from_nothing=True)[0][0]
                 for f in dict.fromkeys(_figure_of(row) for _, row in never.iterrows())}
        out.append(
            "Never run: " + "; ".join(f"{c.split(' (')[0]} ({b})" for c, b in zip(never["claim"], never["budget"]))
            + ". The `paper` budgets of those figures: " + "; ".join(
                f"{f}: {p.runs} runs, {p.steps / 1e9:.3g}B env steps, {p.cpu_hours:,.0f} CPU hours"
                + (f" for the {p.runs - p.unpriced} runs with a measured cost ({p.unpriced} without)" if p.unpriced else "")
                for f, p in plans.items()) + ".")
    out.append(
        "What to take away about off-agent reuse: on the mazes, where the agents' goals differ at some cells, "
        + ("a moderate share of another agent's experience (lambda = 0.7) spared the runs HAPPO lost to exploration"
           if maze["rescued"] else "reuse did not spare HAPPO's failed runs")
        + (", and a larger one trapped them." if maze["trapped"] else ".")
        + (f" On SMAX at these budgets plain parameter sharing ended at or above every OAPPO reading on {len(matched)} "
           f"of {len(sharing)} maps." if len(sharing) else "")
        + " In the seed-paired ablation reuse across networks "
        + (f"ended above no reuse on {', '.join(helped)}" if helped else "never ended above no reuse with its interval above 0")
        + ", and gating it by the policies' KL "
        + (f"helped on {', '.join(selected)} (" + "; ".join(
            f"there the {gate_share(sel[e]['gated vs always'])}, and gated against no reuse is "
            f"{sel[e]['gated vs never'].status}" for e in selected) + ")." if selected else
           f"was not shown to help on any of the {len(tested)} envs where it was decided."))
    return out


def opening(glance: pd.DataFrame | None = None) -> str:
    """The README's opening: the findings in three sentences."""
    glance = claims.glance() if glance is None else glance
    _, maze = _maze_paragraph(glance, claims.summary(glance))
    below = maze["m"]["below"]
    sharing = smax_sharing()
    _, selected, tested = outcome(selection_results())
    never = unrun(glance)
    faster = maze["m"]["faster"]
    first = ("On the mazes, OAPPO (lambda = 0.7) "
             + ("learned faster than HAPPO" if faster["verdict"] == verdicts.REPRODUCED else "was not shown to learn faster than HAPPO")
             + f" ({_estimate(faster)}, {faster['verdict']}) and ended below 95% of the optimum on {below.loc['oappo', 'sum']} of "
             f"{below.loc['oappo', 'size']} generated-layout runs against HAPPO's {maze['happo']}"
             + (", while leaning on the peer (" + ", ".join(f"lambda = {c.split('=')[1]}: {n}" for c, n in maze["lean"].items())
                + ") trapped the agents." if maze["trapped"] else "."))
    second = (f" On SMAX, MAPPO's plain parameter sharing ended at or above HAPPO on "
              f"{int((sharing['mappo'] >= sharing['happo']).sum())} of {len(sharing)} maps" if len(sharing) else " ")
    second += (f"{',' if len(sharing) else ''} and in a seed-paired ablation gated reuse ended above always-on reuse on "
               f"{len(selected)} of the {len(tested)} envs where an interval decided it"
               + (f" ({', '.join(tested)})" if tested else "") + ".")
    third = (" Never run: " + ", ".join(dict.fromkeys(c.split(":")[0] for c in never["claim"]))
             + "; the table below says claim by claim what held." if len(never) else
             " The table below says claim by claim what held.")
    return first + second + third


BEGIN, END = "<!-- opening: generated by python -m oapo_lite.study.conclusion -->", "<!-- end of opening -->"


def write_readme(path=readme.README) -> None:
    """Replace the README's claims table and its opening with what the data gives."""
    glance = claims.glance()
    readme.rewrite(claims.BEGIN, claims.END, claims.readme_markdown(glance), path)
    readme.rewrite(BEGIN, END, opening(glance), path)


if __name__ == "__main__":
    write_readme()
    print(f"wrote the opening and the claims table into {readme.README}", file=sys.stderr)
