"""The algorithm table both tracks read: per algorithm, whose experience each learner uses
(its reuse matrix), whether learners update one after another, and its policy step."""
from __future__ import annotations

from dataclasses import dataclass

from oapo_lite.renamed import refuse


@refuse({"reuse": "reuse_rule", "shared": "networks"})
@dataclass(frozen=True)
class AlgoSpec:
    reuse_rule: str | None  # "oapo": Eq. 9; "own": M = I; "uniform": M = 1/n; None: the A2C learner's own rule
    sequential: bool  # random update order and the factor rho
    trust_region: bool  # Eq. 7 (TRPO step) instead of Eq. 8 (PPO clip)
    networks: str  # the networks reading it trains by default (TrainConfig.networks): "agent" or "one"
    a2c: bool = False  # SEAC / SePS: the A2C family's learner (neural/a2c_family.py), not the PPO / TRPO family's


ALGOS = {
    "oappo": AlgoSpec("oapo", True, False, "agent"),
    "oatrpo": AlgoSpec("oapo", True, True, "agent"),
    "happo": AlgoSpec("own", True, False, "agent"),
    "hatrpo": AlgoSpec("own", True, True, "agent"),
    "mappo": AlgoSpec("uniform", False, False, "one"),
    "ippo": AlgoSpec("own", False, False, "agent"),
    # the A2C family's learner decides who learns from whom
    "seac": AlgoSpec(None, False, False, "agent", a2c=True),
    "seps": AlgoSpec(None, False, False, "agent", a2c=True),
}
