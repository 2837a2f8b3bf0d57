"""Environment names: a built-in maze, a map text, or ``<engine>:<name>`` for a real engine.

An engine is a module with ``check(name)`` (raise ``ValueError`` naming the allowed names;
cheap, without importing the engine itself) and ``make_vec(name, n_envs, seed, max_steps)``
(a vector env as ``envs/vec.py`` describes it). Engines are imported only
when used, so a user without, say, JAX still trains on the mazes. An engine that is optional
(not in environment.txt) also provides ``install_hint()``: None when it is installed, else how
to install it.
"""
from __future__ import annotations

import importlib

from .core import make_vec as make_maze_vec
from .maps import load_maze

ENGINES: dict[str, str] = {  # prefix -> module path
    "layout": "oapo_lite.envs.layouts",
    "smax": "oapo_lite.envs.smax",
    "mamujoco": "oapo_lite.envs.mamujoco",
    "grf": "oapo_lite.envs.grf",
}


def split(spec: str) -> tuple[str | None, str]:
    """``"smax:3m"`` -> ("smax", "3m"); a maze name or map text -> (None, spec)."""
    prefix, sep, name = spec.partition(":")
    if sep and "\n" not in spec:  # a map text has several lines (and an "agents:" header)
        if prefix not in ENGINES:
            raise ValueError(f"unknown engine {prefix!r} in env {spec!r}; engines are {sorted(ENGINES)}")
        return prefix, name
    return None, spec


def _engine(prefix: str):
    return importlib.import_module(ENGINES[prefix])


def missing_engine(prefix: str) -> str | None:
    """How to install engine ``prefix`` if this Python lacks it, else None."""
    hint = getattr(_engine(prefix), "install_hint", None)
    return hint() if hint else None


def check(spec: str) -> None:
    """Raise a clear error for an env name that does not exist."""
    prefix, name = split(spec)
    if prefix is None:
        load_maze(name)  # MapError names the built-in maps
    else:
        _engine(prefix).check(name)


def maze_of(spec: str):
    """The ``Maze`` behind a maze env (built-in, map text or generated layout), else None."""
    prefix, name = split(spec)
    if prefix is None:
        return load_maze(name)
    if prefix == "layout":
        return _engine(prefix).load_layout(name)
    return None


def make_vec(spec: str, n_envs: int, seed: int, max_steps: int):
    prefix, name = split(spec)
    if prefix is None:
        return make_maze_vec(name, n_envs, max_steps, copy=False)
    return _engine(prefix).make_vec(name, n_envs, seed, max_steps)


def agent_types(spec: str, max_steps: int) -> tuple[str, ...]:
    """The agent type of each seat of ``spec`` (``env.agent_types``), from the engine's scenario where it
    can tell without building (SMAX: no compile), else from a one-copy env."""
    prefix, name = split(spec)
    engine = None if prefix is None else _engine(prefix)
    if engine is not None and hasattr(engine, "agent_types"):
        return engine.agent_types(name)
    return make_vec(spec, 1, 0, max_steps).agent_types


def agent_names(spec: str, max_steps: int) -> tuple[str, ...]:
    """The name of each seat of ``spec`` (``env.agents``), from the engine where it can tell
    without building (GRF: its players), else from a one-copy env."""
    prefix, name = split(spec)
    engine = None if prefix is None else _engine(prefix)
    if engine is not None and hasattr(engine, "agent_names"):
        return engine.agent_names(name)
    return tuple(make_vec(spec, 1, 0, max_steps).agents)
