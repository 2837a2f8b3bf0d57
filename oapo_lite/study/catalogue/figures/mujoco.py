"""App. A on multi-agent MuJoCo (HalfCheetah 2x3): no reuse, full sharing, gated reuse and direct
reuse on homogeneous agents, the settings and learner the runs use, OAPPO's readings and the
selection ablation."""
from __future__ import annotations

from dataclasses import replace

from oapo_lite.study.catalogue.figures.readings import (DOSE_QUANTILES, READING_NAMES, SELECTION_SEEDS, dose_claims,
                                                        dose_curves, reading_curves, selection_claims, selection_curves, sigma_on)
from oapo_lite.study.catalogue.grid import ENGINE_BUDGETS, At, Figure
from oapo_lite.study.catalogue.metrics import RETURN, Metric
from oapo_lite.study.catalogue.tests import Claim

# no reuse (HAPPO), full sharing (MAPPO), gated reuse (OAPPO, a net per agent with the engines'
# mean gate, and one net seat by seat; per type is per agent here, every leg being its own type)
# and direct reuse (SEAC). The PPO family runs 15 epochs, HARL's setting that helped most in our
# loop (``fig_mamujoco_settings``).
FIGA_CURVES = {"happo": dict(algo="happo"), "mappo": dict(algo="mappo"), "oappo": dict(algo="oappo", kl_reduce="mean"),
               "oappo one seat": dict(algo="oappo", networks="one", update_by="seat"), "seac": dict(algo="seac")}
FIGA_ALGOS = tuple(FIGA_CURVES)
FIGA_READINGS = {r: READING_NAMES[r] for r in FIGA_CURVES if r in READING_NAMES}
HALFCHEETAH = "mamujoco:HalfCheetah-2x3"
# the cpu batch: 8 copies x 250 steps, MuJoCo's 1,000-step episodes
MAMUJOCO_CPU = dict(n_envs=8, rollout_len=250, max_steps=1000, checkpoint_every=10)
# App. A's cpu budget: 1M steps, 10% of HARL's scale; 10 episodes every 20 iterations (40k
# steps); the studies of its settings and learner at 3 seeds
APPA_CPU = At(steps=1_000_000, eval_every=20, eval_episodes=10, config=MAMUJOCO_CPU)
MUJOCO_1M = replace(APPA_CPU, seeds=(0, 1, 2))
MAMUJOCO_SMOKE = At(steps=200, eval_episodes=2, config=dict(n_envs=2, rollout_len=50, max_steps=100))
# HARL's tuned HalfCheetah 2x3 HAPPO settings, tried in our loop one at a time, then together
HARL_HALFCHEETAH = {"clip 0.05": dict(clip=0.05), "15 epochs": dict(ppo_epochs=15), "128x3": dict(hidden=(128, 128, 128)),
                    "feature norm": dict(feature_norm=True), "20 x 200": dict(n_envs=20, rollout_len=200)}
# Eq. 9's selection here: sigma per (env, reading) by ``selection.gate_sigma``'s rule, read from
# the ablation's always-on runs before any gated run (a test recomputes it from them)
SELECTION_SIGMA = {(HALFCHEETAH, "agent"): 0.047}
# the ablation's return: App. A's, with a level to reach, so that speed can be compared where the
# final returns cannot tell the curves apart (the single-agent anchor passes it at 200k-240k steps)
SPEED_RETURN = Metric(RETURN.column, 1000.0, RETURN.floor, RETURN.reach, RETURN.final, RETURN.tail)
# the ablation's learner: the one ``fig_mamujoco_normalize``'s rule chose
SELECTION_LEARNER = dict(FIGA_CURVES["happo"], normalize=True)
# the dose-response's robot: four legs of two joints, every agent with alike spaces and three
# peers to choose between (HalfCheetah's two agents give the gate one peer: a switch)
ANT = "mamujoco:Ant-4x2"
# its learner, by fig_mamujoco_normalize's rule on Ant's own seeds 0-2 (fig_ant_learner): App. A's
# HAPPO (final IQM 805 against the normalised learner's 316)
ANT_LEARNER = FIGA_CURVES["happo"]
# its return with a level to reach, fixed from those seeds before any test seed ran: a round
# number below HAPPO's final there
ANT_RETURN = Metric(RETURN.column, 500.0, RETURN.floor, RETURN.reach, RETURN.final, RETURN.tail)
# the dose-response's sigmas on Ant, by the rule's quantiles of the always-on runs' K on seeds
# 0-2 (``selection.gate_sigma``), read once those runs were on disk and before any gated run
ANT_DOSE_SIGMA = dict(zip(DOSE_QUANTILES, (0.031, 0.046, 0.077, 0.11)))

# HARL's MaMuJoCo scale: App. A's ``paper`` budget, and the reference its ``cpu`` budgets are a share of
HARL_SCALE = At(steps=10_000_000, eval_every=25, eval_episodes=10,
                config=dict(n_envs=10, rollout_len=400, max_steps=1000, checkpoint_every=10))

FIGURES = (
    # App. A's own settings are not public; ``paper`` is HARL's MaMuJoCo scale (10M steps).
    Figure("figA_mamujoco", tuple(FIGA_CURVES.items()), common=dict(env=HALFCHEETAH, ppo_epochs=15),
           runs_at=ENGINE_BUDGETS, budgets={
               "smoke": MAMUJOCO_SMOKE,
               "cpu": APPA_CPU,
               "paper": HARL_SCALE,
           }, metric=RETURN, claims=(
               # on homogeneous agents, reusing others' experience as it is (SEAC's importance-weighted
               # reuse; MAPPO's one network on everyone's data) ends lower than using one's own
               # (HAPPO), while OAPPO's gated reuse does not
               Claim("direct reuse (SEAC) ends below no reuse (HAPPO)", "higher", ("happo", "seac")),
               Claim("full sharing (MAPPO) ends below no reuse (HAPPO)", "higher", ("happo", "mappo")),
               *(c for r, name in FIGA_READINGS.items()
                 for c in (Claim(f"{name} ends above direct reuse (SEAC)", "higher", (r, "seac")),
                           Claim(f"{name} ends above full sharing (MAPPO)", "higher", (r, "mappo")),
                           # the clean contrast: the same settings and initial networks per seed, reuse or none
                           Claim(f"{name} ends above no reuse (HAPPO), seed by seed", "paired_higher", (r, "happo"),
                                 headline=r == "oappo")))),
           section="App. A", notebook="21_mamujoco_appA", reference="HARL's MaMuJoCo scale; App. A gives no steps"),
    Figure("fig_selection_mamujoco", selection_curves(HALFCHEETAH, sigma_on(SELECTION_SIGMA, HALFCHEETAH),
                                                      SELECTION_LEARNER),
           common=dict(env=HALFCHEETAH, ppo_epochs=15), runs_at=("smoke", "cpu"), budgets={
               "smoke": replace(MAMUJOCO_SMOKE, seeds=(10,)), "cpu": replace(MUJOCO_1M, seeds=SELECTION_SEEDS),
               "paper": HARL_SCALE},
           metric=SPEED_RETURN, claims=tuple(selection_claims(HALFCHEETAH, sigma_on(SELECTION_SIGMA, HALFCHEETAH),
                                                              "HalfCheetah 2x3", per_env=False, metric=SPEED_RETURN)),
           section="App. A", ours=True, paired=True,
           notebook="21_mamujoco_appA", reference="HARL's MaMuJoCo scale; App. A gives no steps"),
    # Does OAPPO's early reuse (its gate is open while the untrained nets look alike) lower the
    # return? Ten seed pairs, so that an interval on the final return's difference can decide it;
    # not a claim of the paper. The control lets Eq. 9 act only after 10 iterations (20k steps),
    # when the nets have moved apart.
    Figure("fig_early_reuse", (("happo", dict(algo="happo")), ("oappo", dict(algo="oappo")),
                               ("oappo warm-up 10", dict(algo="oappo", reuse_warmup=10))),
           common=dict(env=HALFCHEETAH), runs_at=("smoke", "cpu"), budgets={
               "smoke": MAMUJOCO_SMOKE,
               "cpu": At(seeds=tuple(range(10)), steps=600_000, eval_every=10, eval_episodes=10, config=MAMUJOCO_CPU)},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA", paired=True),
    Figure("fig_mamujoco_settings", (("happo", dict(algo="happo")),
                                     *((f"happo {name}", dict(algo="happo", **kw)) for name, kw in HARL_HALFCHEETAH.items()),
                                     ("happo HARL", dict(algo="happo", **{k: v for kw in HARL_HALFCHEETAH.values()
                                                                           for k, v in kw.items()}))),
           common=dict(env=HALFCHEETAH), runs_at=("cpu",), budgets={"cpu": MUJOCO_1M},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
    # App. A's HAPPO settings on the same robot with one agent (all six joints, the full
    # observation), beside the two-leg HAPPO: what the split into two agents costs in our loop,
    # against what our PPO costs against the single-agent anchor (stable-baselines3)
    Figure("fig_single_agent", (("ppo one agent", dict(algo="happo", env="mamujoco:HalfCheetah-1x6")),
                                ("happo two legs", dict(algo="happo", env=HALFCHEETAH))),
           common=dict(ppo_epochs=15), runs_at=("cpu",), budgets={"cpu": MUJOCO_1M},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
    # App. A's HAPPO against the same with running normalisation of observations, states and
    # rewards (stable-baselines3's VecNormalize, which the single-agent anchor uses): the rule,
    # fixed before the runs, for the selection ablation's learner: the one with the higher final IQM
    Figure("fig_mamujoco_normalize", (("happo", FIGA_CURVES["happo"]), ("happo normalized", SELECTION_LEARNER)),
           common=dict(env=HALFCHEETAH, ppo_epochs=15), runs_at=("smoke", "cpu"), budgets={
               "smoke": MAMUJOCO_SMOKE, "cpu": APPA_CPU},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
    # the learner on Ant 4x2, by ``fig_mamujoco_normalize``'s rule (the higher final IQM), and the
    # always-on runs whose K the sigma rule reads: seeds 0-2, which the dose-response does not test on
    Figure("fig_ant_learner", (("happo", FIGA_CURVES["happo"]), ("happo normalized", SELECTION_LEARNER),
                               ("oappo always", dict(dose_curves(ANT, (), ANT_LEARNER))["oappo always"])),
           common=dict(env=ANT, ppo_epochs=15), runs_at=("cpu",), budgets={"cpu": MUJOCO_1M},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
    # Eq. 9's gate swept from never open (HAPPO) to never shut (always-on) on Ant 4x2, seeds 10-19
    Figure("fig_dose_mamujoco", dose_curves(ANT, tuple(ANT_DOSE_SIGMA.values()), ANT_LEARNER),
           common=dict(env=ANT, ppo_epochs=15), runs_at=("cpu",), budgets={"cpu": replace(MUJOCO_1M, seeds=SELECTION_SEEDS),
                                                                          "paper": HARL_SCALE},
           metric=ANT_RETURN, claims=tuple(dose_claims(tuple(ANT_DOSE_SIGMA.values()), "Ant 4x2", ANT_RETURN)),
           section="App. A", ours=True, paired=True,
           notebook="21_mamujoco_appA", reference="HARL's MaMuJoCo scale; App. A gives no steps"),
    # the normalisation rule's choice held out: both learners on the ablation's seeds 10-19 (the
    # normalised runs are the ablation's HAPPO runs)
    Figure("fig_normalize_out_of_sample", (("happo", FIGA_CURVES["happo"]), ("happo normalized", SELECTION_LEARNER)),
           common=dict(env=HALFCHEETAH, ppo_epochs=15), runs_at=("cpu",),
           budgets={"cpu": replace(MUJOCO_1M, seeds=SELECTION_SEEDS)}, metric=RETURN, section="App. A",
           notebook="21_mamujoco_appA"),
    Figure("fig_readings_mamujoco", reading_curves(HALFCHEETAH), runs_at=("cpu",),
           budgets={"cpu": At(seeds=(0, 1, 2), steps=600_000, eval_every=10, eval_episodes=10, config=MAMUJOCO_CPU)},
           metric=RETURN, section="App. A", notebook="21_mamujoco_appA"),
)
