"""The grid: how much a budget spends, and every figure the project reproduces as one entry
(``GRID``): its curves, its budgets, the measure its curves are judged on and the paper's
claims about it. A new figure is a new entry; ``runs_of`` turns an entry into training runs.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from oapo_lite.algorithms import ALGOS
from oapo_lite.neural.a2c_family import beside_ppo
from oapo_lite.neural.config import TrainConfig
from oapo_lite.reuse import KL_REDUCES, SCHEMES
from oapo_lite.study.verdicts import (FRAC_OPT, RETURN, SCORE, WIN_RATE, Metric, better, faster, higher, optimal,
                                      paired_higher, reliable, stabler, stuck)


@dataclass(frozen=True)
class Budget:
    """How much to spend on each curve of each figure."""

    seeds: tuple[int, ...]
    steps: int  # env steps per run
    eval_every: int  # iterations between evaluations
    eval_episodes: int
    config: dict = field(default_factory=dict)  # further TrainConfig fields (batch shape, episode length)
    figures: tuple[str, ...] | None = None  # the figures trained at this budget (None: every one)
    notebooks: tuple[str, ...] | None = None  # number prefixes of the notebooks run at it (None: all)


BUDGETS = {
    "smoke": Budget(seeds=(0,), steps=3_200, eval_every=1, eval_episodes=8),
    "paper": Budget(seeds=(0, 1, 2, 3, 4), steps=240_000, eval_every=2, eval_episodes=32),
    "paper20": Budget(seeds=tuple(range(20)), steps=240_000, eval_every=2, eval_episodes=32),
}
# "cpu": the largest budget this machine (2 cores) can honestly run. The mazes' paper scale
# fits a CPU, so for them it is the paper budget (same runs, same cache); the real engines
# override it per figure (``Figure.budgets``) with what fits in one or two hours.
BUDGETS["cpu"] = BUDGETS["paper"]
# "student": what a laptop runs in about five minutes and still shows the two findings to see
# with one's own eyes: MAPPO trapped at 0.216 on Black-Red while OAPPO reaches the optimum
# (Fig. 3b), and the lambda trap (Fig. 3d). By 120k steps every committed seed 0-2 is there.
BUDGETS["student"] = Budget(seeds=(0, 1, 2), steps=120_000, eval_every=2, eval_episodes=32,
                            figures=("fig3b", "fig3c", "fig3d"),
                            notebooks=("00", "01", "02", "03", "04", "05", "10", "11", "12"))
COMMITTED = ("paper", "cpu")  # the budgets whose figures and runs are committed under figures/
# paper20's figures go to figures/paper20/, but its runs share the committed cache: a run id
# hashes the run's whole config, so its seeds 0-4 are the paper budget's runs, trained once.
SHARED_RUNS = COMMITTED + ("paper20",)


def get_budget(name: str) -> Budget:
    if name not in BUDGETS:
        raise ValueError(f"unknown budget {name!r}; choose from {sorted(BUDGETS)}")
    return BUDGETS[name]


# Section 6.1's figures: which curves, with which settings.
SIGMAS = (0.01, 0.1, 1.0, 10.0)
LAMBDAS = (0.2, 0.4, 0.7, 1.0)
# Within a sharing group every member's experience weighs the same, as in MAPPO's M = 1/n:
# lambda = 1 / group size (NR's learners keep everything for themselves anyway).
SCHEME_LAM = {"NR": 1.0, "UR": 1 / 2, "RR": 1 / 2, "AR": 1 / 3}
BASELINE_ALGOS = ("seac", "seps", "mappo", "happo", "oappo")
MAZES = ("black_red", "black_blue_red")
ADAPTIVE_CURVES = (("oappo adaptive", dict(algo="oappo", reuse_adapt="gradient_test")),
                   ("oappo", dict(algo="oappo")), ("happo", dict(algo="happo")))


@dataclass(frozen=True)
class Figure:
    """The runs behind one figure, as data: every curve is trained on every seed of the budget.

    ``curves``: (label, TrainConfig fields of that curve); ``common``: fields every curve shares
    (env, batch shape, ...); ``seeds``: how many of the budget's seeds (None: all);
    ``budgets``: per-budget overrides of ``Budget`` fields for this figure (a real engine needs
    more env steps than a maze), e.g. ``{"paper": {"steps": 10_000_000}}``; under the key
    ``envs``, overrides for one env alone, and then only the curves on those envs run at that
    budget; ``runs_at``: the budgets the figure has runs at (None: every budget); ``cpus``,
    ``gpus``, ``memory_gb``: what one run asks a Ray cluster for. ``metric``: what its curves
    measure; ``claims``: the paper's claims about it, as (test, the curves it compares, the
    claim), judged by ``claims.judge``; with ``claims_per_env`` (the prefix of the ``env``
    column) each claim starts with the env it is judged on, on that env's runs alone.
    ``section`` and ``notebook``: where the paper and this repository show it; ``reference``:
    whose steps its ``paper`` budget is ("": the paper gives none, the budget is ours).
    """

    id: str
    curves: tuple[tuple[object, dict], ...]
    common: dict = field(default_factory=dict)
    seeds: int | None = None
    budgets: dict = field(default_factory=dict)
    runs_at: tuple[str, ...] | None = None
    cpus: float = 1.0
    gpus: float = 0.0
    memory_gb: float = 0.0
    metric: Metric = FRAC_OPT
    claims: tuple = ()
    claims_per_env: str | None = None
    section: str = ""
    notebook: str = ""
    reference: str = ""

    def budget(self, name: str, env: str | None = None) -> Budget:
        """This figure's budget ``name`` (for the curves on ``env``, if it has its own)."""
        own = dict(self.budgets.get(name, {}))
        envs = own.pop("envs", {})
        return replace(get_budget(name), **{**own, **envs.get(env, {})})

    def envs(self, name: str) -> tuple[str, ...] | None:
        """The envs this figure runs at budget ``name`` (None: every curve's)."""
        envs = self.budgets.get(name, {}).get("envs")
        return None if envs is None else tuple(envs)


# Fig. 4 (Section 6.2) on SMAX: 64 copies x 50 steps is HARL's batch of 20 threads x 160 steps
# (3,200 transitions).
SMAX_ALGOS = ("oappo", "oatrpo", "mappo", "happo", "seac", "seps")
SMAX_BATCH = dict(n_envs=64, rollout_len=50, max_steps=100, checkpoint_every=10)
# The settings of all six algorithms on every map, from the setting-by-setting comparison with
# JaxMARL's MAPPO (ASSUMPTIONS.md, SMAX section): a 4x larger constant learning rate, 4 epochs x 4
# minibatches (16 Adam steps a batch, not 5), no entropy bonus, a tight gradient-norm clip. MAPPO
# with them wins 0.77 on 3m at 300k steps and 0.97 on 2s3z at 500k (5 seeds), JaxMARL's MAPPO 0.72
# and 0.97, at a quarter of its CPU time per step; HARL's per-map settings (5-10 epochs at lr 5e-4)
# learned about 4x more slowly here. OATRPO uses critic_lr, epochs and minibatches for its critic;
# SEAC / SePS read only entropy_coef (their A2C settings are their own).
SMAX_TUNED = dict(lr=2e-3, critic_lr=2e-3, ppo_epochs=4, n_minibatch=4, entropy_coef=0.0, max_grad_norm=0.25)
# The anchor: JaxMARL's end-to-end jitted MAPPO (GRU) on the same scenarios and machine, as
# (env steps, win rate over its training episodes): 3m over 2 seeds, 2s3z over 5
# (benchmarks/smax_anchor.py is the recipe)
SMAX_ANCHOR = {"3m": (295_000, 0.72), "2s3z": (500_000, 0.97)}
# the small maps first (they learn within a CPU budget), then the paper's
FIG4_MAPS = ("3m", "2s3z", "6h_vs_8z", "3s5z_vs_3s6z", "MMM2_like_7m2M_vs_8m3M")
# the paper's heterogeneous maps are 3s5z_vs_3s6z and MMM2 (here its stand-in); 2s3z is
# heterogeneous too and small enough to learn on a CPU
SMAX_HETEROGENEOUS = ("2s3z", "3s5z_vs_3s6z", "MMM2_like_7m2M_vs_8m3M")


# App. A on multi-agent MuJoCo: no reuse (HAPPO), full sharing (MAPPO), gated reuse (OAPPO, per
# agent with the engines' mean gate, and one net seat by seat; per kind is per agent here, every
# leg being its own kind) and direct reuse (SEAC) on homogeneous agents. The PPO family runs 15
# epochs, HARL's setting that helped most in our loop (``fig_mamujoco_settings``, ASSUMPTIONS.md).
FIGA_CURVES = {"happo": dict(algo="happo"), "mappo": dict(algo="mappo"), "oappo": dict(algo="oappo", kl_reduce="mean"),
               "oappo one seat": dict(algo="oappo", networks="one", update_by="seat"), "seac": dict(algo="seac")}
FIGA_ALGOS = tuple(FIGA_CURVES)
HALFCHEETAH = "mamujoco:HalfCheetah-2x3"
# the cpu batch on HalfCheetah: 8 copies x 250 steps, MuJoCo's 1,000-step episodes
MAMUJOCO_CPU = dict(n_envs=8, rollout_len=250, max_steps=1000, checkpoint_every=10)
# HAPPO's settings and the one-agent control: App. A's cpu runs at 3 seeds
HALFCHEETAH_1M = dict(seeds=(0, 1, 2), steps=1_000_000, eval_every=20, eval_episodes=10, config=MAMUJOCO_CPU)
MAMUJOCO_SMOKE = dict(steps=200, eval_episodes=2, config=dict(n_envs=2, rollout_len=50, max_steps=100))
# Issue 31's closing table: OAPPO under each reading of the paper's networks and each statistic
# of Eq. 9's gate, beside HAPPO and MAPPO, at the cpu configs of Fig. 4 (seeds 0-2) and of the
# early-reuse figure. A reading or statistic that cannot change the run on a map is left out
# there: one net per kind is one net per agent where every seat is its own kind (HalfCheetah)
# and MAPPO where all are one kind (6h_vs_8z, as the tests pin on 3m); a network shared by every
# seat is at KL 0 from itself, so its gate never shuts and no statistic matters.
READING_ENVS = ("smax:2s3z", "smax:6h_vs_8z", HALFCHEETAH)


def _reading_curves(env: str) -> tuple:
    kinds = ("agent", "type") if env == "smax:2s3z" else ("agent",)
    return (("happo", dict(algo="happo", env=env)), ("mappo", dict(algo="mappo", env=env)),
            *((f"oappo {kind} {stat}", dict(algo="oappo", env=env, kl_reduce=stat,
                                            **({} if kind == "agent" else dict(networks=kind))))
              for kind in kinds for stat in KL_REDUCES),
            ("oappo one seat", dict(algo="oappo", env=env, networks="one", update_by="seat")))


# Issue 32: one tuning budget for every family on 2s3z (seeds 0-2, 500k steps, Fig. 4's batch and
# its other SMAX_TUNED settings): learning rate (actor and critic) x entropy bonus for HAPPO (the
# separate-network family), MAPPO and the two readings of issue 31 that train differently (one
# network per kind, the engine's mean gate; one network updated seat by seat). The rule, fixed
# before the runs: per family, the setting with the highest final win rate (mean over seeds of
# the last fifth of the evaluations); settings within 0.02 of it tie, and the tie goes to the
# fewest env steps to a 50% win rate (IQM over seeds).
SWEEP_FAMILIES = {"happo": dict(algo="happo"), "mappo": dict(algo="mappo"),
                  "oappo type": dict(algo="oappo", networks="type", kl_reduce="mean"),
                  "oappo one seat": dict(algo="oappo", networks="one", update_by="seat")}
SWEEP_LRS, SWEEP_ENTROPIES = (5e-4, 1e-3, 2e-3), (0.0, 0.01)
# what the rule chose per family, as (lr, entropy) (ASSUMPTIONS.md; a test re-derives it from the
# committed runs)
# then the PPO clip at each family's best (lr, entropy), the same rule over all its settings
SWEEP_CLIPS = (0.1, 0.05)
SWEEP_CHOSEN = {"happo": (2e-3, 0.01, 0.2), "mappo": (2e-3, 0.0, 0.2), "oappo type": (2e-3, 0.0, 0.2),
                "oappo one seat": (5e-4, 0.0, 0.2)}


def _swept(lr: float, entropy: float, clip: float = TrainConfig.clip) -> dict:
    return dict(lr=lr, critic_lr=lr, entropy_coef=entropy, clip=clip)


def tuned(family: str) -> dict:
    """A family's curve at its chosen setting, on top of ``SMAX_TUNED``."""
    return dict(SWEEP_FAMILIES[family], **_swept(*SWEEP_CHOSEN[family]))


# Issue 32: SEAC and SePS with settings of their own on SMAX (at their reference code's A2C
# defaults and Fig. 4's entropy 0 they stayed at a 0-0.05 win rate on every map): A2C learning
# rate x entropy bonus on 3m (seeds 0-1, 300k steps); per algorithm the highest final win rate wins
# (the sweep's rule), and Fig. 4 then shows whether it leaves the floor on 2s3z too.
A2C_LRS, A2C_ENTROPIES = (3e-4, 1e-3, 3e-3), (0.01, 0.05)
A2C_CHOSEN = {"seac": (3e-3, 0.01), "seps": (3e-3, 0.01)}  # (a2c_lr, entropy): what the rule chose (ASSUMPTIONS.md)


# Issue 32's Fig. 4: every family at its sweep's choice. OAPPO under each reading of issue 31
# that trains differently on the map (one net per kind only where kinds differ: with one kind it
# is MAPPO): per agent with the engines' gate statistic (the mean) at the separate-network
# family's setting, per kind, and one net seat by seat. OATRPO gates with the mean too (TRPO has
# no learning rate or entropy bonus to tune). SEAC / SePS at their 3m sweep's choice.
SMAX_READINGS = {"oappo": "OAPPO (a net per agent)", "oappo type": "OAPPO (a net per kind)",
                 "oappo one seat": "OAPPO (one net, seat by seat)"}
# the long maps at 3M+ steps: MAPPO, HAPPO and the reading the sweep found best (per kind and seat
# by seat tie on 2s3z, at 0.956 / 0.946 and 192k steps to 0.5; per kind is the one whose gate acts)
LONG_SMAX_CURVES = ("mappo", "happo", "oappo type")


def smax_curves(m: str) -> tuple:
    """Fig. 4's curves on map ``m``: (label, TrainConfig fields)."""
    curves = {"mappo": tuned("mappo"), "happo": tuned("happo"),
              "oappo": dict(tuned("happo"), algo="oappo", kl_reduce="mean"),
              "oappo type": tuned("oappo type"), "oappo one seat": tuned("oappo one seat"),
              "oatrpo": dict(algo="oatrpo", kl_reduce="mean"),
              **{a: dict(algo=a, a2c_lr=lr, entropy_coef=ent) for a, (lr, ent) in A2C_CHOSEN.items()}}
    if m not in SMAX_HETEROGENEOUS:
        del curves["oappo type"]
    keep = LONG_SMAX_CURVES if m in FIG4_MAPS[3:] else curves
    return tuple((label, dict(kw, env=f"smax:{m}")) for label, kw in curves.items() if label in keep)


def _smax_claims(m: str) -> list:
    """The paper's Section 6.2 claims on map ``m``, for each reading of OAPPO it has."""
    out = []
    for r in (label for label, _ in smax_curves(m) if label in SMAX_READINGS):
        name = SMAX_READINGS[r]
        if m in SMAX_HETEROGENEOUS:
            out += [(m, higher, (r, other), f"{m}: {name} ends above {other.upper()} (heterogeneous agents)")
                    for other in ("mappo", "happo")]
        if m == "6h_vs_8z":
            out += [(m, stabler, (r, "mappo"), f"{m}: {name} improves more stably than MAPPO"),
                    (m, higher, (r, "mappo"), f"{m}: {name} ends above MAPPO")]
        out.append((m, faster, (r, "happo"), f"{m}: {name} converges faster than HAPPO"))
    return out


FIGA_READINGS = {r: SMAX_READINGS[r] for r in FIGA_CURVES if r in SMAX_READINGS}


# Eq. 9's selection on the engines (``study/selection.py``): per env, no reuse (HAPPO), a net per
# agent reusing always (sigma = inf) and through the gate, and on 2s3z a net per kind reusing
# within its kind only (lambda = 1) and across kinds through the gate; each family at its Fig. 4
# setting, on ten seeds that chose no setting (the sweep used 0-2, Fig. 4 and the sigma rule 0-4,
# the early-reuse study 0-9). Sigma per (env, reading): ``selection.gate_sigma``'s rule, fixed
# before these runs (a test recomputes it from the committed runs).
SELECTION_SIGMA = {("smax:2s3z", "agent"): 0.046, ("smax:6h_vs_8z", "agent"): 0.068, ("smax:2s3z", "type"): 0.045}
SELECTION_SEEDS = tuple(range(10, 20))
SELECTION_SMAX = ("smax:2s3z", "smax:6h_vs_8z")


def selection_curves(env: str, per_agent: dict, per_kind: dict | None = None) -> tuple:
    """The selection ablation's curves on ``env`` from the families' settings (the gated one once
    the rule has given its sigma)."""
    gated = dict(per_agent, algo="oappo", kl_reduce="mean", env=env)
    curves = [("happo", dict(per_agent, algo="happo", env=env)), ("oappo always", dict(gated, sigma=float("inf")))]
    if (env, "agent") in SELECTION_SIGMA:
        curves.append(("oappo gated", dict(gated, sigma=SELECTION_SIGMA[env, "agent"])))
    if per_kind is not None:
        kind = dict(per_kind, env=env)
        curves += [("oappo type own kind", dict(kind, reuse_lambda=1.0)),
                   ("oappo type gated", dict(kind, sigma=SELECTION_SIGMA[env, "type"]))]
    return tuple(curves)


def selection_claims(env: str, prefix: str = "", name: str | None = None) -> list:
    """The ablation's claims on ``env`` (each led by the env without ``prefix``, for a figure
    whose claims are per env; else named ``name``): does reuse help, does selection, and across
    kinds."""
    name = name or env.removeprefix(prefix)
    out = [(paired_higher, ("oappo always", "happo"), f"{name}: always-on reuse ends above no reuse")]
    if (env, "agent") in SELECTION_SIGMA:
        sigma = SELECTION_SIGMA[env, "agent"]
        out = [(paired_higher, ("oappo gated", "happo"), f"{name}: gated reuse (a net per agent, sigma {sigma:g}) "
                                                          "ends above no reuse (HAPPO)"),
               (paired_higher, ("oappo gated", "oappo always"), f"{name}: gated reuse ends above always-on reuse "
                                                                 "(selection helps)"), *out]
    if (env, "type") in SELECTION_SIGMA:
        out.append((paired_higher, ("oappo type gated", "oappo type own kind"),
                    f"{name}: a net per kind reusing across kinds through the gate (sigma "
                    f"{SELECTION_SIGMA[env, 'type']:g}) ends above one reusing within its kind only"))
    return [(name, *c) if prefix else c for c in out]


# Issue 32: HARL's tuned HalfCheetah 2x3 HAPPO settings tried in our loop one at a time, then
# together, against App. A's cpu settings, at 1M steps and 10 evaluation episodes
HARL_HALFCHEETAH = {"clip 0.05": dict(clip=0.05), "15 epochs": dict(ppo_epochs=15), "128x3": dict(hidden=(128, 128, 128)),
                    "feature norm": dict(feature_norm=True), "20 x 200": dict(n_envs=20, rollout_len=200)}


# Fig. 6b on GRF academy scenarios: every algorithm of the paper's table the project has.
FIG6B_ALGOS = ("oappo", "oatrpo", "mappo", "happo", "seac", "seps")
GRF_SCENARIOS = ("pass_and_shoot_with_keeper", "3_vs_1_with_keeper", "counterattack_easy", "counterattack_hard")
# HARL's tuned GRF settings (PKU-MARL/HARL); the engine itself ends academy episodes (<= 400 steps)
GRF_HARL = dict(hidden=(64, 64), ppo_epochs=15, n_minibatch=2, clip=0.2, max_steps=400)
ENGINE_BUDGETS = ("smoke", "cpu", "paper")

# The claims of Section 6.1 (Fig. 3c-d compare the paper's sigma and lambda, TrainConfig's
# defaults, with the other values of the sweeps)
SIGMA_REASONS = ("own experience only is slower", "irrelevant experience confuses", "all peers' experience hinders")
LAM_02, LAM_04, LAM_07, LAM_1 = LAMBDAS
# Section 6.2 (Fig. 4) on SMAX, per map and reading of OAPPO
SMAX_CLAIMS = [c for m in FIG4_MAPS for c in _smax_claims(m)]
# Section 6.3 (Fig. 6b) on GRF, per scenario: individual experience suffices on the two simple
# tasks (HAPPO, own experience only, nearly perfect); OAPPO and OATRPO are best on the
# counterattacks (each ends above every other algorithm of the table).
GRF_CLAIMS = [
    *((s, optimal, ("happo",), f"{s}: own experience alone (HAPPO) scores nearly perfectly")
      for s in GRF_SCENARIOS[:2]),
    *((s, higher, (ours, other), f"{s}: {ours.upper()} ends above {other.upper()}")
      for s in GRF_SCENARIOS[2:] for ours in ("oappo", "oatrpo") for other in ("mappo", "happo", "seac", "seps")),
]

# Every figure the project reproduces; a new figure is a new entry here.
GRID = (
    # "converging faster than HAPPO", "OATRPO converges quicker than OAPPO": speed, and (a curve
    # that converges gets there) reaching the optimum at least as often, as two claims
    # HATRPO is our control: OATRPO's trust-region step without reuse, so that OATRPO's claims
    # can tell the step from the reuse
    Figure("fig3b", tuple((a, dict(algo=a)) for a in ("oappo", "oatrpo", "mappo", "happo", "hatrpo")),
           common=dict(env="black_red"), claims=(
               (stuck, ("mappo",), "MAPPO (shared parameters) stays below the optimum"),
               (faster, ("oappo", "happo"), "OAPPO converges faster than HAPPO"),
               (reliable, ("oappo", "happo"), "OAPPO reaches the optimum as reliably as HAPPO"),
               (faster, ("oatrpo", "happo"), "OATRPO converges faster than HAPPO"),
               (reliable, ("oatrpo", "happo"), "OATRPO reaches the optimum as reliably as HAPPO"),
               (higher, ("oappo", "mappo"), "OAPPO ends above MAPPO"),
               (higher, ("oatrpo", "mappo"), "OATRPO ends above MAPPO"),
               (faster, ("oatrpo", "oappo"), "OATRPO converges faster than OAPPO"),
               (reliable, ("oatrpo", "oappo"), "OATRPO reaches the optimum as reliably as OAPPO"),
               (faster, ("oatrpo", "hatrpo"), "OATRPO converges faster than HATRPO (our control: the same step "
                                              "without reuse)")),
           section="6.1", notebook="11_black_red_fig3b"),
    Figure("fig3c", tuple((s, dict(algo="oappo", sigma=s)) for s in SIGMAS), common=dict(env="black_red"),
           claims=tuple((better, (TrainConfig.sigma, s), f"sigma = {TrainConfig.sigma:g} beats sigma = {s:g} ({why})")
                        for s, why in zip([s for s in SIGMAS if s != TrainConfig.sigma], SIGMA_REASONS)),
           section="6.1", notebook="12_sigma_lambda_fig3cd"),
    Figure("fig3d", tuple((lam, dict(algo="oappo", reuse_lambda=lam)) for lam in LAMBDAS), common=dict(env="black_red"),
           # the paper: 0.2 risks a local optimum, 1 converges later than 0.4 / 0.7, which "strike a
           # balance", 0.7 only marginally better than 0.4
           claims=((stuck, (LAM_02,), f"lambda = {LAM_02:g} (mostly others' experience) gets stuck in a local optimum"),
                   (optimal, (LAM_07,), f"lambda = {LAM_07:g} strikes a balance: it reaches the optimum"),
                   (optimal, (LAM_04,), f"lambda = {LAM_04:g} strikes a balance too (0.7 only marginally better): "
                                        "it reaches the optimum"),
                   (faster, (LAM_07, LAM_1), f"lambda = {LAM_1:g} (own experience only) converges later than "
                                             f"lambda = {LAM_07:g}"),
                   (faster, (LAM_04, LAM_1), f"lambda = {LAM_1:g} (own experience only) converges later than "
                                             f"lambda = {LAM_04:g}")),
           section="6.1", notebook="12_sigma_lambda_fig3cd"),
    # A scheme fixes who may reuse whom; the KL gate is opened (sigma = inf) so that the mask
    # alone decides, as in the paper's "modified OAPPO parameters".
    Figure("fig5b", tuple((s, dict(algo="oappo", allowed=s, sigma=float("inf"), reuse_lambda=SCHEME_LAM[s]))
                          for s in SCHEMES), common=dict(env="black_blue_red"), claims=(
               (stuck, ("UR",), "UR (red and black share) gets stuck below the optimum"),
               (stuck, ("AR",), "AR (everyone shares) gets stuck below the optimum"),
               (optimal, ("RR",), "RR (black and blue share) reaches the optimum"),
               (optimal, ("NR",), "NR (no reuse) reaches the optimum")),
           section="6.1", notebook="13_black_blue_red_fig5b"),
    Figure("fig1", (("oappo", dict(algo="oappo")),), common=dict(env="black_blue_red"), seeds=1,
           section="3", notebook="14_policy_distance_fig1"),
    # label: the algorithm; the maze is the ``env`` column
    Figure("fig_baselines_mazes", tuple((a, dict(algo=a, env=m)) for m in MAZES for a in BASELINE_ALGOS),
           notebook="15_baselines_seac_seps"),
    # Issue 12's adaptive reuse rule against the fixed Eq. 9 (sigma 0.1, lambda 0.7: the best of
    # Fig. 3c-d's grid) and no reuse, on both paper mazes; and both at lambda 0.4 on Black-Red,
    # where the fixed rule is trapped (Fig. 3d)
    Figure("fig_adaptive", tuple((label, dict(env=m, **kw)) for m in MAZES for label, kw in ADAPTIVE_CURVES)
           + tuple((f"{label} lambda=0.4", dict(env="black_red", reuse_lambda=0.4, **kw)) for label, kw in ADAPTIVE_CURVES[:2]),
           notebook="17_adaptive_reuse"),
    # Issue 31: the entropy bonus weighted as the own-seat surrogate is (W[i, i]) against HARL's
    # unweighted bonus, on Black-Red (the engines' tuned SMAX settings have no entropy bonus)
    Figure("fig_entropy_weight", (("oappo", dict(algo="oappo")),
                                  ("oappo entropy x W[i,i]", dict(algo="oappo", entropy_by_weight=True))),
           common=dict(env="black_red"), notebook="17_adaptive_reuse"),
    # label: the algorithm or reading (``smax_curves``); the map is the ``env`` column. ``cpu``:
    # the small maps and the paper's 6h_vs_8z (1M steps, 2.5% of HARL's) at 5 seeds;
    # 3s5z_vs_3s6z at 3M (15%; the separate nets learn several times slower than MAPPO there)
    # for its three curves at 3 seeds (ASSUMPTIONS.md); the MMM2 stand-in
    # and the paper's steps run at ``paper``.
    Figure("fig4_smax", tuple(c for m in FIG4_MAPS for c in smax_curves(m)),
           common=dict(SMAX_BATCH, **SMAX_TUNED), runs_at=ENGINE_BUDGETS, budgets={
               "smoke": dict(eval_episodes=8, envs={"smax:3m": dict(steps=6_400, eval_every=1)}),
               "cpu": dict(eval_episodes=64, envs={"smax:3m": dict(steps=300_000, eval_every=10),
                                                   "smax:2s3z": dict(steps=1_000_000, eval_every=10),
                                                   "smax:6h_vs_8z": dict(steps=1_000_000, eval_every=10),
                                                   "smax:3s5z_vs_3s6z": dict(steps=3_000_000, eval_every=40, seeds=(0, 1, 2))}),
               "paper": dict(eval_episodes=64, eval_every=25, envs={
                   "smax:3m": dict(steps=2_000_000), "smax:2s3z": dict(steps=5_000_000),
                   "smax:6h_vs_8z": dict(steps=40_000_000), "smax:3s5z_vs_3s6z": dict(steps=20_000_000),
                   "smax:MMM2_like_7m2M_vs_8m3M": dict(steps=20_000_000)}),
           }, metric=WIN_RATE, claims=tuple(SMAX_CLAIMS), claims_per_env="smax:",
           section="6.2", notebook="20_smax_fig4",
           reference="HARL's steps for the map"),
    # App. A's own settings are not public; ``paper`` is HARL's MaMuJoCo scale (10M steps).
    Figure("figA_mamujoco", tuple(FIGA_CURVES.items()), common=dict(env=HALFCHEETAH, ppo_epochs=15),
           runs_at=ENGINE_BUDGETS, budgets={
               "smoke": MAMUJOCO_SMOKE,
               # 1M steps: 10% of HARL's scale, where every curve has left its initial return (at 200k
               # MAPPO and SEAC had not); 10 episodes every 20 iterations (40k steps)
               "cpu": dict(steps=1_000_000, eval_every=20, eval_episodes=10, config=MAMUJOCO_CPU),
               "paper": dict(steps=10_000_000, eval_every=25, eval_episodes=10,
                             config=dict(n_envs=10, rollout_len=400, max_steps=1000, checkpoint_every=10)),
           }, metric=RETURN, claims=(
               # (ASSUMPTIONS.md) on homogeneous agents, reusing others' experience as it is (SEAC's
               # importance-weighted reuse; MAPPO's one network on everyone's data) ends lower than
               # using one's own (HAPPO), while OAPPO's gated reuse does not
               (higher, ("happo", "seac"), "direct reuse (SEAC) ends below no reuse (HAPPO)"),
               (higher, ("happo", "mappo"), "full sharing (MAPPO) ends below no reuse (HAPPO)"),
               *(c for r, name in FIGA_READINGS.items()
                 for c in ((higher, (r, "seac"), f"{name} ends above direct reuse (SEAC)"),
                           (higher, (r, "mappo"), f"{name} ends above full sharing (MAPPO)")))),
           section="App. A", notebook="21_mamujoco_appA", reference="HARL's MaMuJoCo scale; App. A gives no steps"),
    Figure("fig_selection_smax", tuple(c for env in SELECTION_SMAX for c in selection_curves(
        env, tuned("happo"), tuned("oappo type") if env.removeprefix("smax:") in SMAX_HETEROGENEOUS else None)),
           common=dict(SMAX_BATCH, **SMAX_TUNED), runs_at=("smoke", "cpu"), budgets={
               "smoke": dict(steps=6_400, eval_every=1, eval_episodes=8, seeds=(10,)),
               "cpu": dict(seeds=SELECTION_SEEDS, steps=1_000_000, eval_every=10, eval_episodes=64)},
           metric=WIN_RATE, claims=tuple(c for env in SELECTION_SMAX for c in selection_claims(env, "smax:")),
           claims_per_env="smax:", section="6.2", notebook="20_smax_fig4", reference="HARL's steps for the map"),
    # the selection ablation on HalfCheetah 2x3, with the learner ``fig_mamujoco_normalize`` chose
    Figure("fig_selection_mamujoco", selection_curves(HALFCHEETAH, dict(FIGA_CURVES["happo"], normalize=True)),
           common=dict(env=HALFCHEETAH, ppo_epochs=15), runs_at=("smoke", "cpu"), budgets={
               "smoke": dict(MAMUJOCO_SMOKE, seeds=(10,)), "cpu": dict(HALFCHEETAH_1M, seeds=SELECTION_SEEDS)},
           metric=RETURN, claims=tuple(selection_claims(HALFCHEETAH, name="HalfCheetah 2x3")), section="App. A",
           notebook="21_mamujoco_appA",
           reference="HARL's MaMuJoCo scale; App. A gives no steps"),
    # Issue 31: does OAPPO's early reuse (its gate is open while the untrained nets look alike)
    # lower the return? Ten seed pairs at 600k steps, each point 10 episodes, so that an
    # interval on the final return's difference can decide it; not a claim of the paper. The
    # control lets Eq. 9 act only after 10 iterations (20k steps), when the nets have moved apart.
    Figure("fig_early_reuse", (("happo", dict(algo="happo")), ("oappo", dict(algo="oappo")),
                               ("oappo warm-up 10", dict(algo="oappo", reuse_warmup=10))),
           common=dict(env=HALFCHEETAH), runs_at=("smoke", "cpu"), budgets={
               "smoke": MAMUJOCO_SMOKE,
               "cpu": dict(seeds=tuple(range(10)), steps=600_000, eval_every=10, eval_episodes=10, config=MAMUJOCO_CPU)},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
    # ``cpu``: each env at the config of its committed runs (Fig. 4's, the early-reuse figure's),
    # so HAPPO, MAPPO and OAPPO (per agent, max) there are those runs, read from the cache
    Figure("fig_readings_smax", tuple(c for env in READING_ENVS[:2] for c in _reading_curves(env)),
           common=dict(SMAX_BATCH, **SMAX_TUNED), runs_at=("cpu",),
           budgets={"cpu": dict(seeds=(0, 1, 2), steps=500_000, eval_every=10, eval_episodes=64)},
           metric=WIN_RATE, section="6.2", notebook="20_smax_fig4"),
    Figure("fig_sweep_2s3z", tuple((f"{name} lr={lr:g} ent={ent:g}", dict(kw, **_swept(lr, ent)))
                                   for name, kw in SWEEP_FAMILIES.items() for lr in SWEEP_LRS for ent in SWEEP_ENTROPIES)
           + tuple((f"{name} lr={SWEEP_CHOSEN[name][0]:g} ent={SWEEP_CHOSEN[name][1]:g} clip={clip:g}",
                    dict(kw, **_swept(*SWEEP_CHOSEN[name][:2], clip))) for name, kw in SWEEP_FAMILIES.items() for clip in SWEEP_CLIPS),
           common=dict(SMAX_BATCH, env="smax:2s3z", **SMAX_TUNED),
           runs_at=("cpu",), budgets={"cpu": dict(seeds=(0, 1, 2), steps=500_000, eval_every=10, eval_episodes=64)},
           metric=WIN_RATE, section="6.2", notebook="20_smax_fig4"),
    Figure("fig_a2c_smax", tuple((f"{a} lr={lr:g} ent={ent:g}", dict(algo=a, a2c_lr=lr, entropy_coef=ent))
                                 for a in ("seac", "seps") for lr in A2C_LRS for ent in A2C_ENTROPIES),
           common=dict(SMAX_BATCH, env="smax:3m"), runs_at=("cpu",),
           budgets={"cpu": dict(seeds=(0, 1), steps=300_000, eval_every=10, eval_episodes=64)},
           metric=WIN_RATE, section="6.2", notebook="20_smax_fig4"),
    Figure("fig_mamujoco_settings", (("happo", dict(algo="happo")),
                                     *((f"happo {name}", dict(algo="happo", **kw)) for name, kw in HARL_HALFCHEETAH.items()),
                                     ("happo HARL", dict(algo="happo", **{k: v for kw in HARL_HALFCHEETAH.values()
                                                                           for k, v in kw.items()}))),
           common=dict(env=HALFCHEETAH), runs_at=("cpu",),
           budgets={"cpu": HALFCHEETAH_1M},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
    # Issue 32: App. A's HAPPO settings (15 epochs) on the same robot with one agent (all six
    # joints, the full observation), beside the two-leg HAPPO: what the split into two agents costs
    # in our loop, against what our PPO costs against the single-agent anchor (stable-baselines3)
    Figure("fig_single_agent", (("ppo one agent", dict(algo="happo", env="mamujoco:HalfCheetah-1x6")),
                                ("happo two legs", dict(algo="happo", env=HALFCHEETAH))),
           common=dict(ppo_epochs=15), runs_at=("cpu",),
           budgets={"cpu": HALFCHEETAH_1M},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
    # App. A's HAPPO against the same with running normalisation of observations, states and rewards
    # (stable-baselines3's VecNormalize, which the single-agent anchor uses), seeds 0-4: the rule,
    # fixed before the runs, for the HalfCheetah selection ablation's learner: the one with the higher
    # final IQM (the last fifth of the evaluations, at least 3)
    Figure("fig_mamujoco_normalize", (("happo", FIGA_CURVES["happo"]), ("happo normalized", dict(algo="happo",
                                                                                               normalize=True))),
           common=dict(env=HALFCHEETAH, ppo_epochs=15), runs_at=("smoke", "cpu"), budgets={
               "smoke": MAMUJOCO_SMOKE, "cpu": dict(HALFCHEETAH_1M, seeds=(0, 1, 2, 3, 4))},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
    Figure("fig_readings_mamujoco", _reading_curves(HALFCHEETAH), runs_at=("cpu",),
           budgets={"cpu": dict(seeds=(0, 1, 2), steps=600_000, eval_every=10, eval_episodes=10, config=MAMUJOCO_CPU)},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
    # label: the algorithm; the scenario is the ``env`` column. ``cpu``: what 2 cores train in
    # about 2 hours, on 3_vs_1_with_keeper alone (the scenario HARL learns fastest; the speed is
    # benchmarks/grf_speed.py's, the sizing ASSUMPTIONS.md's).
    Figure("fig6b", tuple((a, dict(algo=a, env=f"grf:academy_{s}")) for s in GRF_SCENARIOS for a in FIG6B_ALGOS),
           runs_at=ENGINE_BUDGETS, budgets={
               "smoke": dict(steps=160, eval_episodes=2, config=dict(n_envs=2, rollout_len=16, max_steps=32),
                             envs={"grf:academy_3_vs_1_with_keeper": {}}),
               "cpu": dict(seeds=(0, 1, 2), steps=32_000, eval_every=4, eval_episodes=16,
                           config=dict(GRF_HARL, n_envs=8, rollout_len=200),
                           envs={"grf:academy_3_vs_1_with_keeper": {}}),
               "paper": dict(steps=25_000_000, eval_every=25, config=dict(GRF_HARL, n_envs=50, rollout_len=200),
                             envs={f"grf:academy_{s}": {} for s in GRF_SCENARIOS[:3]}
                             | {"grf:academy_counterattack_hard": dict(
                                 steps=50_000_000, config=dict(GRF_HARL, n_envs=50, rollout_len=1000))}),
           }, metric=SCORE, claims=tuple(GRF_CLAIMS), claims_per_env="grf:academy_",
           section="6.3", notebook="22_grf_fig6b", reference="HARL's tuned GRF steps"),
)
FIGURES = tuple(f.id for f in GRID)
MAZE_FIGURES = tuple(f.id for f in GRID if f.runs_at is None)  # Section 6.1; the others run real engines


def get_figure(figure: "Figure | str") -> Figure:
    if isinstance(figure, Figure):
        return figure
    known = {f.id: f for f in GRID}
    if figure not in known:
        raise ValueError(f"unknown figure {figure!r}; choose from {sorted(known)}")
    return known[figure]


@dataclass(frozen=True)
class Run:
    """One training run of a figure and what it needs (for a Ray cluster)."""

    figure: str
    label: object
    cfg: TrainConfig
    cpus: float = 1.0
    gpus: float = 0.0
    memory_gb: float = 0.0


def runs_of(figure: "Figure | str", budget: str) -> list[Run]:
    """A figure's runs at a budget: curve by curve, seed by seed."""
    fig = get_figure(figure)
    trained = get_budget(budget).figures  # a bad name fails here, even for a figure without runs at it
    if (fig.runs_at is not None and budget not in fig.runs_at) or (trained is not None and fig.id not in trained):
        return []
    envs, runs = fig.envs(budget), []
    for label, kw in fig.curves:
        env = {**fig.common, **kw}.get("env", TrainConfig.env)
        if envs is not None and env not in envs:
            continue
        b = fig.budget(budget, env)
        seeds = b.seeds if fig.seeds is None else b.seeds[:fig.seeds]
        runs += [Run(fig.id, label, _config(b, seed=s, **{**fig.common, **kw}), fig.cpus, fig.gpus, fig.memory_gb)
                 for s in seeds]
    return runs


def _config(b: Budget, **kw) -> TrainConfig:
    """A run's config at budget ``b``; A2C runs take the shape that evaluates them at the PPO
    family's env steps (``a2c_family.beside_ppo``)."""
    kw, budget = {**b.config, **kw}, dict(steps=b.steps, eval_every=b.eval_every, eval_episodes=b.eval_episodes)
    if budget.keys() & kw.keys():
        raise ValueError(f"a curve or budget config sets {sorted(budget.keys() & kw.keys())}, which the budget decides")
    kw |= budget
    return TrainConfig(**(beside_ppo(kw) if ALGOS[kw["algo"]].a2c else kw))


def figure_runs(figure: "Figure | str", budget: str) -> list[tuple[object, TrainConfig]]:
    """(label, config) of every run of a figure."""
    return [(r.label, r.cfg) for r in runs_of(figure, budget)]


