"""The grid's types: a budget (how much to spend), a figure (its curves, per-budget overrides,
the measure its curves are judged on and the paper's claims about it) and a run;
``Figure.runs`` turns a figure into training runs. The figures themselves are the catalogue,
``study.figures``.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

from oapo_lite.algorithms import ALGOS
from oapo_lite.neural.config import TrainConfig
from oapo_lite.study.catalogue.metrics import FRAC_OPT, Metric


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
# override it per figure (``Figure.budgets``) with what fits the machine.
BUDGETS["cpu"] = BUDGETS["paper"]
# "student": what a laptop runs in about five minutes and still shows the two findings to see
# with one's own eyes: MAPPO trapped on Black-Red while OAPPO reaches the optimum (Fig. 3b), and
# the lambda trap (Fig. 3d).
BUDGETS["student"] = Budget(seeds=(0, 1, 2), steps=120_000, eval_every=2, eval_episodes=32,
                            figures=("fig3b", "fig3c", "fig3d"),
                            notebooks=("00", "01", "02", "03", "04", "05", "10", "11", "12"))
COMMITTED = ("paper", "cpu")  # the budgets whose figures and runs are committed under figures/
# paper20's figures go to figures/paper20/, but its runs share the committed cache: a run id
# hashes the run's whole config, so its seeds 0-4 are the paper budget's runs, trained once.
SHARED_RUNS = COMMITTED + ("paper20",)
ENGINE_BUDGETS = ("smoke", "cpu", "paper")  # where a real engine's figure has runs


def get_budget(name: str, where: str = "") -> Budget:
    """The budget called ``name``; a name that names none, or a value that is no name (a list
    from papermill's ``-y "budget: [smoke]"``), is refused naming the budgets."""
    if not isinstance(name, str) or name not in BUDGETS:
        kind = "" if isinstance(name, str) else f" (a {type(name).__name__}, where a budget is one name)"
        raise ValueError(f"{where}unknown budget {name!r}{kind}; choose from {sorted(BUDGETS)}")
    return BUDGETS[name]


@dataclass(frozen=True)
class At:
    """A figure's overrides of one budget (``Figure.budgets``): each field given replaces the
    budget's; ``envs`` gives overrides for single envs, and then only the curves on those envs run
    at that budget. A field that no budget has is an error, as for any dataclass."""

    seeds: tuple[int, ...] | None = None
    steps: int | None = None
    eval_every: int | None = None
    eval_episodes: int | None = None
    config: dict | None = None
    envs: dict[str, "At"] | None = None

    def given(self) -> dict:
        """The fields this override sets, but ``envs``."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "envs" and getattr(self, f.name) is not None}


@dataclass(frozen=True)
class Figure:
    """The runs behind one figure, as data: every curve is trained on every seed of the budget.

    ``curves``: (label, TrainConfig fields of that curve); ``common``: fields every curve shares
    (env, batch shape, ...); ``seeds``: how many of the budget's seeds (None: all);
    ``budgets``: per budget, an ``At`` of overrides (a real engine needs more env steps than a
    maze); ``runs_at``: the budgets the figure has runs at (None: every budget); ``cpus``,
    ``gpus``, ``memory_gb``: what one run asks a Ray cluster for. ``metric``: what its curves
    measure; ``claims``: the paper's claims about it, as (test, the curves it compares, the
    claim), judged by ``claims.judge``; with ``claims_per_env`` (the prefix of the ``env``
    column) each claim starts with the env it is judged on, on that env's runs alone.
    ``section`` and ``notebook``: where the paper and this repository show it; ``reference``:
    whose steps its ``paper`` budget is ("": the paper gives none, the budget is ours); ``ours``:
    its claims are this project's tests of the paper's mechanism (an ablation), not the paper's
    words, and are counted apart from them; ``paired``: a seed gives every curve the same initial
    networks and envs, so a seed is read only once every curve of its env has run it (a grid
    stopped midway leaves no curve with a seed the others lack).
    """

    id: str
    curves: tuple[tuple[object, dict], ...]
    common: dict = field(default_factory=dict)
    seeds: int | None = None
    budgets: dict[str, At] = field(default_factory=dict)
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
    ours: bool = False
    paired: bool = False

    def __post_init__(self):
        for name, at in self.budgets.items():
            get_budget(name, f"figure {self.id!r}: ")
            for env, own in [(None, at), *(getattr(at, "envs", None) or {}).items()]:
                if not isinstance(own, At):
                    where = f" for env {env!r}" if env else ""
                    raise TypeError(f"figure {self.id!r}: the override of budget {name!r}{where} is a "
                                    f"{type(own).__name__}; write At(...) with Budget fields")

    def budget(self, name: str, env: str | None = None) -> Budget:
        """This figure's budget ``name`` (for the curves on ``env``, if it has its own)."""
        own = self.budgets.get(name, At())
        per_env = (own.envs or {}).get(env, At())
        return replace(get_budget(name), **{**own.given(), **per_env.given()})

    def runs(self, budget: str) -> list["Run"]:
        """This figure's runs at a budget: curve by curve, seed by seed."""
        trained = get_budget(budget).figures  # a bad name fails here, even for a figure without runs at it
        if (self.runs_at is not None and budget not in self.runs_at) or (trained is not None and self.id not in trained):
            return []
        envs, runs = self.envs(budget), []
        for label, kw in self.curves:
            env = {**self.common, **kw}.get("env", TrainConfig.env)
            if envs is not None and env not in envs:
                continue
            b = self.budget(budget, env)
            seeds = b.seeds if self.seeds is None else b.seeds[:self.seeds]
            runs += [Run(self.id, label, _config(b, seed=s, **{**self.common, **kw}), self.cpus, self.gpus,
                         self.memory_gb) for s in seeds]
        return runs

    def envs(self, name: str) -> tuple[str, ...] | None:
        """The envs this figure runs at budget ``name`` (None: every curve's)."""
        envs = self.budgets.get(name, At()).envs
        return None if envs is None else tuple(envs)


@dataclass(frozen=True)
class Run:
    """One training run of a figure and what it needs (for a Ray cluster)."""

    figure: str
    label: object
    cfg: TrainConfig
    cpus: float = 1.0
    gpus: float = 0.0
    memory_gb: float = 0.0


def _config(b: Budget, **kw) -> TrainConfig:
    """A run's config at budget ``b``; A2C runs take the shape that evaluates them at the PPO
    family's env steps (``a2c_family.beside_ppo``)."""
    from oapo_lite.neural.a2c_family import beside_ppo  # imports torch: not for the catalogue's names (--help)

    kw, budget = {**b.config, **kw}, dict(steps=b.steps, eval_every=b.eval_every, eval_episodes=b.eval_episodes)
    if budget.keys() & kw.keys():
        raise ValueError(f"a curve or budget config sets {sorted(budget.keys() & kw.keys())}, which the budget decides")
    kw |= budget
    return TrainConfig(**(beside_ppo(kw) if ALGOS[kw["algo"]].a2c else kw))
