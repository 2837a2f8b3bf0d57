"""Any PettingZoo ``ParallelEnv`` behind the ``VecEnv`` interface (``envs.vec``).

The generic path: ``n_envs`` copies stepped one after another (environments we do not own
cannot be vectorised for them). Agents come in ``possible_agents`` order; the team reward
of a step is the mean of the agents' rewards; observations of agents whose spaces are
smaller are zero-padded, and so are discrete action sets (padded actions are unavailable).
Agents that have left ``env.agents`` before the episode ends are marked inactive
(``VecStep.active``): they get no action, and training ignores their samples.

A checkpoint holds the copies as data (``snapshot``): each object's attributes, down to numbers,
strings and arrays, and numpy generators' states; functions and classes stay the env's own. A
resumed run writes them back into the copies ``env_fn`` made (``restore``), so reading a
checkpoint builds no object of a type it names.
"""
from __future__ import annotations

import copyreg
import functools
import math
import types
from typing import Callable

import numpy as np
from gymnasium import spaces

from .vec import DATA_KINDS, VecStep, check_copies


def _flat_obs(obs) -> tuple[np.ndarray, np.ndarray | None]:
    """(flat observation, action mask or None) of one agent's raw observation."""
    mask = None
    if isinstance(obs, dict) and "observation" in obs:
        mask = obs.get("action_mask")
        obs = obs["observation"]
    return np.asarray(obs, dtype=np.float32).ravel(), mask


def _obs_size(space: spaces.Space) -> int:
    if isinstance(space, spaces.Dict) and "observation" in space.spaces:
        space = space["observation"]
    return int(np.prod(space.shape))


class PettingZooVec:
    """``n_envs`` copies of ``env_fn()`` with auto-reset, presenting ``VecMaze``'s interface.

    ``reset()`` seeds copy k with ``seed + k`` (so every evaluation that resets starts from
    the same episodes); auto-resets after an episode continue the copy's own randomness.
    The global state is ``env.state()`` when the environment implements it, otherwise the
    concatenated observations. Action masks come
    from an ``action_mask`` key of a dict observation or of the info dict; Box action spaces
    give continuous actions (``continuous = True``), clipped to their bounds when stepping.
    ``max_steps`` (optional) truncates episodes that the environment itself lets run on.
    ``episode_success`` is read from an ``episode_success`` info entry (NaN without one).
    """

    def __init__(self, env_fn: Callable[[], object], n_envs: int, seed: int = 0, max_steps: int | None = None):
        self.n_envs, self.max_steps = check_copies(n_envs, max_steps, own_limit=True)
        self.envs = [env_fn() for _ in range(self.n_envs)]
        self.seed = int(seed)
        first = self.envs[0]
        self.agents = tuple(first.possible_agents)
        # every seat its own type unless the env says otherwise (``agent_types``: one name per seat)
        self.agent_types = tuple(getattr(first, "agent_types", self.agents))
        if len(self.agent_types) != len(self.agents):
            raise ValueError(f"the env's agent_types {list(self.agent_types)} must name one type per agent "
                             f"of {list(self.agents)}")
        self.n_agents = len(self.agents)
        self.time_in_state, self.optimum = False, math.nan  # no clock in the state; no oracle
        self.spaces = tuple((first.observation_space(a), first.action_space(a)) for a in self.agents)
        acts = [act for _, act in self.spaces]
        kinds = {type(a) for a in acts}
        if kinds == {spaces.Discrete}:
            self.continuous = False
            self.n_actions = max(int(a.n) for a in acts)
        elif kinds == {spaces.Box} and len({a.shape for a in acts}) == 1:
            self.continuous = True
            self.n_actions = int(np.prod(acts[0].shape))
        else:
            raise ValueError(
                "PettingZooVec needs all-Discrete action spaces, or Box spaces of one shape; got "
                + ", ".join(f"{a}: {s}" for a, s in zip(self.agents, acts))
            )
        self.obs_dim = max(_obs_size(o) for o, _ in self.spaces)
        state = self._try_state(first)
        self._has_state = state is not None
        # an env may implement state() without declaring state_space (MaMuJoCo does)
        self.state_dim = (int(np.prod(getattr(first, "state_space", state).shape)) if self._has_state
                          else sum(_obs_size(o) for o, _ in self.spaces))
        self._t = np.zeros(self.n_envs, dtype=np.int64)
        self._returns = np.zeros(self.n_envs, dtype=np.float64)

    @staticmethod
    def _try_state(env) -> np.ndarray | None:
        try:
            return np.asarray(env.state(), dtype=np.float32).ravel()
        except (NotImplementedError, AttributeError):
            return None

    def _view(self, env, obs: dict, infos: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(obs (n, obs_dim), avail (n, A), state, active (n,)) of one copy; agents without an
        observation read as zeros, and agents no longer in ``env.agents`` are inactive."""
        o = np.zeros((self.n_agents, self.obs_dim), dtype=np.float32)
        avail = np.ones((self.n_agents, self.n_actions), dtype=bool)
        for k, agent in enumerate(self.agents):
            if not self.continuous:
                avail[k, self.spaces[k][1].n:] = False
            if agent not in obs:
                continue
            flat, mask = _flat_obs(obs[agent])
            o[k, : flat.size] = flat  # the rest stays zero: padding up to the largest space
            mask = mask if mask is not None else infos.get(agent, {}).get("action_mask")
            if mask is not None and not self.continuous:
                avail[k, : len(mask)] = np.asarray(mask, dtype=bool)
        state = self._try_state(env) if self._has_state else self._concat_obs(obs)
        return o, avail, state, np.array([a in env.agents for a in self.agents])

    def _concat_obs(self, obs: dict) -> np.ndarray:
        """The global state of an environment without ``state()``: every agent's raw observation."""
        return np.concatenate([_flat_obs(obs[a])[0] if a in obs else np.zeros(_obs_size(s), np.float32)
                               for a, (s, _) in zip(self.agents, self.spaces)])

    def _reset_copy(self, k: int, seed: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        obs, infos = self.envs[k].reset(seed=seed)
        self._t[k], self._returns[k] = 0, 0.0
        return self._view(self.envs[k], obs, infos)

    def reset(self) -> VecStep:
        views = [self._reset_copy(k, self.seed + k) for k in range(self.n_envs)]
        obs, avail, state, active = (np.stack(v) for v in zip(*views))
        return VecStep.at_reset(obs, state, avail, active)

    def _env_action(self, k: int, a):
        space = self.spaces[k][1]
        return np.clip(a, space.low, space.high).astype(space.dtype) if self.continuous else int(a)

    def step(self, actions) -> VecStep:
        """``actions`` (N, n) ints, or (N, n, D) floats for Box spaces."""
        N = self.n_envs
        out = {key: [] for key in ("obs", "avail", "state", "active", "final_obs", "final_state")}
        reward = np.zeros(N, np.float32)
        terminated, truncated = np.zeros(N, bool), np.zeros(N, bool)
        ep_return, ep_success = np.full(N, np.nan, np.float32), np.full(N, np.nan, np.float32)
        for e, env in enumerate(self.envs):
            live = list(env.agents)
            obs, rew, term, trunc, infos = env.step(
                {a: self._env_action(k, actions[e][k]) for k, a in enumerate(self.agents) if a in live})
            team = sum(float(rew[a]) for a in live) / len(live) if live else 0.0
            reward[e] = team
            self._t[e] += 1
            self._returns[e] += team
            terminated[e] = bool(live) and all(term.get(a, False) for a in live)
            truncated[e] = not terminated[e] and (
                not env.agents or all(term.get(a, False) or trunc.get(a, False) for a in live)
                or (self.max_steps is not None and self._t[e] >= self.max_steps))
            final = self._view(env, obs, infos)
            if terminated[e] or truncated[e]:
                ep_return[e] = self._returns[e]
                ep_success[e] = next((i["episode_success"] for i in infos.values() if "episode_success" in i), np.nan)
                now = self._reset_copy(e, None)
            else:
                now = final
            for key, value in zip(("obs", "avail", "state", "active"), now):
                out[key].append(value)
            out["final_obs"].append(final[0])
            out["final_state"].append(final[2])
        o = {key: np.stack(v) for key, v in out.items()}
        return VecStep(obs=o["obs"], state=o["state"], avail=o["avail"], reward=reward, terminated=terminated,
                       truncated=truncated, final_obs=o["final_obs"], final_state=o["final_state"],
                       episode_return=ep_return, episode_success=ep_success, active=o["active"])

    def get_state(self) -> dict:
        """The environment copies as data (``snapshot``) and the episode counters (for checkpoints)."""
        return {"envs": snapshot(self.envs, "envs"), "t": self._t.copy(), "returns": self._returns.copy()}

    def set_state(self, d: dict) -> None:
        if not isinstance(d["envs"], list) or len(d["envs"]) != self.n_envs:
            raise ValueError(f"state must hold {self.n_envs} environment copies, got {type(d['envs']).__name__} "
                             f"of {len(d['envs'])}")
        self.envs = restore(self.envs, d["envs"], "envs")
        self._t, self._returns = np.array(d["t"], np.int64), np.array(d["returns"], np.float64)


# a snapshot's own entries are dicts with this key (a dict of the env's own with it is wrapped as one)
MARK = "__oapo_lite__"
# what stays as it is: immutable data
PLAIN = (type(None), bool, int, float, complex, str, bytes, np.generic, np.dtype)
# code an env holds (its factory, callbacks): never stored, the resumed copy keeps its own
CODE = (types.FunctionType, types.BuiltinFunctionType, types.MethodType, types.ModuleType, type, functools.partial)
GENERATORS = {g.__name__: g for g in (np.random.PCG64, np.random.PCG64DXSM, np.random.MT19937, np.random.Philox,
                                      np.random.SFC64)}


def snapshot(obj, path: str, memo: dict | None = None):
    """``obj`` as data a checkpoint can hold: containers element by element, a numpy
    ``Generator`` as its bit generator's state, an object as its type's name and its pickled
    state (its ``__dict__``, or what its ``__getstate__`` gives), code as a marker. An object met
    twice is one snapshot, so ``restore`` keeps it one object (and a cycle ends). ``TypeError``
    naming ``path`` for anything else (an object kept in C or pickled by its own ``__reduce__``,
    an array of objects)."""
    memo = {} if memo is None else memo
    if isinstance(obj, PLAIN):
        if isinstance(obj, (np.generic, np.dtype)):
            _check_kind(obj.dtype if isinstance(obj, np.generic) else obj, path)
        return obj
    if id(obj) in memo:
        return memo[id(obj)][1]
    if isinstance(obj, np.ndarray):
        _check_kind(obj.dtype, path)
        return _remember(memo, obj, obj.copy())
    if isinstance(obj, tuple):  # immutable: a cycle through it passes a list, dict or object first
        return _remember(memo, obj, tuple(snapshot(x, f"{path}[{k}]", memo) for k, x in enumerate(obj)))
    if isinstance(obj, (set, frozenset)):
        if not all(isinstance(x, PLAIN) for x in obj):
            raise TypeError(f"{path} is a set of objects; a checkpoint holds sets of numbers and strings")
        return _remember(memo, obj, type(obj)(obj))
    if isinstance(obj, list):
        out = _remember(memo, obj, [])
        out.extend(snapshot(x, f"{path}[{k}]", memo) for k, x in enumerate(obj))
    elif isinstance(obj, dict):
        pairs = []
        out = _remember(memo, obj, {MARK: "dict", "items": pairs} if MARK in obj else {})
        pairs.extend((_key(k, path), snapshot(v, f"{path}[{k!r}]", memo)) for k, v in obj.items())
        if MARK not in obj:
            out.update(pairs)
    elif isinstance(obj, np.random.Generator):
        out = _remember(memo, obj, {MARK: "generator", "state": snapshot(obj.bit_generator.state, path, memo)})
    elif isinstance(obj, CODE):
        out = _remember(memo, obj, {MARK: "code"})
    else:
        out = _remember(memo, obj, {MARK: "object", "type": _name(type(obj))})
        out["state"] = {_key(k, path): snapshot(v, f"{path}.{k}", memo) for k, v in _state(obj, path).items()}
    return out


def _remember(memo: dict, obj, out):
    memo[id(obj)] = (obj, out)  # obj kept alive: its id is not reused while the snapshot is taken
    return out


def restore(live, saved, path: str, memo: dict | None = None):
    """What ``saved`` (a ``snapshot``) describes, written into the objects of ``live`` at the
    same places: an object's state goes into the live object of its type there, a generator's
    into a generator; no object is made from a name. ``ValueError`` naming ``path`` where
    ``live`` has no object of the saved type."""
    memo = {} if memo is None else memo
    if isinstance(saved, PLAIN):
        return saved
    if id(saved) in memo:
        return memo[id(saved)]
    if isinstance(saved, np.ndarray):
        memo[id(saved)] = saved.copy()  # the snapshot stays as it was: it may be restored again
    elif isinstance(saved, tuple):
        items = live if isinstance(live, tuple) and len(live) == len(saved) else (None,) * len(saved)
        memo[id(saved)] = tuple(restore(x, s, f"{path}[{k}]", memo) for k, (x, s) in enumerate(zip(items, saved)))
    elif isinstance(saved, (set, frozenset)):
        memo[id(saved)] = type(saved)(saved)
    elif isinstance(saved, list):
        items = live if isinstance(live, list) and len(live) == len(saved) else [None] * len(saved)
        out = memo[id(saved)] = []
        out.extend(restore(x, s, f"{path}[{k}]", memo) for k, (x, s) in enumerate(zip(items, saved)))
    elif isinstance(saved, dict) and saved.get(MARK) in ("object", "generator", "code"):
        memo[id(saved)] = _restore_entry(live, saved, path, memo)
    elif isinstance(saved, dict):
        old = live if isinstance(live, dict) else {}
        out = memo[id(saved)] = {}
        for k, v in (saved["items"] if saved.get(MARK) == "dict" else saved.items()):
            out[k] = restore(old.get(k), v, f"{path}[{k!r}]", memo)
    else:
        raise TypeError(f"{path} holds a {type(saved).__name__}, which no snapshot holds")
    return memo[id(saved)]


def _restore_entry(live, saved: dict, path: str, memo: dict):
    kind = saved[MARK]
    if kind == "code":
        if live is None:
            raise ValueError(f"{path}: the checkpoint kept code there, and this env has none")
        return live
    if kind == "generator":
        state = restore(None, saved["state"], path, memo)
        name = state.get("bit_generator") if isinstance(state, dict) else None
        if name not in GENERATORS:
            raise ValueError(f"{path}: bit generator {name!r} is not one of {sorted(GENERATORS)}")
        gen = live if isinstance(live, np.random.Generator) and type(live.bit_generator).__name__ == name else \
            np.random.Generator(GENERATORS[name]())
        gen.bit_generator.state = state
        return gen
    if _name(type(live)) != saved["type"]:
        raise ValueError(f"{path} held a {saved['type']}; this env has a {_name(type(live))} there")
    if not isinstance(saved["state"], dict):
        raise ValueError(f"{path}: the state of a {saved['type']} must be a dict of its attributes")
    memo[id(saved)] = live  # the same object met again below (a cycle) is this one
    old = _state(live, path)
    state = {k: restore(old.get(k), v, f"{path}.{k}", memo) for k, v in saved["state"].items()}
    if hasattr(live, "__setstate__"):  # its own way of taking its state back (gymnasium's spaces have one)
        live.__setstate__(state)
    else:
        vars(live).update(state)
    return live


def _name(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def _check_kind(dtype: np.dtype, path: str) -> None:
    if dtype.kind not in DATA_KINDS:
        raise TypeError(f"{path} holds numpy data of dtype {dtype}; a checkpoint holds booleans, numbers and strings")


def _state(obj, path: str) -> dict:
    """What pickling ``obj`` stores besides its type (``copyreg``'s protocol 4: its ``__dict__``,
    or what its own ``__getstate__`` gives), for a plain Python object only."""
    try:
        reduced = obj.__reduce_ex__(4)
    except TypeError as err:
        raise TypeError(f"{path} is a {_name(type(obj))}, which a checkpoint cannot hold as data ({err})") from None
    plain = isinstance(reduced, tuple) and reduced[0] is copyreg.__newobj__ and reduced[1] == (type(obj),) and \
        all(x is None for x in reduced[3:])
    state = reduced[2] if plain and len(reduced) > 2 else None
    if not isinstance(state, dict):
        raise TypeError(f"{path} is a {_name(type(obj))}, which a checkpoint cannot hold as data: only plain objects "
                        "(state in their attributes), numbers, strings, arrays, containers and numpy generators")
    return state


def _key(key, path: str):
    if isinstance(key, PLAIN) or (isinstance(key, tuple) and all(isinstance(k, PLAIN) for k in key)):
        return key
    raise TypeError(f"{path} has a key of type {type(key).__name__}; a checkpoint holds keys of numbers and strings")
