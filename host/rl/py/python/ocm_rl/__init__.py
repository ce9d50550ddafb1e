"""Gymnasium environments of the ocm soft manipulator's rigid-link surrogate.

The physics, tasks and rewards are the Rust crate ``ocm-rl`` (``ocm_rl._native``); this module
wraps them as a :class:`gymnasium.Env` (:class:`OcmEnv`) and a
:class:`gymnasium.vector.VectorEnv` (:class:`OcmVectorEnv`, stepped on a Rust thread pool).

Observations: 40 float32 values scaled to order one (joint positions and velocities, TCP position
and velocity, the force on the TCP, the next target, its offset from the TCP, the target force).
Actions: three float32 values in [-1, 1], the absolute grouped joint commands (bend about x, bend
about y, extension), each the middle of its range plus the value times its half-width; values
outside are clipped (``info["clipped"]``), NaN and infinities raise ``ValueError``. An episode
is 100 steps, one per target point, then ``truncated``; ``terminated`` when the TCP is lost
(more than 50 mm from its target). Seeds: ``reset(seed=s)`` plays the Rust episode of seed ``s``.

The robot comes from ``model`` (the ``surrogate.json`` written by ``ocm surrogate map``) or from
``chain`` (the chain geometry, a dict or JSON, with the default joint limits).
"""

from __future__ import annotations

import json
from typing import Any, Optional, Union

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _native

__all__ = ["OcmEnv", "OcmVectorEnv", "TASKS", "OBS_DIM", "ACT_DIM", "env_id"]

#: Task names: circle, star, weight, force, ellipse.
TASKS: tuple = tuple(_native.TASKS)
#: Observation length.
OBS_DIM: int = int(_native.OBS_DIM)
#: Action length.
ACT_DIM: int = int(_native.ACT_DIM)

_SEED_LIMIT = 2**63  # episode seeds drawn by seedless resets stay below this


def _chain_json(chain: Union[None, str, dict]) -> Optional[str]:
    if chain is None or isinstance(chain, str):
        return chain
    return json.dumps(dict(chain))


def _model_path(model: Any) -> Optional[str]:
    return None if model is None else str(model)


def _spaces(low: float, high: float, size: int) -> spaces.Box:
    return spaces.Box(low=low, high=high, shape=(size,), dtype=np.float32)


def _info(raw: dict) -> dict:
    """A step's info with the vectors as float64 arrays (m, N)."""
    out = dict(raw)
    for key in ("tcp_m", "target_m", "force_n", "force_target_n"):
        out[key] = np.asarray(raw[key], dtype=np.float64)
    return out


class OcmEnv(gymnasium.Env):
    """One environment of ``task`` (see :data:`TASKS`) as a ``gymnasium.Env``.

    Settings left at ``None`` keep the defaults of ``ocm-rl``: ``substeps`` physics steps of 1 ms
    per action (50), ``init_noise`` of the first command in action units (0.02),
    ``lost_distance_m`` (0.05).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        task: str = "circle",
        model: Any = None,
        chain: Union[None, str, dict] = None,
        substeps: Optional[int] = None,
        init_noise: Optional[float] = None,
        lost_distance_m: Optional[float] = None,
        render_mode: Optional[str] = None,
    ):
        if render_mode is not None:
            raise ValueError(f"render_mode {render_mode!r} is not supported (None only)")
        self.render_mode = None
        self._env = _native.Env(
            task, _model_path(model), _chain_json(chain), substeps, init_noise, lost_distance_m
        )
        self.task = self._env.task
        self.control_period_s = self._env.control_period_s
        self.max_episode_steps = self._env.max_episode_steps
        self.observation_space = _spaces(*self._env.observation_bounds, self._env.observation_size)
        self.action_space = _spaces(*self._env.action_bounds, self._env.action_size)

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        """Starts an episode: the Rust episode of ``seed``, or one drawn from ``np_random``."""
        super().reset(seed=seed)
        episode_seed = int(seed) if seed is not None else int(self.np_random.integers(_SEED_LIMIT))
        obs = self._env.reset(episode_seed)
        return np.asarray(obs, dtype=np.float32), {"episode_seed": episode_seed}

    def step(self, action):
        """One control period; a ``ValueError`` for NaN, infinite or wrongly sized actions."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        obs, reward, terminated, truncated, info = self._env.step(a.tolist())
        return np.asarray(obs, dtype=np.float32), float(reward), terminated, truncated, _info(info)

    def expert_action(self) -> np.ndarray:
        """The inverse-model expert's action for the next target (for imitation learning)."""
        return np.asarray(self._env.expert_action(), dtype=np.float32)

    def command_of_action(self, action) -> np.ndarray:
        """Grouped joint command (rad, rad, m) of a normalised action."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        return np.asarray(self._env.command_of_action(a.tolist()), dtype=np.float64)


class OcmVectorEnv(VectorEnv):
    """``num_envs`` environments of ``task`` stepped together by Rust on ``threads`` threads.

    Same-step autoreset like ``gymnasium.vector.SyncVectorEnv`` in ``SAME_STEP`` mode: a finished
    environment is reset within the step, its last observation is in ``infos["final_obs"]`` and its
    step info in ``infos["final_info"]``. ``reset(seed=s)`` gives environment i the episode of seed
    ``s + i``; its k-th automatic reset plays seed ``s + i + k * num_envs``.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self,
        task: str = "circle",
        num_envs: int = 8,
        threads: int = 1,
        model: Any = None,
        chain: Union[None, str, dict] = None,
        substeps: Optional[int] = None,
        init_noise: Optional[float] = None,
        lost_distance_m: Optional[float] = None,
        render_mode: Optional[str] = None,
    ):
        if render_mode is not None:
            raise ValueError(f"render_mode {render_mode!r} is not supported (None only)")
        self.render_mode = None
        single = _native.Env(
            task, _model_path(model), _chain_json(chain), substeps, init_noise, lost_distance_m
        )
        self._env = _native.VecEnv(
            task,
            num_envs,
            threads,
            _model_path(model),
            _chain_json(chain),
            substeps,
            init_noise,
            lost_distance_m,
        )
        self.num_envs = self._env.num_envs
        self.task = single.task
        self.single_observation_space = _spaces(*single.observation_bounds, single.observation_size)
        self.single_action_space = _spaces(*single.action_bounds, single.action_size)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    def _obs(self, flat) -> np.ndarray:
        return np.asarray(flat, dtype=np.float32).reshape(self.num_envs, -1)

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        """Resets every environment (environment i plays seed ``seed + i``)."""
        if seed is not None and not isinstance(seed, (int, np.integer)):
            raise ValueError(
                f"seed must be an int or None (environment i plays seed + i), not {seed!r}"
            )
        super().reset(seed=seed)
        base = int(seed) if seed is not None else int(self.np_random.integers(_SEED_LIMIT))
        obs = self._obs(self._env.reset(base))
        infos = {
            "episode_seed": base + np.arange(self.num_envs, dtype=np.int64),
            "_episode_seed": np.ones(self.num_envs, dtype=bool),
        }
        return obs, infos

    def step(self, actions):
        """Steps every environment with its row of ``actions`` (``num_envs x 3``)."""
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (self.num_envs, ACT_DIM):
            raise ValueError(f"actions have shape {a.shape}, expected {(self.num_envs, ACT_DIM)}")
        obs, rewards, terminated, truncated, final_obs, raw_infos = self._env.step(
            a.reshape(-1).tolist()
        )
        infos: dict = {}
        for i, (last, raw) in enumerate(zip(final_obs, raw_infos)):
            if last is None:
                infos = self._add_info(infos, _info(raw), i)
            else:
                final = {
                    "final_obs": np.asarray(last, dtype=np.float32),
                    "final_info": _info(raw),
                }
                infos = self._add_info(infos, final, i)
        return (
            self._obs(obs),
            np.asarray(rewards, dtype=np.float64),
            np.asarray(terminated, dtype=bool),
            np.asarray(truncated, dtype=bool),
            infos,
        )

    def expert_actions(self) -> np.ndarray:
        """The expert's actions of every environment, ``num_envs x 3``."""
        return np.asarray(self._env.expert_actions(), dtype=np.float32).reshape(self.num_envs, -1)


def env_id(task: str) -> str:
    """The Gymnasium id of a task, e.g. ``ocm_rl/Circle-v0``."""
    return f"ocm_rl/{task.capitalize()}-v0"


for _task in TASKS:
    if env_id(_task) not in gymnasium.registry:
        gymnasium.register(
            id=env_id(_task),
            entry_point="ocm_rl:OcmEnv",
            vector_entry_point="ocm_rl:OcmVectorEnv",
            kwargs={"task": _task},
            disable_env_checker=False,
        )
