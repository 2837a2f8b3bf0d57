"""A run's state between iterations, and the files that keep it: ``RunState`` holds everything
that carries over (env, actors, learner, generators, history, evaluation rows); its
``state_dict`` *is* the checkpoint, so what is saved and what is resumed cannot drift apart.

A checkpoint is data: tensors, numbers, strings, bytes, lists, tuples, dicts and sets, numpy
arrays and scalars of booleans, numbers and strings. It is read with torch's restricted
unpickler (``weights_only=True``), which builds nothing but those (``DATA``): a run folder
someone else wrote or changed can hold wrong numbers, never code that runs when it is read."""
from __future__ import annotations

import dataclasses
import json
import os
import pickle
import re
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from oapo_lite.algorithms import ALGOS
from oapo_lite.envs.vec import DATA_KINDS, VecStep
from oapo_lite.neural import seps
from oapo_lite.neural.a2c_family import A2CFamilyLearner
from oapo_lite.neural.config import TrainConfig, derive_seed
from oapo_lite.neural.learner import Learner
from oapo_lite.neural.nets import Actors, owners
from oapo_lite.neural.normalize import Moments, Normalized
from oapo_lite.neural.ppo_family import PPOFamilyLearner
from oapo_lite.neural.rollout import make_env
from oapo_lite.neural.seps import group_labels
from oapo_lite.store import DamagedFile, atomic_write, regular_file, write_frame

START_AFRESH = "start afresh (resume=False; on the command line --no-resume) or use another output folder"
# the keys under which a checkpoint before the layer folders kept its learner's state: the PPO family's at the top
PPO_KEYS_BEFORE = ("critic", "value_norm", "critic_opt", "np_rng")

# What a numpy array or scalar is pickled with beyond torch's own types: the functions that
# rebuild them, and the dtypes they may have: booleans, integers, floats, complex numbers and
# fixed-width strings, in every width numpy names (an object dtype would hold objects: left out).
# torch pickles with protocol 2, which writes empty bytes (an empty array's data) as a call of
# bytes(), and a frozenset as a call of frozenset
DATA_DTYPES = sorted({type(np.dtype(c)) for c in np.typecodes["All"] if np.dtype(c).kind in DATA_KINDS},
                     key=lambda t: t.__name__)
DATA = [np.ndarray, np.dtype, np.zeros(0).__reduce__()[0], np.float64(0).__reduce__()[0], bytes, frozenset,
        *DATA_DTYPES]
# The two objects a checkpoint written before issue 54 holds, read only to be turned into data
# (``_from_old_layout``): the envs' last step, and SePS's buffer during pre-training (before
# issue 35 pickled by the module's old path)
OLD_LAYOUT = [VecStep, seps.Buffer, (seps.Buffer, "oapo_lite.seps.Buffer")]
ALLOWED = DATA + OLD_LAYOUT


def allowed_names(entries: list = ALLOWED) -> list[str]:
    """The names pickles give ``entries`` (by default every global a checkpoint may name beyond torch's own)."""
    return [entry[1] if isinstance(entry, tuple) else f"{entry.__module__}.{entry.__qualname__}" for entry in entries]


def git_revision() -> str:
    """HEAD of the checkout the code runs from; ``OAPO_GIT_REV`` when set (a Ray worker runs a
    copy of the package shipped by the driver, outside any checkout, and is given the driver's)."""
    if os.environ.get("OAPO_GIT_REV"):
        return os.environ["OAPO_GIT_REV"]
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True,
                             text=True, timeout=10)
        return out.stdout.strip() if out.returncode == 0 else "unknown"
    except OSError:
        return "unknown"


@dataclass
class RunState:
    """Everything a run carries from one iteration to the next. ``start`` builds it from a config
    (always in the same order: a run is reproducible from its seed); ``learner`` is its
    algorithm family's (``learner.Learner``)."""

    cfg: TrainConfig
    env: object
    eval_env: object
    actors: Actors
    learner: Learner
    act_gen: torch.Generator  # the actions of the rollouts
    step: object  # the envs' last step: where the next rollout starts
    iteration: int = 0
    history: list = field(default_factory=list)  # per-iteration metrics
    rows: list = field(default_factory=list)  # the evaluation rows: results.csv
    # what the run has cost so far (``cost.Meter``); None: unmeasured (resumed from a checkpoint
    # written before costs were recorded)
    cost: dict | None = field(default_factory=lambda: {"cpu_s": 0.0, "wall_s": 0.0})

    @classmethod
    def start(cls, cfg: TrainConfig) -> "RunState":
        env = make_env(cfg, cfg.n_envs, seed=cfg.seed)
        eval_env = make_env(cfg, cfg.eval_episodes, seed=derive_seed(cfg.seed, 2))
        if cfg.normalize:  # the evaluation reads the training copies' statistics
            moments = Moments.of(env)
            env, eval_env = Normalized(env, moments, cfg.gamma, train=True), Normalized(eval_env, moments, cfg.gamma,
                                                                                      train=False)
        torch.manual_seed(cfg.seed)
        init_gen = torch.Generator().manual_seed(cfg.seed)
        owner = owners(cfg.networks_used, env.agent_types)
        actors = Actors(max(owner) + 1, env.obs_dim, env.n_actions, cfg.hidden, env.continuous, init_gen, cfg.feature_norm)
        learner = (A2CFamilyLearner if ALGOS[cfg.algo].a2c else PPOFamilyLearner)(cfg, env, actors, init_gen, owner)
        act_gen = torch.Generator().manual_seed(derive_seed(cfg.seed, 1))
        return cls(cfg, env, eval_env, actors, learner, act_gen, env.reset())

    @property
    def owner(self) -> list[int]:
        """The net of every seat (SePS regroups its seats once its pre-training ends)."""
        return self.learner.owner

    def state_dict(self) -> dict:
        return {"config": self.cfg.flat(), "iteration": self.iteration, "actors": self.actors.state_dict(),
                "learner": self.learner.state_dict(), "act_gen": self.act_gen.get_state(), "torch_rng": torch.get_rng_state(),
                "env": self.env.get_state(), "step": dataclasses.asdict(self.step), "history": self.history,
                "rows": self.rows, "cost": self.cost}

    def load_state_dict(self, ck: dict, path: Path | str = "") -> None:
        """Continue from checkpoint ``ck`` (``check_resumable`` first). A run extended to more
        steps has no row where the shorter budget ended off the evaluation grid (evaluating draws
        no shared randomness, so dropping it changes nothing else), and its rows carry the new config."""
        name = f"checkpoint {path}".rstrip()
        check_resumable(self.cfg, ck, name)
        try:
            self.actors.load_state_dict(ck["actors"])
            self.learner.load_state_dict(ck["learner"] if "learner" in ck else learner_state_before(ck))
            self.act_gen.set_state(ck["act_gen"])
            torch.set_rng_state(ck["torch_rng"])
            self.env.set_state(ck["env"])
            self.iteration, self.step, self.history = ck["iteration"], VecStep(**ck["step"]), ck["history"]
            self.cost = ck.get("cost")  # absent: the run so far was not measured
        except KeyError as err:
            raise ValueError(f"{name} has no entry {err} (written by an older oapo_lite); {START_AFRESH}") from None
        except (RuntimeError, TypeError, ValueError, IndexError, AttributeError) as err:
            # shapes, generator states, an env's state: what this run cannot take
            detail = " ".join(str(err).split())[:160]
            raise DamagedFile(f"{name} does not fit this run ({type(err).__name__}: {detail}); {START_AFRESH}") from None
        config = self.cfg.flat()
        self.rows = [{**r, **config, **(self.structure(r) if "owner" not in r else {})} for r in ck["rows"]
                     if self.cfg.evaluates(r["iteration"])]

    def structure(self, row: dict | None = None) -> dict:
        """What the run is (``results.STRUCTURE``): the seats' networks now, or those of a checkpoint's
        ``row`` written before the rows recorded them (SePS regroups once: a row names its groups)."""
        owner = self.owner
        if row is not None and self.cfg.algo == "seps":
            groups = row.get("seps_groups")
            owner = group_labels(groups, self.env.agents) if isinstance(groups, str) else [0] * len(owner)
        return {"owner": np.array(owner), "agent_types": json.dumps(list(self.env.agent_types))}

    def save(self, out: Path) -> None:
        """``results.csv`` and ``checkpoint.pt``, each written atomically."""
        save_results(self.rows, out)
        state = self.state_dict()
        atomic_write(lambda p: torch.save(state, p), out / "checkpoint.pt")


def save_results(rows: list[dict], out: Path) -> None:
    write_frame(pd.DataFrame(rows), out / "results.csv")


def load_checkpoint(out_dir: str | Path) -> dict:
    """The last checkpoint of a run directory (parameters, optimisers, RNG states, metrics), read
    as data only (``read_data``); ``store.DamagedFile`` naming it if it cannot be read or holds
    anything else."""
    path = Path(out_dir) / "checkpoint.pt"
    ck = read_data(path)
    if not isinstance(ck, dict) or "config" not in ck:
        raise DamagedFile(f"checkpoint {path} is not an oapo_lite checkpoint; {START_AFRESH}")
    _from_old_layout(ck)
    why = _inconsistent(ck)
    if why:
        raise DamagedFile(f"checkpoint {path} is damaged: {why}; {START_AFRESH}")
    return ck


def read_data(path: Path) -> object:
    """What ``torch.save`` wrote to ``path``, built by torch's restricted unpickler from data
    alone (``ALLOWED``); ``store.DamagedFile`` naming the file, and the types it refused if it
    holds others: nothing in such a file is run."""
    regular_file(path, "checkpoint")  # a FIFO would block torch.load, and the rerun it advised, forever
    try:
        with torch.serialization.safe_globals(ALLOWED):
            return torch.load(path, weights_only=True)
    except (FileNotFoundError, PermissionError):  # absent or unreadable, not damaged: starting afresh would lose it
        raise
    except Exception as err:  # truncated, empty or foreign bytes, or types beyond ALLOWED: torch raises many kinds
        refused = _refused(path, str(err)) if isinstance(err, pickle.UnpicklingError) else []
        if refused:
            raise DamagedFile(f"checkpoint {path} holds {refused}, which a checkpoint may not hold (it is read as data "
                              f"only: tensors, numbers, strings, lists, dicts, numpy arrays); nothing in it was run; "
                              f"{START_AFRESH}") from None
        detail = str(err).split(". ")[0][:120] or "no detail"
        raise DamagedFile(f"checkpoint {path} is damaged and cannot be read ({type(err).__name__}: {detail}); "
                          f"{START_AFRESH}") from None


def _refused(path: Path, error: str) -> list[str]:
    """The types or functions the restricted unpickler refused in ``path``: the globals its
    pickle names beyond ``ALLOWED`` (listed without unpickling anything), else the class torch's
    error says it would not build."""
    try:
        named = [g for g in torch.serialization.get_unsafe_globals_in_checkpoint(path) if g not in allowed_names()]
    except Exception:  # not a zip of a pickle: torch's error says what was wrong
        named = []
    return named or re.findall(r"(?:Unsupported global: GLOBAL |but got <class ')([\w.]+)", error)


def _from_old_layout(ck: dict) -> None:
    """A checkpoint written before issue 54 in place as data: the envs' last step was a
    ``VecStep`` and SePS's pre-training buffer a ``seps.Buffer``; both become what
    ``RunState.state_dict`` writes now."""
    if isinstance(ck.get("step"), VecStep):
        ck["step"] = dict(vars(ck["step"]))
    for learner in (ck.get("learner"), ck.get("a2c")):  # "a2c": the layout before issue 35
        if isinstance(learner, dict) and isinstance(learner.get("buffer"), seps.Buffer):
            learner["buffer"] = getattr(learner["buffer"], "parts", learner["buffer"])


# what every checkpoint holds (the learner's state under "learner", or, before it had one, its
# keys at the top level: ``learner_state_before``)
CHECKPOINT_KEYS = ("config", "iteration", "actors", "act_gen", "torch_rng", "env", "step", "history", "rows")


def _inconsistent(ck: dict) -> str | None:
    """What is missing from a checkpoint or contradicts itself, or None: every entry a run needs,
    of its type; its iteration, one history entry per iteration, and its evaluation rows (the
    first before training, in order, none past the iteration)."""
    missing = [k for k in CHECKPOINT_KEYS if k not in ck] + ([] if "learner" in ck or "critic" in ck or "a2c" in ck
                                                            else ["learner"])
    if missing:
        return f"it has no entries {missing}"
    kinds = {"config": dict, "actors": dict, "act_gen": torch.Tensor, "torch_rng": torch.Tensor}
    wrong = [k for k, kind in kinds.items() if not isinstance(ck[k], kind)]
    wrong += [] if isinstance(ck["step"], dict) else ["step"]
    wrong += [] if ck["env"] is not None else ["env"]
    wrong += [] if ck.get("cost") is None or (isinstance(ck["cost"], dict) and all(
        isinstance(ck["cost"].get(k), float) and ck["cost"][k] >= 0 for k in ("cpu_s", "wall_s"))) else ["cost"]
    if "learner" in ck and not (isinstance(ck["learner"], dict) and ck["learner"]):
        wrong.append("learner")
    if wrong:
        return f"its entries {wrong} are not what a run writes there"
    it, history, rows = ck.get("iteration"), ck.get("history"), ck.get("rows")
    if not isinstance(it, int) or isinstance(it, bool) or it < 0:
        return f"its iteration is {it!r}, not an integer >= 0"
    if not isinstance(history, list) or len(history) != it:
        return f"it is at iteration {it} but holds {len(history) if isinstance(history, list) else history!r} " \
               "history entries"
    if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) and "iteration" in r for r in rows):
        return "its evaluation rows are missing or not a list of rows"
    seen = [r["iteration"] for r in rows]
    if seen[0] != 0 or any(b <= a for a, b in zip(seen, seen[1:])) or seen[-1] > it:
        return f"its evaluation rows are at iterations {seen}, not from 0 upwards to at most {it}"
    for key in ("cpu_s", "wall_s") if ck.get("cost") is not None else ():  # the run's sums go on from its cost
        last = rows[-1].get(key)
        if isinstance(last, float) and last > ck["cost"][key]:
            return f"its cost {key} = {ck['cost'][key]!r} is below its last row's {last!r}; a sum so far never falls"
    return None


def nonfinite(ck: dict, keys) -> list[str]:
    """The entries below ``keys`` of checkpoint ``ck`` (nets, optimisers) that hold a NaN or an
    infinity, as paths such as ``actors/net0.body.0.weight``."""
    found = []

    def walk(value, at: str) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                walk(v, f"{at}/{k}")
        elif isinstance(value, (list, tuple)):
            for k, v in enumerate(value):
                walk(v, f"{at}/{k}")
        elif isinstance(value, torch.Tensor) and value.is_floating_point():
            if not torch.isfinite(value).all():
                found.append(at)
        elif isinstance(value, np.ndarray) and value.dtype.kind == "f" and not np.isfinite(value).all():
            found.append(at)

    for key in keys:
        walk(ck.get(key), key)
    return found


def learner_state_before(ck: dict) -> dict:
    """The learner's state of a checkpoint written before the learner had the one key "learner":
    the A2C family's was under "a2c", the PPO family's keys were at the top level."""
    if "a2c" in ck:
        return ck["a2c"]
    return {k: v for k, v in ck.items() if k in PPO_KEYS_BEFORE or k.startswith("actor_opt")}


def load_history(out_dir: str | Path) -> list[dict]:
    """A run's per-iteration metrics (losses, K, M, the mapping drawn, ...), one dict per
    iteration, from the checkpoint where they are kept with the rest of the run state."""
    return load_checkpoint(out_dir)["history"]


def check_resumable(cfg: TrainConfig, ck: dict, name: str = "checkpoint") -> None:
    """A checkpoint (``name``: "checkpoint" and its path, in the messages) can continue ``cfg`` if
    it has every current field and only ``steps`` differs, and grows."""
    now, saved = cfg.flat(), ck["config"]
    missing = [k for k in now if k not in saved]
    if missing:
        raise ValueError(f"{name} has no config fields {missing} (written by an older oapo_lite); {START_AFRESH}")
    differ = [k for k in now if k != "steps" and str(now[k]) != str(saved[k])]
    if differ:
        raise ValueError(f"{name} was written by a different config (fields {differ}); {START_AFRESH}")
    stale = [f.name for f in dataclasses.fields(VecStep) if f.name not in ck["step"]]
    if stale:
        raise ValueError(f"{name}'s environment step has no fields {stale} (written by an older oapo_lite); "
                         f"{START_AFRESH}")
    if cfg.lr_anneal and str(now["steps"]) != str(saved["steps"]) and ck["iteration"] > 0:
        raise ValueError(f"{name} was written with steps = {saved['steps']}, and with lr_anneal the learning rate's "
                         f"schedule depends on steps, so it cannot continue with steps = {cfg.steps}; {START_AFRESH}")
    if ck["iteration"] > cfg.n_iterations:
        raise ValueError(f"{name} is at iteration {ck['iteration']} (steps = {saved['steps']}), past steps = "
                         f"{cfg.steps} ({cfg.n_iterations} iterations); resuming needs steps >= {saved['steps']}; "
                         f"or {START_AFRESH}")

