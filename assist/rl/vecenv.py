"""stable-baselines3 on a gymnasium vector environment: :class:`SB3VecEnv`.

SB3's algorithms take a ``stable_baselines3.common.vec_env.VecEnv``, whose contract differs from
gymnasium's vector API: ``reset()`` returns only observations, ``step`` returns ``(obs, reward, done,
infos)`` with one info dict per env, and an env whose episode ends is reset *in the same step*, its last
observation in ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]`` set when the
end was a time limit. :class:`SB3VecEnv` gives that contract over a gymnasium ``VectorEnv`` in
``NEXT_STEP`` autoreset mode (such as :class:`ptw_env.vector.PTWRollVectorEnv`): the envs that end are
reset at once with ``reset(options={"reset_mask": done})``, which continues each env's generator exactly
as the autoreset would. ``infos[i]["cost"]`` carries the safety cost when the env reports one.

>>> import gymnasium as gym, numpy as np, ptw_env
>>> from assist.rl.vecenv import SB3VecEnv
>>> venv = SB3VecEnv(gym.make_vec("PTWRollNorm-v0", num_envs=2, vectorization_mode="vector_entry_point"))
>>> venv.seed(0) and None
>>> venv.reset().shape
(2, 7)
>>> obs, reward, done, infos = venv.step(np.zeros((2, 1), dtype=np.float32))
>>> reward.shape, "cost" in infos[0]
((2,), True)
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

try:
    from stable_baselines3.common.vec_env import VecEnv
except ImportError:  # the [rl] extra is optional
    VecEnv = object  # type: ignore[misc,assignment]


class SB3VecEnv(VecEnv):  # type: ignore[misc,valid-type]
    """SB3 ``VecEnv`` over a gymnasium ``VectorEnv`` with ``NEXT_STEP`` autoreset and ``reset_mask`` support."""

    def __init__(self, venv: Any) -> None:
        if VecEnv is object:
            raise ImportError('SB3VecEnv needs stable-baselines3: pip install "ptw-assist[rl]"')
        from gymnasium.vector import AutoresetMode

        if venv.metadata.get("autoreset_mode") != AutoresetMode.NEXT_STEP:
            raise ValueError(f"SB3VecEnv needs a vector env in NEXT_STEP autoreset mode, got {venv.metadata.get('autoreset_mode')}")
        self.venv = venv
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self.render_mode = getattr(venv, "render_mode", None)
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        seeds = self._seeds
        seed = None if all(s is None for s in seeds) else [None if s is None else int(s) for s in seeds]
        obs, _ = self.venv.reset(seed=seed)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """The vector env's step in SB3's form (module docstring): ended envs reset at once."""
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        done = terminated | truncated
        cost = info.get("cost")
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)] if cost is None else [{"cost": float(c)} for c in cost]
        if done.any():
            for i in np.flatnonzero(done):
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            new_obs, _ = self.venv.reset(options={"reset_mask": done})
            obs[done] = new_obs[done]
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.venv, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        return [getattr(self.venv, method_name)(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [self.venv.render()]
