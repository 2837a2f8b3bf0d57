"""SMAX (JaxMARL's JAX re-implementation of SMAC) behind the ``VecEnv`` interface (``envs.vec``).

``n_envs`` copies of one scenario against SMAX's heuristic enemy are stepped by ONE jitted,
vmapped call (auto-reset inside it); its outputs come back as one pytree of host arrays
(``jax.device_get``, a buffer copy per field, no Python loop over copies). The controlled
agents are the allies, in SMAX's order. Per step:

- ``reward``: SMAX's team reward (enemy health removed / number of enemies, + 1 on a win);
- ``terminated``: one side is wiped out; ``truncated``: the ``max_steps`` limit came first;
- ``episode_success``: a win, as SMAC counts it: every enemy dead and at least one ally
  alive (a simultaneous wipe-out is a draw, and SMAX gives it no win bonus either);
- ``active``: the ally is alive. A dead ally sees zeros and may only take no-op (action 4),
  and the training loop ignores its samples (HARL's active masks).

JAX compiles the step once per process and batch shape, which takes tens of seconds; the
compiled executables are cached here, the compile time is printed once, and JAX's persistent
compilation cache (``OAPO_JAX_CACHE``, default ``~/.cache/oapo_lite/jax``; empty to disable)
lets later processes on the same machine load them instead.
"""
from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from .vec import VecStep, check_copies

# SMAX's own scenarios (jaxmarl 0.2.0), and stand-ins registered here: unit types by index
# (0 marine, 1 marauder, 2 stalker, 3 zealot, 4 zergling, 5 hydralisk), allies then enemies.
SCENARIOS = ("3m", "2s3z", "25m", "3s5z", "8m", "5m_vs_6m", "10m_vs_11m", "27m_vs_30m", "3s5z_vs_3s6z",
             "3s_vs_5z", "6h_vs_8z", "smacv2_5_units", "smacv2_10_units", "smacv2_20_units")
STANDINS = {
    # SMAC's MMM2 is 1 medivac, 2 marauders, 7 marines against 1 medivac, 3 marauders,
    # 8 marines. SMAX has no medivac (no healing), so both medivacs are dropped.
    "MMM2_like_7m2M_vs_8m3M": ((0,) * 7 + (1,) * 2, (0,) * 8 + (1,) * 3),
}
MAPS = SCENARIOS + tuple(STANDINS)
NOOP = 4  # SMAX's "stop": the only action of a dead unit


def check(name: str) -> None:
    """Raise ``ValueError`` naming the scenarios if ``name`` is not one (imports no JAX)."""
    if name not in MAPS:
        raise ValueError(f"unknown SMAX scenario {name!r}; scenarios are {list(MAPS)} "
                         f"(this project's stand-ins, see ASSUMPTIONS.md: {list(STANDINS)})")


def _jaxmarl_smax():
    """``jaxmarl.environments.smax``, imported quietly and with ``sys.stdout`` and ``sys.stderr``
    kept: importing jaxmarl replaces ``sys.stdout`` by a plain stream, which in a notebook kernel
    sends every later print to the kernel's terminal instead of the notebook, and then prints
    two lines about environments it does not find, which land in whichever output captures the
    process's file descriptor 1 (a notebook cell under one runner, a terminal under another)."""
    if "jaxmarl.environments.smax" in sys.modules:
        return sys.modules["jaxmarl.environments.smax"]
    out, err = sys.stdout, sys.stderr
    out.flush()
    saved, quiet = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(quiet, 1)
    try:
        import jaxmarl.environments.smax as smax
    finally:
        sys.stdout.flush()  # the stream jaxmarl put there: its lines go to /dev/null
        os.dup2(saved, 1)
        os.close(saved)
        os.close(quiet)
        sys.stdout, sys.stderr = out, err
    return smax


def agent_types(name: str) -> tuple[str, ...]:
    """The unit type of every ally of scenario ``name``, read from the scenario (nothing compiled)."""
    scenario = _scenario(name)
    names = _jaxmarl_smax().SMAX(scenario=scenario).unit_type_names
    return tuple(names[int(t)] for t in scenario.unit_types[:scenario.num_allies])


def _scenario(name: str):
    import jax.numpy as jnp

    smax = _jaxmarl_smax()
    if name in STANDINS:
        allies, enemies = STANDINS[name]
        return smax.Scenario(jnp.array(allies + enemies, dtype=jnp.uint8), len(allies), len(enemies), False, False)
    return smax.map_name_to_scenario(name)


def _persistent_cache() -> None:
    import jax

    path = os.environ.get("OAPO_JAX_CACHE", str(Path.home() / ".cache" / "oapo_lite" / "jax"))
    if path and jax.config.jax_compilation_cache_dir is None:
        jax.config.update("jax_compilation_cache_dir", path)


class _Compiled:
    """One scenario's jitted, vmapped reset and step (per process, per (name, max_steps))."""

    def __init__(self, name: str, max_steps: int):
        import jax
        import jax.numpy as jnp
        HeuristicEnemySMAX = _jaxmarl_smax().HeuristicEnemySMAX

        _persistent_cache()
        env = HeuristicEnemySMAX(scenario=_scenario(name), max_steps=max_steps)
        self.name, self.env = name, env
        n = env.num_allies
        agents = env.agents

        def view(state):
            obs = env.get_obs(state)
            avail = env.get_avail_actions(state)
            return (jnp.stack([obs[a] for a in agents]), env.get_world_state(state),
                    jnp.stack([avail[a] for a in agents]).astype(bool), state.state.unit_alive[:n])

        def reset_one(key):
            key, sub = jax.random.split(key)
            _, state = env.reset(sub)
            return (key, state, jnp.float32(0)), view(state)

        def step_one(carry, actions):
            key, state, ret = carry
            key, k_step, k_reset = jax.random.split(key, 3)
            _, state, rewards, _, _ = env.step_env(k_step, state, {a: actions[i] for i, a in enumerate(agents)})
            alive = state.state.unit_alive
            allies_dead, enemies_dead = ~alive[:n].any(), ~alive[n:].any()
            terminated = allies_dead | enemies_dead
            done = state.state.done  # SMAX: a side wiped out, or step >= max_steps
            reward = rewards[agents[0]]  # the team reward, the same for every ally
            ret = ret + reward
            final = view(state)
            (_, fresh, _), fresh_view = reset_one(k_reset)
            pick = lambda a, b: jnp.where(done, a, b)  # noqa: E731
            state = jax.tree.map(pick, fresh, state)
            now = jax.tree.map(pick, fresh_view, final)
            nan = jnp.float32(jnp.nan)
            out = dict(obs=now[0], state=now[1], avail=now[2], active=now[3], reward=reward,
                       terminated=terminated, truncated=done & ~terminated, final_obs=final[0],
                       final_state=final[1], episode_return=jnp.where(done, ret, nan),
                       episode_success=jnp.where(done, (enemies_dead & ~allies_dead).astype(jnp.float32), nan))
            return (key, state, jnp.where(done, 0.0, ret)), out

        self.reset_fn = jax.jit(jax.vmap(reset_one))
        self.step_fn = jax.jit(jax.vmap(step_one))
        self.executables: dict[int, tuple] = {}

    def for_batch(self, n_envs: int):
        """(reset, step) compiled for ``n_envs`` copies; compiled (and timed) on first use."""
        if n_envs not in self.executables:
            import jax
            import jax.numpy as jnp

            tic = time.perf_counter()
            keys = jax.random.split(jax.random.PRNGKey(0), n_envs)
            reset = self.reset_fn.lower(keys).compile()
            carry, _ = reset(keys)
            actions = jnp.zeros((n_envs, self.env.num_allies), dtype=jnp.int32)
            self.executables[n_envs] = (reset, self.step_fn.lower(carry, actions).compile())
            print(f"smax {self.name}: JAX compiled {n_envs} copies in {time.perf_counter() - tic:.1f} s "
                  "(once per process and batch size)", file=sys.stderr, flush=True)
        return self.executables[n_envs]


_CACHE: dict[tuple[str, int], _Compiled] = {}


def compiled(name: str, max_steps: int) -> _Compiled:
    check(name)
    if (name, max_steps) not in _CACHE:
        _CACHE[name, max_steps] = _Compiled(name, max_steps)
    return _CACHE[name, max_steps]


class SmaxVec:
    """``n_envs`` copies of SMAX scenario ``name`` with auto-reset (see the module docstring).

    ``reset()`` seeds copy k from ``(seed, k)``, so every evaluation that resets starts from
    the same episodes; auto-resets continue each copy's own key.
    """

    def __init__(self, name: str, n_envs: int, seed: int = 0, max_steps: int = 100):
        self.n_envs, self.max_steps = check_copies(n_envs, max_steps)
        self.seed = int(seed)
        self._c = compiled(name, self.max_steps)
        env = self._c.env
        self.name = name
        self.agents = tuple(env.agents)
        self.agent_types = agent_types(name)
        self.n_agents = env.num_allies
        self.n_actions = env.num_ally_actions
        self.obs_dim = env.obs_size
        self.state_dim = env.state_size
        self.continuous = False
        self.time_in_state, self.optimum = False, math.nan  # no clock in the state; no oracle
        self._reset, self._step = self._c.for_batch(self.n_envs)
        self._carry = None

    def reset(self) -> VecStep:
        import jax

        keys = jax.random.split(jax.random.PRNGKey(self.seed), self.n_envs)
        self._carry, view = self._reset(keys)
        obs, state, avail, active = map(np.array, view)
        return VecStep.at_reset(obs, state, avail, active)

    def step(self, actions) -> VecStep:
        """Step every copy by ``actions[env, ally]`` (ints in 0..n_actions-1)."""
        a = np.asarray(actions)
        if a.shape != (self.n_envs, self.n_agents):
            raise ValueError(f"actions must have shape (n_envs, n_agents) = {(self.n_envs, self.n_agents)}, "
                             f"got {a.shape}")
        if not np.issubdtype(a.dtype, np.integer) or a.min() < 0 or a.max() >= self.n_actions:
            raise ValueError(f"actions must be integers in 0..{self.n_actions - 1}, got dtype {a.dtype}, "
                             f"range {a.min()}..{a.max()}")
        if self._carry is None:
            raise RuntimeError("call reset() before step()")
        self._carry, out = self._step(self._carry, a.astype(np.int32))
        # np.array: one host copy per field, writable (torch.from_numpy needs that)
        return VecStep(**{k: np.array(v) for k, v in out.items()})

    def get_state(self) -> dict:
        """The copies' keys, game states and running returns as host arrays (for checkpoints)."""
        import jax

        leaves, _ = jax.tree.flatten(self._carry)
        return {"scenario": self.name, "leaves": [np.asarray(x).copy() for x in jax.device_get(leaves)]}

    def set_state(self, d: dict) -> None:
        """Restore what ``get_state`` returned; the continuation is then bit-identical."""
        import jax
        import jax.numpy as jnp

        if d.get("scenario") != self.name:
            raise ValueError(f"state is of SMAX scenario {d.get('scenario')!r}, this env runs {self.name!r}")
        if self._carry is None:
            self.reset()
        leaves, tree = jax.tree.flatten(self._carry)
        if [np.shape(x) for x in d["leaves"]] != [x.shape for x in leaves]:
            raise ValueError(f"state does not fit {self.n_envs} copies of {self.name!r}")
        self._carry = jax.tree.unflatten(tree, [jnp.asarray(x, dtype=y.dtype) for x, y in zip(d["leaves"], leaves)])


def make_vec(name: str, n_envs: int, seed: int, max_steps: int) -> SmaxVec:
    return SmaxVec(name, n_envs, seed, max_steps)
