"""What the reproduction found, in sentences rendered from data: the verdict records of every
claim (``judge.verdicts.glance``), the layout study's runs, the ablation's and dose-response's
runs and their cost records. Notebook 00 prints ``findings`` and ``ablation_table``; the README
opens with ``opening`` and lists ``headlines`` (``write_readme`` writes them with the claims table;
a test compares them with what the data gives)."""
from __future__ import annotations

import sys

import numpy as np
import pandas as pd

from oapo_lite.study.catalogue import figures
from oapo_lite.study.catalogue.figures import get_figure
from oapo_lite.study.catalogue.figures.layouts import CURVES
from oapo_lite.study.judge import verdicts
from oapo_lite.study.judge.evidence import Evidence
from oapo_lite.study.judge.records import DECIDED, MECHANISM, Status, Verdict
from oapo_lite.study.report import claims, words
from oapo_lite.study.runs import costs, experiments, readme
from oapo_lite.study.studies import layout_study, selection

LAYOUT_BUDGET = "paper"  # the layout study's committed runs (5 seeds per layout and curve)
LEAN = ("oappo lambda=0.2", "oappo lambda=0.4")  # the readings that lean on the peer (lambda < 1/2)
ABLATION = ("fig_selection_smax", "fig_selection_mamujoco")
DOSE = ("fig_dose_smax", "fig_dose_mamujoco")
CEILING = 0.9  # a win rate every run of every curve ends at or above: final values cannot tell curves apart


def _verdict(judged: list[verdicts.Judged], figure: str, text: str) -> Verdict:
    found = [j.lead for j in judged if j.figure.id == figure and j.lead.claim.text == text]
    if len(found) != 1:
        raise KeyError(f"{figure} has {len(found)} claims {text!r}")
    return found[0]


def _figure(judged: list[verdicts.Judged], figure: str) -> list[Verdict]:
    return [j.lead for j in judged if j.figure.id == figure]


# --- the facts, as data ------------------------------------------------------------------

def layouts() -> pd.DataFrame:
    """Per curve of the layout study: its runs that ended below 95% of the optimum, of how many."""
    runs = layout_study.per_run(layout_study.load(LAYOUT_BUDGET))
    out = (runs["final"] < 0.95).groupby(runs["label"]).agg(["sum", "size"]).rename(columns={"sum": "below", "size": "runs"})
    return out.assign(layouts=runs["layout"].nunique())


APP_A = "direct experience reuse degrades performance"  # App. A's claim, in the paper's words


def headline_verdicts(judged: list[verdicts.Judged]) -> list[tuple[verdicts.Judged, Verdict]]:
    """The paper's headline claims (``Claim.headline``) with their lead verdicts."""
    return [(j, j.lead) for j in judged if j.lead.claim.headline]


def ceiling(figure: str, env: str | None = None) -> tuple[float, float] | None:
    """(lowest, highest) final value of every run of every curve of ``figure`` (on ``env``) at
    ``cpu``, where the lowest is at or above ``CEILING`` (a win rate); else None."""
    fig = get_figure(figure)
    df = experiments.read_figure(figure, "cpu", skip_missing=True)[0]
    if env is not None and len(df):
        df = df[df["env"] == env]
    if df.empty or fig.metric.column != "eval_success":
        return None
    finals = Evidence(df, fig.metric).runs["final"]
    return (float(finals.min()), float(finals.max())) if finals.min() >= CEILING else None


def ablation_table(judged: list[verdicts.Judged]) -> pd.DataFrame:
    """The seed-paired ablation and the dose-response, one row per claim: env, the comparison,
    the verdict, each estimate its interval read against its curve (``words.short``; a selection
    claim reads two, one per end, and both must hold), its budget as a share of HARL's steps, its
    seeds of those planned, and whether one seed carries it."""
    rows = []
    for figure in ABLATION + DOSE:
        planned = len(get_figure(figure).budget("cpu").seeds)
        for v in _figure(judged, figure):
            read = v.estimates[:2] if v.claim.kind.statistic == "selection" else v.estimates[:1]
            rows.append({"env": env_name(v), "claim": v.claim.text, "verdict": v.status.value,
                         "estimate": "; ".join(
                             f"vs {e.curves[1]}: {words.short(e.interval)}"
                             + ("" if e.higher_on is None else f", higher on {e.higher_on} of {e.seeds}")
                             for e in read) or "-",
                         "budget": claims.budget_share(figure, v.claim.env or _env_of(figure), "cpu"),
                         "seeds": f"{len(v.robustness.seeds)}" + (f" of {planned} planned" * (len(v.robustness.seeds) < planned))
                         + ("; " + words.robustness(v) if v.one_seed else "") if v.robustness else "-"})
    return pd.DataFrame(rows)


def _env_of(figure: str) -> str:
    """The env of a figure judged whole (its common env, else its curves')."""
    fig = get_figure(figure)
    return fig.common.get("env") or next(kw["env"] for _, kw in fig.curves if "env" in kw)


def env_name(v: Verdict) -> str:
    """The map or robot a verdict is about: its claim's env, else its figure's, without the engine."""
    env = v.claim.env or get_figure(v.figure).common.get("env") or next(
        kw["env"] for _, kw in get_figure(v.figure).curves if "env" in kw)
    return env.partition(":")[2] or env


def draw_pairs() -> pd.DataFrame:
    """Algorithm 1's sampled source against Eq. 8's weights (``selection.estimators``) per env."""
    frames = [selection.estimators(experiments.read_figure(f, "cpu", skip_missing=True)[0], f) for f in ABLATION]
    return pd.concat([f for f in frames if len(f)], ignore_index=True) if any(len(f) for f in frames) else pd.DataFrame()


def compute(figure: str) -> pd.DataFrame:
    """Per env and curve of an ablation figure: CPU seconds to its metric's level (the runs' own
    records, ``selection.cpu_to_level``), and whether every seed's runs of that curve and of HAPPO
    were trained at one revision (only then are the two measured side by side)."""
    fig = get_figure(figure)
    df = experiments.read_figure(figure, "cpu", skip_missing=True)[0]
    rows = []
    for env, part in df.groupby("env", sort=False) if len(df) else []:
        cpu = selection.cpu_to_level(part, fig.metric, fig.metric.threshold)
        rev = part.groupby(["label", "seed"])["git_rev"].first().unstack("label")
        for label, seconds in cpu.items():
            same = bool(label == "happo" or ("happo" in rev and (rev[label] == rev["happo"]).all()))
            rows.append({"env": env, "label": label, "cpu_s": seconds, "side_by_side": same})
    return pd.DataFrame(rows)


# --- the findings, in words ----------------------------------------------------------------

def _maze(judged) -> dict:
    lay = layouts()
    return {"faster": next(j for j, v in headline_verdicts(judged) if v.claim.text == "OAPPO converges faster than HAPPO"),
            "balance": _verdict(judged, "fig3d", next(c.text for c in get_figure("fig3d").claims if c.headline)),
            "below": lay, "n": int(lay["layouts"].iloc[0])}


def maze_sentence(judged) -> str:
    m = _maze(judged)
    faster, below = m["faster"].lead, m["below"]
    b = lambda label: f"{int(below.loc[label, 'below'])} of {int(below.loc[label, 'runs'])}"  # noqa: E731
    lean = ", ".join(f"{b(c)} at lambda = {CURVES[c]['reuse_lambda']:g}" for c in LEAN if c in below.index)
    balance = m["balance"]
    level = next(lv for lv in balance.levels if lv.stat == "final")
    j = m["faster"]
    return (f"On the mazes (Section 6.1; {claims.budget_share(j.figure.id, None, j.budget, j.seeds_on_disk)}), the "
            f"paper's claim that OAPPO converges faster than HAPPO is {faster.status} "
            f"on {len(faster.robustness.seeds)} seeds (P(faster) {words.short(faster.estimates[0].interval)}). Reuse "
            f"helped the agents reach the optimum: on {m['n']} generated layouts (notebook 16) OAPPO (lambda = 0.7) ended below 95% of "
            f"the optimum on {b('oappo')} runs against HAPPO's {b('happo')}, since a moderate share of the peer's "
            f"experience carried the runs HAPPO lost to exploration. Leaning on the peer trapped them ({lean}); on "
            f"Black-Red (notebook 12), lambda = 0.4 ended at {level.interval.point:.3f} of the optimum (IQM over {level.seeds} seeds, "
            f"{level.reached} of which reached 95%), so the paper's \"lambda = 0.4 strikes a balance\" is "
            f"{balance.status} here: below lambda = 1/2 a learner's update weighs its peer's experience above its own.")


def _smax(judged) -> dict:
    heads = [v for j, v in headline_verdicts(judged) if j.figure.id == "fig4_smax"]
    decided = [v for v in heads if v.status in DECIDED]
    return {"heads": heads, "decided": decided, "held": [v for v in decided if v.held],
            "contradicted": [v for v in decided if v.status == Status.CONTRADICTED]}


def _share(figure: str) -> str:
    fig = get_figure(figure)
    shares = [fig.budget("cpu", env).steps / fig.budget("paper", env).steps for env in fig.envs("cpu") or (None,)]
    low, high = (f"{100 * x:.3g}" for x in (min(shares), max(shares)))
    return f"{low}%" if low == high else f"{low}-{high}%"


def dose(judged, figure: str) -> dict:
    """A dose-response's selection verdicts on the final value, with the ablation's median-sigma
    verdict beside them (the dose figure leaves it to the ablation): the sigmas that selected, and
    those whose gate never shut on any seed (their runs are always-on reuse)."""
    vs = [v for v in _figure(judged, figure) if v.claim.test == "selects"]
    vs += [v for f in ABLATION for v in _figure(judged, f) if v.claim.test == "selects" and env_name(v) == env_name(vs[0])
           and v.claim.curves[0] == "oappo gated"] if vs else []
    return dose_of(vs, figure)


def dose_of(vs: list[Verdict], figure: str) -> dict:
    """``dose``'s summary of the selection verdicts ``vs`` (final value) of dose-response ``figure``."""
    sigma = lambda v: float(next(kw for label, kw in get_figure(v.figure).curves if label == v.claim.curves[0])["sigma"])  # noqa: E731
    return {"verdicts": sorted(vs, key=sigma), "sigmas": sorted(sigma(v) for v in vs),
            "planned": len(get_figure(figure).budget("cpu").seeds),
            "selected": [sigma(v) for v in vs if v.held], "testable": [v for v in vs if v.estimates],
            "never_shut": sorted(sigma(v) for v in vs if v.reuse and v.reuse[0].never_shut == v.reuse[0].seeds)}


def _finals(v: Verdict, named: bool = True) -> str:
    """A verdict's curves' final IQMs, "a 0.94 against b 0.98" (``named``) or "0.94 against 0.98"."""
    return " against ".join(f"{level.curve} " * named + f"{level.interval.point:.2f}"
                            for level in v.levels if level.stat == "final")


def reading(label) -> str:
    """OAPPO's reading of the networks in running text: "OAPPO with a net per agent"."""
    return figures.readings.READING_NAMES[label].replace(" (", " with ").rstrip(")")


def on_seeds(v: Verdict) -> str:
    """A verdict on a map in a sentence or two: the map (and whether the paper ran it), status,
    seeds, final values and whether one seed carries it; then how much the curve reused across
    networks, and whether its gate ever shut."""
    env = env_name(v)
    fig = get_figure(v.figure)
    share = fig.budget("cpu", v.claim.env).steps / fig.budget("paper", v.claim.env).steps
    text = (f"On {env} (at {100 * share:.3g}% of HARL's steps"
            f"{')' if env in figures.smax.PAPER_MAPS else '; a map the paper did not run)'}, {reading(v.claim.curves[0])} "
            f"was {v.status} on {len(v.robustness.seeds)} seeds ({_finals(v)}"
            + (", resting on one seed" if v.robustness.one_seed else "") + ").")
    if v.reuse:
        r = v.reuse[0]
        text += (" Its gate never shut: it reused across networks at every evaluation while it learned, so this was "
                 "reuse without selection." if r.while_learning >= 1 else
                 f" It reused across networks at {r.while_learning:.0%} of its evaluations while it learned.")
    return text


def other_readings(judged, head: Verdict) -> str:
    """The same claim on the same map under OAPPO's other readings of the networks, where they
    tested reuse (a reading whose seats share networks tests sharing and is left out)."""
    others = [v for v in _figure(judged, head.figure) if v.claim.env == head.claim.env and v.claim.test == head.claim.test
              and v.claim.curves[1:] == head.claim.curves[1:] and v.claim.curves[0] != head.claim.curves[0]
              and v.status not in MECHANISM and v.levels]
    return "".join(f" {reading(v.claim.curves[0])} was {v.status} there ({_finals(v, named=False)}"
                   + (", resting on one seed" if v.robustness.one_seed else "") + ")." for v in others)


HOMOGENEOUS = "6h_vs_8z"  # the paper's homogeneous SMAC map
COMPARED = {"stabler": "more stable than", "higher": "above", "faster": "faster than"}


def homogeneous(fig4: list[Verdict]) -> str:
    """The paper's claims for OAPPO (a net per agent) on its homogeneous map, status by status,
    from Fig. 4's verdicts ``fig4``."""
    vs = [v for v in fig4 if env_name(v) == HOMOGENEOUS and v.claim.curves[0] == "oappo"]
    if not vs:
        return ""
    fig = get_figure(vs[0].figure)
    share = fig.budget("cpu", vs[0].claim.env).steps / fig.budget("paper", vs[0].claim.env).steps
    seeds = next((len(v.robustness.seeds) for v in vs if v.robustness), None)
    return (f" On {HOMOGENEOUS}, the paper's homogeneous map (at {100 * share:.3g}% of HARL's steps"
            + (f", {seeds} seeds" if seeds else "") + f"), the claims for {reading('oappo')} were judged: "
            + "; ".join(f"{COMPARED[v.claim.test]} {v.claim.curves[1].upper()}, {v.status}"
                        + (f" ({words.estimate(v.estimates[0])}" + (", resting on one seed" if v.one_seed else "") + ")"
                           if v.estimates else "") for v in vs)
            + ".")


def smax_sentence(judged) -> str:
    s = _smax(judged)
    ran = [v for v in s["heads"] if v.status != Status.NOT_RUN]
    unrun = [v for v in s["heads"] if v.status == Status.NOT_RUN]
    ablation = _figure(judged, "fig_selection_smax")
    ends = {env_name(v): v for v in ablation if v.claim.test == "selects"}
    reuse = [v for v in ablation if v.claim.test == "paired_higher" and v.claim.curves[0] == "oappo always" and v.held]
    top = ceiling("fig_selection_smax", "smax:6h_vs_8z")
    d = dose(judged, "fig_dose_smax")
    named = "; ".join(env_name(v) + ("" if env_name(v) in figures.smax.PAPER_MAPS else ", not a map of the paper")
                      for v in ran)
    text = (f"On SMAX (Section 6.2, notebook 20, at {_share('fig4_smax')} of HARL's steps), the paper's claim that "
            f"OAPPO ends above MAPPO on heterogeneous maps held on {len(s['held'])} of the {len(ran)} maps with runs "
            f"({named}); the 95% interval decided it on {len(s['decided'])}, "
            f"{len(s['contradicted'])} of them against the claim"
            + (f"; {', '.join(env_name(v) for v in unrun)} was not run" if unrun else "") + ". "
            + " ".join(on_seeds(v) + other_readings(judged, v) for v in s["heads"] if v.levels)
            + homogeneous(_figure(judged, "fig4_smax"))
            + " Plain parameter sharing was strong: MAPPO's final IQM was at or above HAPPO's on every map. "
            "In a seed-paired ablation, reuse across networks ended above no reuse on "
            + (", ".join(env_name(v) for v in reuse) or "no map") + ", but a KL gate ended above both no reuse and "
            f"always-on reuse on {sum(v.held for v in ends.values())} of {len(ends)} maps"
            + (f" (on 6h_vs_8z every run ended at a win rate of {top[0]:.2f}-{top[1]:.2f}, a ceiling)" if top else ""))
    if d["testable"]:
        text += " and " + dose_clause(d, "2s3z")
    return text + "."


def dose_clause(d: dict, where: str) -> str:
    """How many of a dose-response's sigmas selected (``dose``), on how many paired seeds, and
    from which sigma up the gate never shut."""
    seeds = min(v.estimates[0].seeds for v in d["testable"])
    within = sum(v.status == Status.WITHIN_NOISE for v in d["verdicts"])
    one = sum(v.one_seed for v in d["verdicts"])
    return (f"at {len(d['selected'])} of {len(d['sigmas'])} sigmas on {where} from {d['sigmas'][0]:g} to "
            f"{d['sigmas'][-1]:g} (on {seeds} of the {d['planned']} planned paired seeds"
            + (", provisional while the others train" if seeds < d["planned"] else "")
            + f"; {within} within noise" + (f"; {one} resting on one seed" if one else "")
            + (f"; from {d['never_shut'][0]:g} up the gate never shut: those runs are always-on reuse" if d["never_shut"]
               else "") + ")")


def _switch(judged) -> Verdict | None:
    return next((v for v in _figure(judged, "fig_selection_mamujoco") if v.claim.test == "selects"), None)


def mujoco_sentence(judged) -> str:
    head = next(v for j, v in headline_verdicts(judged) if j.figure.id == "figA_mamujoco")
    switch = _switch(judged)
    degrade = [v for v in _figure(judged, "figA_mamujoco") if v.claim.curves[0] == "happo"]
    always = {v.claim.test: v for v in _figure(judged, "fig_selection_mamujoco") if v.claim.curves == ("oappo always", "happo")}
    one = lambda v: ", resting on one seed" if v.robustness.one_seed else ""  # noqa: E731
    text = (f"On multi-agent MuJoCo (App. A, notebook 21, HalfCheetah 2x3, at {_share('figA_mamujoco')} of HARL's "
            f"steps), the paper's claim that {APP_A} is "
            + " and ".join(f"{v.status} for {v.claim.curves[1].upper()} on {len(v.robustness.seeds)} seeds "
                           f"({'; '.join(words.estimate(e) for e in v.estimates)}{one(v)})" for v in degrade)
            + f", and OAPPO's gated reuse, read strictly as ending above no reuse seed by seed, is {head.status} (IQM of "
            f"{head.estimates[0].seeds} paired differences {words.short(head.estimates[0].interval)}{one(head)})"
            + (f"; its gate (sigma {sigma_of(head):g}) gave the other leg weight at {r.overall:.0%} of its evaluations, so "
               "this compares reuse that was on most of the time with none" if (r := head.reuse_of("oappo")) is not None
               and r.overall > 0.5 else "") + ".")
    if always:
        level = get_figure("fig_selection_mamujoco").metric
        moved = {"paired_higher": ("ended {} no reuse on the final return", "above", "below"),
                 "faster": (f"reached {level.reach.format(level.threshold)} {{}} no reuse", "sooner than", "later than")}
        text += (" In the seed-paired ablation on the stronger, normalised learner, always-on reuse across the two legs "
                 + " and ".join(moved[v.claim.test][0].format(direction(v, *moved[v.claim.test][1:]))
                                + f" ({'P(faster) ' if v.claim.test == 'faster' else ''}"
                                f"{words.short(v.estimates[0].interval)} over {v.estimates[0].seeds} paired seeds{one(v)}"
                                + ("" if v.status in DECIDED else "; by its point estimate only") + ")"
                                for v in always.values()))
        slower = always.get("faster")
        if slower is not None and slower.status == Status.CONTRADICTED:
            text += ": " + app_a_reading(slower)
        text += "."
    if switch is not None and switch.status == Status.NO_SELECTION:
        gated = switch.estimates[1]
        text += (f" With one peer the gate is a switch: it shut for good by {switch.reuse[0].last_open / 1e3:,.0f}k "
                 f"steps on every seed, beating always-on reuse ({gated.interval.point:+.0f}, {gated.higher_on} of "
                 f"{gated.seeds} seeds) only by turning reuse off.")
    d = dose(judged, "fig_dose_mamujoco")
    if d["testable"]:
        ends = always_vs_never("fig_dose_mamujoco")
        text += (" Where each leg's gate has three peers to choose between, a gate ended above both no reuse and "
                 "always-on reuse " + dose_clause(d, f"Ant 4x2 (at {_share('fig_dose_mamujoco')} of HARL's steps)")
                 + (f", and always-on reuse ended {ends}" if ends else "") + ".")
    return text


def sigma_of(v: Verdict) -> float:
    """The sigma of the first curve of ``v``'s claim, from its figure's config."""
    return float(dict(figures.figure_runs(v.figure, "cpu"))[v.claim.curves[0]].sigma)


def app_a_reading(v: Verdict) -> str:
    """A claim that always-on reuse beats no reuse, read against App. A's claim (reuse degrades):
    where it went App. A's way, how firmly (wholly, or by the point estimate only; the seeds whose
    removal would move the interval); empty where it did not go that way."""
    if v.status not in (Status.NOT, Status.CONTRADICTED):
        return ""
    how = "reuse slowing the legs down" if v.claim.test == "faster" else "reuse lowering the return"
    if v.status == Status.NOT:
        return f"App. A's direction, {how}, by the point estimate only"
    line = 0.5 if v.estimates[0].kind == "improvement" else 0
    return (f"what App. A's claim predicts, {how}"
            + (f", though without any one of {len(v.robustness.flips)} seed{'s' * (len(v.robustness.flips) > 1)} the "
               f"interval reaches {line:g}" if v.robustness.one_seed else ""))


def direction(v: Verdict, more: str, less: str) -> str:
    """Which way a verdict's curve moved against the other, by the side its point estimate is on:
    ``more`` (the claim's side) or ``less``; whether its interval is wholly there is the status's."""
    return more if v.status in (Status.REPRODUCED, Status.WITHIN_NOISE) else less


def always_vs_never(figure: str) -> str:
    """Always-on reuse against no reuse in a dose-response's runs: which side of no reuse it
    ended on (where the interval says), the IQM of the paired differences and the seeds."""
    fig = get_figure(figure)
    df = experiments.read_figure(figure, "cpu", skip_missing=True)[0]
    if df.empty or not {"oappo always", "happo"} <= set(df["label"]):
        return ""
    ev = Evidence(df, fig.metric)
    d, pairs = ev.paired("oappo always", "happo"), ev.pairs("oappo always", "happo")
    side = "below" if d.high < 0 else "above" if d.low > 0 else "within noise of"
    return (f"{side} no reuse there ({words.short(d)}, higher on {int((pairs['difference'] > 0).sum())} of "
            f"{len(pairs)} paired seeds)")


# what a figure's envs are, in the paper's words (a sentence names them with these)
KINDS = {"fig4_smax": "heterogeneous SMAC map (here SMAX's stand-in for MMM2)", "fig6b": "football academy scenarios"}


def unrun_sentence(judged) -> str:
    never = [j for j in judged if j.lead.status == Status.NOT_RUN]
    if not never:
        return "The table below says claim by claim what held."
    by = {}
    for j in never:
        by.setdefault(j.figure.id, []).append(env_name(j.lead))
    parts = []
    for f, envs in by.items():
        fig = get_figure(f)
        price = costs.plan("paper", figures=(f,), from_nothing=True, envs={j.lead.claim.env for j in never})[0][0]
        priced = price.runs - price.unpriced
        parts.append(f"Section {fig.section}'s {KINDS.get(f, 'envs')} {', '.join(dict.fromkeys(envs))} (notebook "
                     f"{fig.notebook[:2]}; " + (f"at least {price.cpu_hours:,.0f} CPU hours for the {priced} of "
                                                f"{price.runs} runs with a measured price" if price.unpriced else
                                                f"about {price.cpu_hours:,.0f} CPU hours for its {price.runs} runs") + ")")
    return (f"Never run, and priced at their `paper` budgets: {'; '.join(parts)}" + untested_clause(judged)
            + ". The table below says claim by claim what held.")


def untested_clause(judged) -> str:
    """The figures' envs that ran and whose every claim found a curve that did not learn."""
    by = {}
    for j in judged:
        if j.figure.id in KINDS:
            by.setdefault((j.figure.id, j.lead.claim.env), []).append(j)
    idle = [(f, js) for (f, env), js in by.items() if all(j.lead.status == Status.NOT_TESTABLE and j.lead.gap.kind ==
                                                           "learned" for j in js)]
    return "".join(
        f". Section {js[0].lead.section}'s {env_name(js[0].lead)} ran at "
        f"{claims.budget_share(f, js[0].lead.claim.env, js[0].budget, js[0].seeds_on_disk)} and tested nothing: "
        + " and ".join(sorted({n.curve for j in js for n in j.lead.gap.not_learned})) + " did not learn"
        for f, js in idle)


def opening(judged: list[verdicts.Judged] | None = None) -> str:
    """The README's opening: the theory, one paragraph per engine family and one on what was never run."""
    judged = verdicts.glance() if judged is None else judged
    return "\n\n".join([THEORY, maze_sentence(judged), smax_sentence(judged), mujoco_sentence(judged),
                        unrun_sentence(judged)])


def headlines(judged: list[verdicts.Judged] | None = None) -> str:
    """The paper's headline claims, one line each: where the claim is from (and where it is our
    reading or our map), its budget and seeds, the verdict, and the first budget's verdict where
    the lead one is the 20-seed budget's and differs."""
    judged = verdicts.glance() if judged is None else judged
    lines = []
    for j in judged:
        v = j.lead
        own = j.figure.id == "figA_mamujoco" and v.claim.curves[0] == "happo"  # App. A's words: direct reuse degrades
        homogeneous_map = (j.figure.id == "fig4_smax" and env_name(v) == HOMOGENEOUS and v.claim.test == "higher"
                           and v.claim.curves == ("oappo", "mappo"))  # "superior outcomes compared to MAPPO"
        if not (v.claim.headline or own or homogeneous_map):
            continue
        where = f"Section {j.figure.section}"
        if own:
            where += "; App. A's own claim"
        elif j.figure.id == "figA_mamujoco":
            where += f"; our strict reading for OAPPO, where App. A's own claim is that {APP_A}"
        elif homogeneous_map:
            where += "; the paper's homogeneous map"
        elif j.figure.id == "fig4_smax" and env_name(v) not in figures.smax.PAPER_MAPS:
            where += "; a map the paper did not run"
        if v.status != Status.NOT_RUN:
            where += "; " + claims.budget_share(j.figure, v.claim.env, j.budget, j.seeds_on_disk)
        lines.append(f"- {v.claim.text} ({where}): **{v.status}**"
                     + (f", {words.lead_estimate(v)}" if v.estimates else f" ({words.reason(v)})")
                     + (f" ({v.metric.final})" if v.estimates and v.estimates[0].kind == "level" else "")
                     + (f"; {words.robustness(v)}" if v.one_seed else "")
                     + (f"; at {len(j.first.robustness.seeds)} seeds: {j.first.status}"
                        if j.first is not None and j.first.status != v.status else ""))
    return "\n".join(lines)


def draw_sentence() -> str:
    """What Algorithm 1's one-source draw did against Eq. 8's weights, per env."""
    pairs = draw_pairs()
    always = pairs[pairs["weights"] == "oappo always"]
    if always.empty:
        return ""
    parts = [f"{row['env'].partition(':')[2]} {row['sampled minus weights']:+.3g} [{row['low']:.3g}, {row['high']:.3g}] "
             f"(sampled higher on {row['sampled higher']} of {row['pairs']} seeds)" for _, row in always.iterrows()]
    why = draw_why()
    return ("Every curve above weighs its sources by M, as Eq. 8 does. In the seed-paired ablations (notebooks 20 "
            "and 21, at the ablations' budgets), with the gate always open, Algorithm 1's draw (one source per learner "
            "and iteration) against Eq. 8's weights, final value sampled minus weights, IQM of paired seeds: "
            + "; ".join(parts) + "."
            + (f" Why the draw failed on 2s3z: {why}." if why else ""))


def draw_why() -> str:
    """Why Algorithm 1's draw failed on 2s3z (``selection.draw_probe``), as a clause; empty
    where the probe's files are not on disk."""
    p = selection.draw_probe()
    if p is None:
        return ""
    return (f"in seed 10's probe (notebook 20) the updates that drew a peer were {p['peer']:.0%} of all and carried {p['carried']:.0%} "
            "of the acting policies' move, since nothing in such a learner's loss holds its own seat; with its own seat "
            f"kept beside the drawn peer the run's last 11 evaluations won {p['anchored']:.2f} against the draw's "
            f"{p['sampled']:.2f}")


def cost_sentence() -> str:
    """Per env: did reuse reach the ablation's level in fewer CPU seconds than HAPPO, where the two
    were measured side by side."""
    parts = []
    for figure in ABLATION:
        table = compute(figure)
        level = get_figure(figure).metric
        for env, part in table.groupby("env", sort=False):
            part = part.set_index("label")
            if "happo" not in part.index or np.isnan(part.loc["happo", "cpu_s"]):
                continue
            rows = [(label, r) for label, r in part.iterrows() if label != "happo" and "sampled" not in label]
            said = [f"{label} {r['cpu_s']:.0f}" for label, r in rows if r["side_by_side"] and not np.isnan(r["cpu_s"])]
            apart = [label for label, r in rows if not r["side_by_side"]]
            paid = [label for label, r in rows if r["side_by_side"] and r["cpu_s"] < part.loc["happo", "cpu_s"]]
            parts.append(f"{env.partition(':')[2]} (to {level.reach.format(level.threshold)}): HAPPO "
                         f"{part.loc['happo', 'cpu_s']:.0f}, " + ", ".join(said) + " CPU seconds; reuse "
                         + (f"reached it on fewer CPU seconds than HAPPO, by the median alone, with {', '.join(paid)}"
                            if paid else "reached it on no fewer CPU seconds than HAPPO")
                         + (f" ({', '.join(apart)}: measured at other revisions than HAPPO, left out)" if apart else ""))
    return ("What reuse costs, from the runs' own records (notebooks 20 and 21; the median over seeds of the CPU seconds spent when a "
            "curve's IQM first reached the level; without an interval, a reading rather than a verdict): "
            + "; ".join(parts) + ".") if parts else ""


THEORY = (
    "The theory, checked exactly on small games (notebooks 01-05): Eq. 1 is exact only with the new policy's state "
    "distribution; Proposition 1 holds with a correction (with its \"-1\" the right side is the local increment of the "
    "multi-agent advantage decomposition, which has the same maximiser); Lemma 1 as printed is not a bound and needs "
    "three corrections (the left side is the mean return of the permuted joint policies, the surrogate must be the "
    "local increments, the KL must compare what sits in a seat before and after), after which it is TRPO's bound for "
    "each permuted policy, and at gamma = 0.99 its constant C = 4 gamma eps / (1 - gamma)^2 = 39,600 eps makes it "
    "vacuous at every step the algorithms take; Eq. 8 as printed (the clip on the ratio before the advantage "
    "multiplies it) is optimistic where the advantage is negative, so the package uses PPO's pessimistic min.")


def findings(judged: list[verdicts.Judged] | None = None) -> list[str]:
    """The conclusion, one paragraph per finding, every number from the data."""
    judged = verdicts.glance() if judged is None else judged
    out = ["What the paper claims: agents that update one after another (HAPPO's scheme) and also learn from another "
           "agent's experience while their policies are within KL sigma (Eq. 9) learn faster than agents that use only "
           "their own experience, and avoid the local optima that full parameter sharing (MAPPO) falls into.",
           THEORY, maze_sentence(judged), smax_sentence(judged), mujoco_sentence(judged)]
    out += [s for s in (draw_sentence(), cost_sentence()) if s]
    out.append(unrun_sentence(judged))
    return out


BEGIN, END = "<!-- opening: generated by python -m oapo_lite.study.report.conclusion -->", "<!-- end of opening -->"
HEADLINES = ("<!-- headlines: generated by python -m oapo_lite.study.report.conclusion -->", "<!-- end of headlines -->")


def write_readme(path=readme.README) -> None:
    """Replace the README's opening, headline claims and claims table with what the data gives."""
    judged = verdicts.glance()
    readme.rewrite(claims.BEGIN, claims.END, claims.readme_markdown(claims.glance_table(judged)), path)
    readme.rewrite(BEGIN, END, opening(judged), path)
    readme.rewrite(*HEADLINES, headlines(judged), path)


if __name__ == "__main__":
    write_readme()
    print(f"wrote the opening, the headline claims and the claims table into {readme.README}", file=sys.stderr)
