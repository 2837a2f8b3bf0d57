"""Why Algorithm 1's draw with the gate always open fails on 2s3z and not on HalfCheetah 2x3
(issue 52, part 4): one learner's batch and loss followed through every update of a run.

A run of ``fig_selection_smax``'s "oappo always sampled" curve (reuse_mode="sample", sigma=inf,
the mean gate; seed 10 unless told) is trained again with a probe around ``ppo_family.ppo_update``,
so that the run is the committed one, bit for bit (the script checks its evaluation rows against
the committed file). For every iteration and learner the probe records:

- the drawn source (a learner's own seat, a peer of its unit type, or a peer of the other type:
  2s3z has 2 stalkers and 3 zealots) and the learner's place in the update order;
- on the source's samples, before the first Adam step: KL(pi_j || pi_i) on o_j, the share of
  the off-agent ratios pi_i(a_j|o_j) / pi_j(a_j|o_j) already outside [1 - clip, 1 + clip], and the
  share whose clipped term has no gradient (ratio past the clip on the side the advantage pushes);
- on the learner's OWN samples, after its update: the exact KL(pi_old || pi_new), the share of
  its own actions' ratios outside the clip range and their 1st-99th percentile range: how far the
  policy that acts moved where nothing in its loss held it;
- the sequential factor rho each learner receives, and the factor after it (its 1st and 99th
  percentile over the joint samples);
- alignment checks for a defect: the learner's own-seat ratio is 1 before its update, and a source
  seat whose network has not moved yet this iteration reproduces its stored behaviour log-probs
  (so actions, observations, masks and log-probs of the drawn seat line up), and the draws'
  frequencies match M's rows.

It also records the own seat's surrogate gain, the mean of (r - 1) rho A over the learner's own
samples after its update: the estimate of what the move did for the seat its network acts in.

The same probe runs on the paired "oappo always" run (Eq. 8's weights), where a learner has every
seat at once (its own at 0.7). Three controls then separate the mechanism's parts, on the same
seed (diagnostics patched in here, not readings of the paper): the same draws with the learner's
own seat kept at weight 0.7 beside the drawn peer (0.3), so that its own samples stay in its
clipped loss; the draw with the factor left unchanged by a learner that drew a peer; and the draw
restricted to the learner's own unit type (``allowed``: stalkers draw stalkers, zealots zealots).
Last, HalfCheetah 2x3's "oappo always sampled" (fig_selection_mamujoco) with the same probe. The
tables print medians and, in brackets, 90th percentiles (10th for the quantities that fall)
over a run's updates.

    .venv/bin/python benchmarks/draw_collapse.py [--seed 10] [--save DIR]
        [--only sampled weights anchored frozen-factor same-type cheetah]

A 2s3z run of 1M steps costs 3-5 CPU minutes with the probe, HalfCheetah about as much.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout's package, not an installed one

from oapo_lite.envs.registry import agent_types
from oapo_lite.neural import ppo_family
from oapo_lite.neural.ppo_family import learner_dists
from oapo_lite.neural.train import train
from oapo_lite.study.runs.experiments import read_run
from oapo_lite.study.catalogue.figures import runs_of


def figure_cfg(figure: str, label: str, seed: int):
    """The committed run's config of ``label`` on ``figure``'s first env (2s3z / HalfCheetah)."""
    runs = [r for r in runs_of(figure, "cpu") if r.label == label and r.cfg.seed == seed]
    env = runs[0].cfg.env if figure != "fig_selection_smax" else "smax:2s3z"
    return [r.cfg for r in runs if r.cfg.env == env][0]


def _mean(x: torch.Tensor, active: torch.Tensor | None) -> float:
    return (x.mean() if active is None else x[active].mean()).item() if (active is None or active.any()) else np.nan


def _pick(x: torch.Tensor, active: torch.Tensor | None) -> torch.Tensor:
    return x.reshape(-1) if active is None else x[active]


class Probe:
    """Records what ``ppo_family.ppo_update`` does to every learner (see the module's text).
    ``freeze_after_peer``: a learner that drew a peer leaves the factor as it found it;
    ``anchor``: a learner that drew a peer keeps its own seat at this weight (the peer gets the
    rest), the draws being the same as without it (the generator is used alike)."""

    def __init__(self, types: tuple[str, ...], freeze_after_peer: bool = False, anchor: float | None = None):
        self.types, self.freeze, self.anchor = types, freeze_after_peer, anchor
        self.rows: list[dict] = []
        self.pending: list[dict] = []
        self.moved: set[int] = set()
        self.returns: dict[int, float] = {}
        self.align: list[float] = []  # max |log pi_j(a_j|o_j) - stored log-prob| of unmoved source nets
        self.wants = frozenset()

    def __call__(self, iteration: int, update) -> None:  # ``learner.Observer``: after each iteration
        for k, r in enumerate(self.pending):
            r.update(it=iteration, pos=k)
        self.rows += self.pending
        self.pending, self.moved = [], set()
        self.returns[iteration] = update.metrics["train_return"]

    @contextlib.contextmanager
    def patched(self):
        original_update, original_factor = ppo_family.ppo_update, ppo_family.update_factor
        original_units = ppo_family.update_units
        probe = self

        def update_units(W, owner, by):
            if probe.anchor is not None:
                drew_peer = np.diag(W) == 0
                W = np.where(drew_peer[:, None], (1 - probe.anchor) * W + probe.anchor * np.eye(len(W)), W)
            return original_units(W, owner, by)

        def ppo_update(actors, opt, inputs, src, factor, adv, cfg, rng):
            head, clip = actors.head, cfg.clip
            with torch.no_grad():
                d0 = learner_dists(actors, inputs, src)
                lp0 = head.log_prob(d0, src.act)
            out = original_update(actors, opt, inputs, src, factor, adv, cfg, rng)
            with torch.no_grad():
                d1 = learner_dists(actors, inputs, src)
                lp1 = head.log_prob(d1, src.act)
                probe.pending.append(probe.measure(actors, inputs, src, factor, adv, clip, d0, lp0, d1, lp1))
            probe.moved.add(src.net)
            return out

        def update_factor(factor, logp_new_own, logp_old_own, active_own=None):
            if probe.freeze and probe.pending and probe.pending[-1]["peer"]:
                return factor
            return original_factor(factor, logp_new_own, logp_old_own, active_own)

        ppo_family.ppo_update, ppo_family.update_factor, ppo_family.update_units = (ppo_update, update_factor,
                                                                                   update_units)
        try:
            yield self
        finally:
            ppo_family.ppo_update, ppo_family.update_factor = original_update, original_factor
            ppo_family.update_units = original_units

    def measure(self, actors, inputs, src, factor, adv, clip, d0, lp0, d1, lp1) -> dict:
        head, i = actors.head, src.net  # a net per agent: net i is seat i
        (o,) = src.own
        act = (lambda r: None) if src.active is None else (lambda r: src.active[r])
        own_start = _pick((lp0[o] - src.logp_old[o]).abs(), act(o))
        logr = lp1[o] - src.logp_old[o]
        own_logr = _pick(logr, act(o))
        log_f = factor.log()
        after = log_f + (logr if src.active is None else torch.where(src.active[o], logr, 0.0))
        scaled = factor * adv
        rec = {"learner": i, "own_start_dev": own_start.max().item() if len(own_start) else 0.0,
               "own_kl": _mean(head.kl(d0[o], d1[o]), act(o)),
               "own_clip": _mean(((logr.exp() - 1).abs() > clip).float(), act(o)),
               "own_logr_lo": own_logr.quantile(0.01).item(), "own_logr_hi": own_logr.quantile(0.99).item(),
               # the own seat's surrogate gain, the estimate of what the move did for the seat it acts in
               "own_gain": _mean((logr.exp() - 1) * scaled, act(o)),
               "f_in_lo": log_f.quantile(0.01).item(), "f_in_hi": log_f.quantile(0.99).item(),
               "f_out_lo": after.quantile(0.01).item(), "f_out_hi": after.quantile(0.99).item()}
        peers = [(r, j) for r, j in enumerate(src.rows) if j != i and src.w[r] > 0]
        rec["source"] = peers[0][1] if len(peers) == 1 and (src.w[o] == 0 or self.anchor) else (i if not peers else -1)
        rec["peer"] = rec["source"] not in (i, -1)
        rec["cross"] = rec["peer"] and self.types[rec["source"]] != self.types[i]
        for kind, keep in (("same", lambda j: self.types[j] == self.types[i]),
                           ("cross", lambda j: self.types[j] != self.types[i])):
            stats = []
            for r, j in peers:
                if not keep(j):
                    continue
                a = act(r)
                with torch.no_grad():
                    used, inverse = torch.unique(inputs.index[j], return_inverse=True)
                    dj = actors(inputs.obs[used].unsqueeze(0), [j], inputs.avail[used].unsqueeze(0))[0][inverse]
                if j not in self.moved:  # net j still acts as it did in the rollout
                    self.align.append(_pick((head.log_prob(dj, src.act[r]) - src.logp_old[r]).abs(), a).max().item())
                ratio0, ratio1 = (lp0[r] - src.logp_old[r]).exp(), (lp1[r] - src.logp_old[r]).exp()
                flat = ((scaled > 0) & (ratio0 > 1 + clip)) | ((scaled < 0) & (ratio0 < 1 - clip))
                stats.append([_mean(head.kl(dj, d0[r]), a), _mean(((ratio0 - 1).abs() > clip).float(), a),
                              _mean(flat.float(), a), _mean(((ratio1 - 1).abs() > clip).float(), a),
                              _mean(head.kl(dj, d1[r]), a)])
            if stats:
                s = np.nanmean(np.array(stats), 0)
                rec.update({f"{kind}_K0": s[0], f"{kind}_out0": s[1], f"{kind}_flat0": s[2], f"{kind}_out1": s[3],
                            f"{kind}_K1": s[4]})
        if self.freeze and rec["peer"]:  # the factor this learner passes on is the one it received
            rec["f_out_lo"], rec["f_out_hi"] = rec["f_in_lo"], rec["f_in_hi"]
        return rec

    def frame(self) -> pd.DataFrame:
        return pd.DataFrame(self.rows)


def run(cfg, probe: Probe, check: bool) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Train ``cfg`` with ``probe``; with ``check``, the evaluation rows must be the committed run's."""
    if cfg.networks_used != "agent" or cfg.update_by != "net" or cfg.algo != "oappo":
        raise ValueError("the probe reads net i as seat i's: OAPPO with a net per agent only")
    with tempfile.TemporaryDirectory() as out, probe.patched():
        rows = train(cfg, out, resume=False, progress=False, observer=probe)
    if check:
        committed = read_run(cfg, "cpu")
        same = np.allclose(committed["eval_success" if cfg.env.startswith("smax") else "eval_return"].values,
                           rows["eval_success" if cfg.env.startswith("smax") else "eval_return"].values)
        print(f"  the probed run reproduces the committed evaluation rows: {same}")
    return probe.frame(), rows


def q(x: pd.Series, p: float = 0.5) -> float:
    x = x.dropna()
    return float(x.quantile(p)) if len(x) else np.nan


def kind_of(df: pd.DataFrame, sampled: bool) -> pd.Series:
    if not sampled:
        return pd.Series("weights (all seats)", index=df.index)
    return np.where(~df.peer, "drew itself", np.where(df.cross, "drew other type", "drew own type"))


def expected_draws(types: tuple[str, ...], allowed: np.ndarray | None, lam: float) -> tuple[float, float]:
    """The shares of draws of a peer of the learner's type and of another type that M's rows give
    with the gate always open (sigma = inf: every allowed peer at (1 - lambda) / their count)."""
    n = len(types)
    ok = np.ones((n, n), bool) if allowed is None else np.asarray(allowed, bool)
    same = other = 0.0
    for i in range(n):
        peers = [j for j in range(n) if j != i and ok[i, j]]
        same += (1 - lam) * sum(types[j] == types[i] for j in peers) / len(peers) / n
        other += (1 - lam) * sum(types[j] != types[i] for j in peers) / len(peers) / n
    return same, other


def report(name: str, df: pd.DataFrame, rows: pd.DataFrame, probe: Probe, sampled: bool, M_row: float = 0.7,
           allowed: np.ndarray | None = None) -> dict:
    df = df.assign(kind=kind_of(df, sampled))
    score = "eval_success" if rows.eval_success.notna().all() else "eval_return"
    print(f"\n== {name}: {df.it.max()} iterations, {len(df)} updates; final evaluation {rows[score].iloc[-1]:.3f}")
    print(f"  own-seat ratio before the update: max |log r| {df.own_start_dev.max():.2e}; source net not moved "
          f"yet reproduces its stored log-probs: max |diff| {max(probe.align, default=np.nan):.2e} "
          f"({len(probe.align)} checks)")
    if sampled:
        own = (~df.peer).mean()
        same, other = expected_draws(probe.types, allowed, M_row)
        print(f"  draws: own seat {own:.3f} (M: {M_row}), peer of own type {(df.peer & ~df.cross).mean():.3f} "
              f"(M: {same:.3f}), other type {df.cross.mean():.3f} (M: {other:.3f}); iterations with >= 1 "
              f"other-type draw {df.groupby('it').cross.any().mean():.3f}")
    print("  per update, median [90th pct]:")
    cols = [("own KL(old||new)", "own_kl", 0.9), ("own clip frac", "own_clip", 0.9),
            ("own log r 1st pct", "own_logr_lo", 0.1), ("own log r 99th pct", "own_logr_hi", 0.9),
            ("own surrogate gain", "own_gain", 0.1)]
    print(f"  {'':22s}{'n':>6s}" + "".join(f"{c[0]:>22s}" for c in cols))
    for kind, g in df.groupby("kind"):
        print(f"  {kind:22s}{len(g):6d}" + "".join(f"{q(g[c]):10.3f} [{q(g[c], p):8.3f}]" for _, c, p in cols))
    print("  the source's samples before the first step (peer sources only), median [90th pct]:")
    src_cols = [("K0=KL(pj||pi) on o_j", "K0"), ("ratio out of clip", "out0"), ("no gradient", "flat0"),
                ("out of clip after", "out1"), ("K after", "K1")]
    print(f"  {'':22s}" + "".join(f"{c[0]:>22s}" for c in src_cols))
    for kind in ("same", "cross"):
        g = df[df.kind.isin(("drew own type",) if kind == "same" else ("drew other type",))] if sampled else df
        if f"{kind}_K0" not in g or g[f"{kind}_K0"].notna().sum() == 0:
            continue
        print(f"  {kind + ' type peer':22s}" + "".join(f"{q(g[f'{kind}_{c}']):10.3f} [{q(g[f'{kind}_{c}'], 0.9):8.3f}]"
                                                       for _, c in src_cols))
    if sampled and df.peer.any():
        # what sets the size of a peer-drawn move: how far the learner was from the source on o_j
        peer = df[df.peer].copy()
        peer["K0"] = peer.get("same_K0", pd.Series(np.nan, index=peer.index)).fillna(
            peer.get("cross_K0", pd.Series(np.nan, index=peer.index)))
        rho = peer[["K0", "own_kl"]].corr(method="spearman").iloc[0, 1]
        print(f"  peer-drawn updates by K0 (Spearman(K0, own KL) {rho:+.2f}; K0 > 0.1 on {(peer.K0 > 0.1).mean():.3f}, "
              f"> 0.2 on {(peer.K0 > 0.2).mean():.3f}): median own KL / mean own surrogate gain / count")
        peer["K0 bin"] = pd.cut(peer.K0, [0, 0.05, 0.1, 0.2, 0.4, np.inf])
        for (b, kind), g in peer.groupby(["K0 bin", "kind"], observed=True):
            print(f"    K0 in {str(b):14s} {kind:16s} {q(g.own_kl):7.3f} {g.own_gain.mean():+8.4f} {len(g):5d}")
        third = np.array_split(np.sort(df.it.unique()), 3)
        print("  median K0 of the peer draws by third of the run: " + ", ".join(
            f"iterations {t[0]}-{t[-1]} {q(peer[peer.it.isin(t)].K0):.3f}" for t in third))
    # the factor after each update, and what the learners after it receive
    df["f_out_span"] = df.f_out_hi - df.f_out_lo
    df["f_in_span"] = df.f_in_hi - df.f_in_lo
    print("  factor rho after the update, log 1st..99th pct span, median [90th pct]:")
    for kind, g in df.groupby("kind"):
        contrib = (g.f_out_span - g.f_in_span)
        print(f"  {kind:22s} span after {q(g.f_out_span):7.3f} [{q(g.f_out_span, 0.9):7.3f}]   "
              f"rho 1st..99th pct exp: {np.exp(q(g.f_out_lo)):.3f}..{np.exp(q(g.f_out_hi)):.3f}   span added "
              f"{q(contrib):7.3f}")
    print(f"  share of the acting policies' own-seat KL travelled in peer-drawn updates "
          f"{df[df.peer].own_kl.sum() / df.own_kl.sum():.3f}; mean own KL per update {df.own_kl.mean():.4f}")
    if sampled:
        first_peer = df[df.peer].groupby("it").pos.min()
        df["after_peer"] = df.pos > df.it.map(first_peer).fillna(99)
        late = df[(df.pos >= 1) & ~df.peer]
        print("  self-drawn learners in place >= 2 of the order, by whether an earlier learner drew a peer:")
        for flag, g in late.groupby("after_peer"):
            print(f"    {'after a peer draw' if flag else 'no peer draw before':28s} n {len(g):5d}  "
                  f"rho received: exp span {np.exp(q(g.f_in_span)):7.2f}x [{np.exp(q(g.f_in_span, 0.9)):8.2f}x]   "
                  f"own KL {q(g.own_kl):.3f} [{q(g.own_kl, 0.9):.3f}]  own clip {q(g.own_clip):.3f}")
    # learning: the return of the next batch against the draws of this update
    ret = pd.Series(probe.returns).sort_index()
    step = ret.shift(-1) - ret  # train_return of iteration it is the batch before update it
    per_it = df.groupby("it").agg(cross=("cross", "sum"), own_kl=("own_kl", "max"))
    per_it["d_return"] = step.reindex(per_it.index)
    if sampled and per_it.d_return.notna().sum() > 10:
        print("  the next batch's train return minus this one's, by the update's other-type draws:")
        for c, g in per_it.groupby(per_it.cross.clip(upper=3)):
            print(f"    {int(c)}{'+' if c == 3 else ' '} other-type draws: {len(g):4d} iterations, mean change "
                  f"{g.d_return.mean():+.3f} (se {g.d_return.std() / np.sqrt(max(len(g), 1)):.3f})")
    if per_it.d_return.notna().sum() > 10:
        corr = per_it[["own_kl", "d_return"]].dropna().corr(method="spearman").iloc[0, 1]
        print(f"  Spearman(largest own KL in the update, next change in train return) {corr:+.3f}")
    if sampled and "eval_success" in rows and rows.eval_success.notna().all():
        # between evaluations (every 10 iterations): the peer draws against the change in win rate
        at = rows.iteration.tolist()
        peers = [df[(df.it > a) & (df.it <= b)].peer.sum() for a, b in zip(at[:-1], at[1:])]
        change = np.diff(rows.eval_success.values)
        rho = pd.Series(peers).corr(pd.Series(change), method="spearman")
        print(f"  between evaluations: Spearman(peer draws, change in win rate) {rho:+.3f} over {len(peers)} windows")
    return {"rows": rows, "df": df}


def keep(folder: str | None, key: str, df: pd.DataFrame, rows: pd.DataFrame, probe: Probe) -> None:
    if folder is not None:
        Path(folder).mkdir(parents=True, exist_ok=True)
        df.to_csv(Path(folder) / f"{key}_updates.csv", index=False)
        rows.to_csv(Path(folder) / f"{key}_rows.csv", index=False)
        pd.Series(probe.returns).to_csv(Path(folder) / f"{key}_returns.csv")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=10)
    parser.add_argument("--only", nargs="*", default=["sampled", "weights", "anchored", "frozen-factor", "same-type",
                                                       "cheetah"])
    parser.add_argument("--steps", type=int, default=None, help="cut the runs short (no committed-rows check)")
    parser.add_argument("--save", default=None, help="a folder to keep each run's per-update records in (CSV)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    types = agent_types("smax:2s3z", 100)
    sampled = figure_cfg("fig_selection_smax", "oappo always sampled", args.seed)
    weights = figure_cfg("fig_selection_smax", "oappo always", args.seed)
    cut = (lambda c: dataclasses.replace(c, steps=args.steps)) if args.steps else (lambda c: c)
    print(f"2s3z seats {types}; sampled config: lr {sampled.lr}, {sampled.ppo_epochs} epochs x {sampled.n_minibatch} "
          f"minibatches, clip {sampled.clip}, entropy {sampled.entropy_coef}, grad norm {sampled.max_grad_norm}")
    same_type = np.equal.outer(np.array(types), np.array(types))
    plans = {
        "sampled": ("2s3z, Algorithm 1's draw (oappo always sampled)", sampled, {}, True),
        "weights": ("2s3z, Eq. 8's weights (oappo always)", weights, {}, False),
        "same-type": ("2s3z, the draw within the learner's unit type (control)", dataclasses.replace(
            sampled, allowed=same_type), {}, True),
        "frozen-factor": ("2s3z, the draw, factor untouched by a peer-drawn learner (control)", sampled,
                          {"freeze_after_peer": True}, True),
        "anchored": ("2s3z, the same draws, own seat kept at 0.7 beside a drawn peer (control)", sampled,
                     {"anchor": sampled.reuse_lambda}, True),
    }
    summary = {}
    for key in args.only:
        if key == "cheetah":
            continue
        name, cfg, kw, is_sampled = plans[key]
        probe = Probe(types, **kw)
        df, rows = run(cut(cfg), probe, check=args.steps is None and key in ("sampled", "weights"))
        summary[name] = report(name, df, rows, probe, is_sampled, cfg.reuse_lambda, cfg.allowed)
        keep(args.save, key, df, rows, probe)
    if "cheetah" in args.only:
        cfg = figure_cfg("fig_selection_mamujoco", "oappo always sampled", args.seed)
        ctypes = agent_types(cfg.env, cfg.max_steps)
        probe = Probe(ctypes)
        df, rows = run(cut(cfg), probe, check=args.steps is None)
        name = "HalfCheetah 2x3, Algorithm 1's draw"
        summary[name] = report(f"{name} (seats {ctypes})", df, rows, probe, True, cfg.reuse_lambda, cfg.allowed)
        keep(args.save, "cheetah", df, rows, probe)
    print("\nfinal evaluation per run:")
    for name, s in summary.items():
        r = s["rows"]
        score = "eval_success" if r.eval_success.notna().all() else "eval_return"
        print(f"  {name:72s} final {r[score].iloc[-1]:8.3f}, mean of the last 11 evaluations "
              f"{r[score].iloc[-11:].mean():8.3f} ({score})")


if __name__ == "__main__":
    main()
