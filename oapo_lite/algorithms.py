"""The algorithm table both tracks read: per algorithm, whose experience each learner uses
(its reuse matrix), whether learners update one after another, and its policy step."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class AlgoSpec:
    reuse: str | None  # "oapo": Eq. 9; "own": M = I; "uniform": M = 1/n; None: the A2C learner's own rule
    sequential: bool  # random update order and the factor rho
    trust_region: bool  # Eq. 7 (TRPO step) instead of Eq. 8 (PPO clip)
    shared: bool  # one network for every seat
    a2c: bool = False  # SEAC / SePS: the A2C family's learner (neural/a2c_family.py), not the PPO / TRPO family's


ALGOS = {
    "oappo": AlgoSpec("oapo", True, False, False),
    "oatrpo": AlgoSpec("oapo", True, True, False),
    "happo": AlgoSpec("own", True, False, False),
    "hatrpo": AlgoSpec("own", True, True, False),
    "mappo": AlgoSpec("uniform", False, False, True),
    "ippo": AlgoSpec("own", False, False, False),
    # the A2C family's learner decides who learns from whom
    "seac": AlgoSpec(None, False, False, False, a2c=True),
    "seps": AlgoSpec(None, False, False, False, a2c=True),
}
