"""What the reproduction found, in sentences: every number in them is computed here from the
committed runs (the claims table, the layout study, Fig. 4's runs, the selection ablation and the
cost records), so the text changes when the data does. Notebook 00 prints ``findings``; the
README opens with ``opening`` (``write_readme`` writes it with the claims table, a test compares them)."""
from __future__ import annotations

import sys

import pandas as pd

from oapo_lite.study import claims, costs, experiments, layout_study, readme, selection, verdicts
from oapo_lite.study.figures import get_figure, runs_of

LAYOUT_BUDGET = "paper"  # the layout study's committed runs (5 seeds per layout and curve)
SELECTION_FIGURES = ("fig_selection_smax", "fig_selection_mamujoco")
UNRUN_FIGURES = ("fig6b", "fig4_smax")  # where the claims table has rows "not run"


def _row(glance: pd.DataFrame, claim: str) -> pd.Series:
    rows = glance[glance["claim"] == claim]
    if len(rows) != 1:
        raise KeyError(f"the claims table has {len(rows)} rows for {claim!r}")
    return rows.iloc[0]


def _estimate(row: pd.Series) -> str:
    """The interval a row's reason leads with (its reading after "by the interval alone", if any)."""
    why = row["why"].split(f"{verdicts.INTERVAL_ALONE} ")[-1]
    return why.split(": ")[0] if ": " in why else why


def mazes(glance: pd.DataFrame) -> dict:
    """The maze facts the conclusion states: OAPPO against HAPPO at the better-powered budget,
    and the layout study's runs that stayed below 95% of the optimum per curve."""
    faster = _row(glance, "OAPPO converges faster than HAPPO")
    runs = layout_study.per_run(layout_study.load(LAYOUT_BUDGET))
    below = (runs["final"] < verdicts.THRESHOLD).groupby(runs["label"]).agg(["sum", "size"])
    return {"faster": faster, "below": below, "layouts": runs["layout"].nunique()}


def smax_sharing() -> pd.DataFrame:
    """Per Fig. 4 map at ``cpu``: MAPPO's and HAPPO's final win rate (IQM) and P(MAPPO reaches a
    50% win rate in fewer steps than HAPPO)."""
    df = experiments.load_figure("fig4_smax", "cpu", skip_missing=True)
    rows = {}
    for env, runs in df.groupby("env", sort=False):
        ev = verdicts.Evidence(runs, metric=verdicts.WIN_RATE)
        if {"mappo", "happo"} <= set(ev.summary.index):
            rows[env.removeprefix("smax:")] = {"mappo": ev.level("mappo", "final").point,
                                               "happo": ev.level("happo", "final").point,
                                               "p_mappo_faster": ev.improvement("mappo", "happo", "steps").point}
    return pd.DataFrame.from_dict(rows, orient="index")


def selection_results() -> dict[str, dict]:
    """Per env of the selection ablation: seeds on disk (fewest of a curve), and the verdict of
    each of its claims, keyed by the claim's test ("gated vs never", "gated vs always", ...)."""
    out = {}
    for figure in SELECTION_FIGURES:
        fig = get_figure(figure)
        df = experiments.load_figure(figure, "cpu", skip_missing=True)
        table = selection.summary(df, figure)
        for claim, v in zip(fig.claims, claims.judge(fig, df)):
            env = claim[0] if fig.claims_per_env else "HalfCheetah 2x3"
            labels = claim[-2]
            key = {("oappo gated", "happo"): "gated vs never", ("oappo gated", "oappo always"): "gated vs always",
                   ("oappo always", "happo"): "always vs never",
                   ("oappo type gated", "oappo type own type"): "across types vs within"}[tuple(labels)]
            part = table[table["env"].str.contains(env.split()[0], regex=False)]
            out.setdefault(env, {"seeds": int(part["seeds"].min()) if len(part) else 0})[key] = v
    return out


def smax_share() -> str:
    """Fig. 4's ``cpu`` steps as a share of HARL's, the smallest and largest over its maps."""
    fig = get_figure("fig4_smax")
    shares = [fig.budget("cpu", env).steps / fig.budget("paper", env).steps for env in fig.envs("cpu")]
    return f"{100 * min(shares):.2g}-{100 * max(shares):.2g}%"


def grf_steps() -> int:
    """The env steps of a GRF run at ``cpu``, the longest."""
    return max(r.cfg.steps for r in runs_of("fig6b", "cpu"))


def outcome(sel: dict) -> tuple[list[str], list[str], list[str]]:
    """From ``selection_results``: the envs where reuse (always or gated) ended above no reuse,
    those where gated reuse ended above always-on (each with its interval above 0), and those
    where gated against always-on could be judged at all."""
    def status(r, k):
        return r[k].status if k in r else verdicts.NOT_RUN
    helped = [e for e, r in sel.items() if verdicts.REPRODUCED in (status(r, "gated vs never"), status(r, "always vs never"))]
    selected = [e for e, r in sel.items() if status(r, "gated vs always") == verdicts.REPRODUCED]
    tested = [e for e, r in sel.items() if status(r, "gated vs always") not in (verdicts.NOT_TESTABLE, verdicts.NOT_RUN)]
    return helped, selected, tested


def unrun(glance: pd.DataFrame) -> list[tuple[str, str]]:
    """The claims table's rows of envs with no run, (claim, budget) each."""
    rows = glance[glance["verdict"] == verdicts.NOT_RUN]
    return list(zip(rows["claim"], rows["budget"]))


def findings(glance: pd.DataFrame | None = None) -> list[str]:
    """The conclusion, one paragraph per finding, every number from the data."""
    glance = claims.glance() if glance is None else glance
    counts = claims.summary(glance)
    held = {s: int(counts.loc[s].get(verdicts.REPRODUCED, 0)) for s in counts.index}
    against = {s: int(counts.loc[s].get(verdicts.CONTRADICTED, 0)) for s in counts.index}
    m = mazes(glance)
    below = m["below"]
    lam = [c for c in ("oappo lambda=0.2", "oappo lambda=0.4") if c in below.index]
    traps = ", ".join(f"{c.removeprefix('oappo ')} ended below 95% on {below.loc[c, 'sum']} of {below.loc[c, 'size']}"
                      for c in lam)
    out = [
        "What the paper claims: agents that update one after another (HAPPO's scheme) and also learn from another "
        "agent's experience while their policies are within KL sigma (Eq. 9) learn faster than agents that use only "
        "their own experience, and avoid the local optima that full parameter sharing (MAPPO) falls into.",
        f"On the mazes (Section 6.1, {held['6.1']} claims reproduced, {against['6.1']} contradicted): reuse at lambda = "
        f"0.7 learned faster than HAPPO ({m['faster']['verdict']} at {m['faster']['budget'].split(';')[0]}: "
        f"{_estimate(m['faster'])}), and on {m['layouts']} generated layouts it ended below 95% of the optimum on "
        f"{below.loc['oappo', 'sum']} of {below.loc['oappo', 'size']} runs against HAPPO's {below.loc['happo', 'sum']} of "
        f"{below.loc['happo', 'size']}: reuse rescued HAPPO's exploration failures."
        + (f" Leaning on the peer traps the agents: {traps} (the paper recommends lambda = 0.4)." if lam else ""),
    ]
    sharing = smax_sharing()
    if len(sharing):
        beats = sharing[sharing["mappo"] >= sharing["happo"]]
        out.append(
            f"On SMAX (Section 6.2, at a `cpu` budget of {smax_share()} of HARL's steps per map), MAPPO, which only shares "
            f"one network, ended at or above HAPPO on {len(beats)} of {len(sharing)} maps and reached a 50% win rate "
            f"faster with P = " + ", ".join(f"{p:.2f} ({mp})" for mp, p in sharing["p_mappo_faster"].items())
            + f"; {int(counts.loc['6.2'].get(verdicts.SHARING, 0))} of the readings' claims over HAPPO or MAPPO are tests "
            "of parameter sharing rather than of reuse, because those readings share networks and hardly reused across them.")
    sel = selection_results()
    helped, selected, tested = outcome(sel)
    if sel:
        parts = [f"{env} (at least {r['seeds']} seed pairs on disk): " + "; ".join(
            f"{k} {v.status} ({v.estimate.split(': ')[-1]})" if v.status not in (verdicts.NOT_TESTABLE, verdicts.NOT_RUN)
            else f"{k} {v.status}" for k, v in r.items() if k != "seeds") for env, r in sel.items()]
        out.append(
            "What the engines say about selective reuse, from the seed-paired ablation at equal settings (a net per "
            "agent; final value differences paired by seed, 1M steps): " + ". ".join(parts) + ". Selection "
            + (f"helped on {', '.join(selected)}." if selected else
               f"did not help: on none of the {len(tested)} envs where it could be judged did the gated curve end above "
               "the always-on one with its interval above 0.")
            + (f" Reuse itself ended above no reuse, interval above 0, on {', '.join(helped)}."
               if helped else " Reuse itself never ended above no reuse with its interval above 0."))
    never = unrun(glance)
    if never:
        plans = {f: costs.plan("paper", figures=(f,), from_nothing=True)[0][0] for f in UNRUN_FIGURES}
        out.append(
            "Never tested: " + "; ".join(f"{c.split(' (')[0]} ({b})" for c, b in never) + ". The `paper` budgets of "
            "those figures would take " + "; ".join(
                f"{f}: {p.runs} runs, {p.steps / 1e9:.3g}B env steps, {p.cpu_hours:,.0f} CPU hours"
                + (f" for the {p.runs - p.unpriced} priced runs ({p.unpriced} without a measured cost)" if p.unpriced else "")
                for f, p in plans.items()) + ".")
    out.append(
        "What to take away about off-agent reuse: on the mazes, where the agents' goals differ, a moderate share of "
        "another agent's experience speeds learning and a large one traps. On the engines at these budgets, plain "
        "parameter sharing matched or beat OAPPO's readings over HAPPO; reuse across networks at equal settings "
        + (f"ended above no reuse on {', '.join(helped)}" if helped else "never ended above no reuse with its interval above 0")
        + ", and gating it by the policies' KL "
        + (f"helped on {', '.join(selected)}." if selected else "added nothing measurable over reusing always."))
    return out


def opening(glance: pd.DataFrame | None = None) -> str:
    """The README's opening: the findings in three sentences."""
    glance = claims.glance() if glance is None else glance
    m = mazes(glance)
    below = m["below"]
    sharing = smax_sharing()
    _, selected, tested = outcome(selection_results())
    return (f"On the mazes, reuse at lambda = 0.7 learned faster than HAPPO ({_estimate(m['faster'])}) and ended below 95% "
            f"of the optimum on {below.loc['oappo', 'sum']} of {below.loc['oappo', 'size']} generated-layout runs against "
            f"HAPPO's {below.loc['happo', 'sum']}, while a larger share of the peer's experience (lambda <= 0.4) trapped "
            f"the agents. On SMAX, MAPPO's plain parameter sharing ended at or above HAPPO on "
            f"{int((sharing['mappo'] >= sharing['happo']).sum())} of {len(sharing)} maps, and in a seed-paired ablation "
            f"gated reuse ended above always-on reuse on {len(selected)} of the {len(tested)} envs where it could be judged"
            + (f" ({', '.join(tested)})" if tested else "") + f". Google Research Football beyond {grf_steps() / 1e3:g}k "
            "steps, the MMM2 stand-in and the paper's own step budgets were never run; the table below says claim by "
            "claim what held.")


BEGIN, END = "<!-- opening: generated by python -m oapo_lite.study.conclusion -->", "<!-- end of opening -->"


def write_readme(path=readme.README) -> None:
    """Replace the README's claims table and its opening with what the data gives."""
    glance = claims.glance()
    readme.rewrite(claims.BEGIN, claims.END, claims.readme_markdown(glance), path)
    readme.rewrite(BEGIN, END, opening(glance), path)


if __name__ == "__main__":
    write_readme()
    print(f"wrote the opening and the claims table into {readme.README}", file=sys.stderr)
