"""Section 6.3 on Google Research Football (Fig. 6b): every algorithm of the paper's table the
project has, on four academy scenarios."""
from __future__ import annotations

from oapo_lite.study.catalogue.grid import ENGINE_BUDGETS, At, Figure
from oapo_lite.study.catalogue.metrics import SCORE
from oapo_lite.study.catalogue.tests import Claim

FIG6B_ALGOS = ("oappo", "oatrpo", "mappo", "happo", "seac", "seps")
GRF_SCENARIOS = ("pass_and_shoot_with_keeper", "3_vs_1_with_keeper", "counterattack_easy", "counterattack_hard")
# HARL's tuned GRF settings (PKU-MARL/HARL); the engine itself ends academy episodes (<= 400 steps)
GRF_HARL = dict(hidden=(64, 64), ppo_epochs=15, n_minibatch=2, clip=0.2, max_steps=400)
# Per scenario: individual experience suffices on the two simple tasks (HAPPO, own experience
# only, nearly perfect); OAPPO and OATRPO are best on the counterattacks (each ends above every
# other algorithm of the table).
GRF_CLAIMS = (
    *(Claim(f"{s}: own experience alone (HAPPO) scores nearly perfectly", "optimal", ("happo",), f"grf:academy_{s}")
      for s in GRF_SCENARIOS[:2]),
    *(Claim(f"{s}: {ours.upper()} ends above {other.upper()}", "higher", (ours, other), f"grf:academy_{s}",
            headline=(ours, other) == ("oappo", "mappo"))
      for s in GRF_SCENARIOS[2:] for ours in ("oappo", "oatrpo") for other in ("mappo", "happo", "seac", "seps")),
)

FIGURES = (
    # label: the algorithm; the scenario is the ``env`` column. ``cpu``: what 2 cores train in a
    # couple of hours, on 3_vs_1_with_keeper alone (the scenario HARL learns fastest;
    # benchmarks/grf_speed.py measures the speed, ASSUMPTIONS.md sizes the budget).
    Figure("fig6b", tuple((a, dict(algo=a, env=f"grf:academy_{s}")) for s in GRF_SCENARIOS for a in FIG6B_ALGOS),
           runs_at=ENGINE_BUDGETS, budgets={
               "smoke": At(steps=160, eval_episodes=2, config=dict(n_envs=2, rollout_len=16, max_steps=32),
                           envs={"grf:academy_3_vs_1_with_keeper": At()}),
               "cpu": At(seeds=(0, 1, 2), steps=32_000, eval_every=4, eval_episodes=16,
                         config=dict(GRF_HARL, n_envs=8, rollout_len=200),
                         envs={"grf:academy_3_vs_1_with_keeper": At()}),
               "paper": At(steps=25_000_000, eval_every=25, config=dict(GRF_HARL, n_envs=50, rollout_len=200),
                           envs={f"grf:academy_{s}": At() for s in GRF_SCENARIOS[:3]}
                           | {"grf:academy_counterattack_hard": At(
                               steps=50_000_000, config=dict(GRF_HARL, n_envs=50, rollout_len=1000))}),
           }, metric=SCORE, claims=GRF_CLAIMS, claims_per_env="grf:academy_",
           section="6.3", notebook="22_grf_fig6b", reference="HARL's tuned GRF steps"),
)
