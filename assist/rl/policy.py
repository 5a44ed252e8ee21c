"""The RL baseline at run time: the observation encoder and the trained policy (:func:`load_policy`), and the
controller adapter of :mod:`assist.evaluate` (:class:`RLAdapter`). stable-baselines3 is needed to read a
policy file (:func:`require_sb3`). See :mod:`assist.rl` for the method."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ptw_env.env import OBS_NAMES, PTWRollEnv
from ptw_env.sensors import CHANNEL_RANGES, channel_ranges
from ptw_env.vehicle import REFERENCE_SCOOTER

#: Algorithms of ``ptw-assist train-rl --algo``.
ALGOS = ("ppo", "sac")
#: The shipped policy (trained by the command in ``policies/ppo_roll.json``).
DEFAULT_POLICY = Path(__file__).resolve().parents[1] / "policies" / "ppo_roll.zip"
#: Version of the observation encoding stored in a policy file.
ENCODER_FORMAT = 1
EXTRA_HINT = 'pip install "ptw-assist[rl]"'


class RLUnavailableError(ImportError, ValueError):
    """stable-baselines3 or torch is missing (the message names the extra to install)."""


class PolicyError(ValueError):
    """A bad RL request: unknown algorithm, bad step count, unusable policy file."""


def require_sb3():
    """Import stable-baselines3 and torch, or raise :class:`RLUnavailableError` naming the extra.

    Returns
    -------
    (module, module)
        ``stable_baselines3`` and ``torch``.
    """
    try:
        import stable_baselines3
        import torch
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise RLUnavailableError(
            f"the RL baseline needs stable-baselines3 and torch ({exc.name} is missing); "
            f"install the optional extra: {EXTRA_HINT}"
        ) from None
    return stable_baselines3, torch


# ----------------------------------------------------------------------------- observation
#: Channel order of the environment's observation.
OBS_CHANNELS = OBS_NAMES[:7]  # the default observation (no roll channel)
#: Channels that change sign when the ride is mirrored left/right (all but vx).
_MIRROR = np.array([-1, -1, -1, -1, -1, 1, -1], dtype=np.float32)


def _default_scales(r: Mapping[str, float] = CHANNEL_RANGES) -> tuple[float, ...]:
    # vx: centred at 15 m/s, scale 10 m/s (applied in ObsEncoder); phi_ref like the roll channel
    return (r["delta"], r["delta_rate"], r["yaw_rate"], r["roll_rate"], r["ay"], 10.0, r["roll"])


@dataclass
class ObsEncoder:
    """The policy's input, built from the environment's noisy observations only.

    ``z_k = clip((obs_k - center) / scale, -clip, clip)`` per channel
    (scales: the sensor ranges of :data:`ptw_env.sensors.CHANNEL_RANGES`
    [rad, rad/s, rad/s, rad/s, m/s^2], 10 m/s around 15 m/s for ``vx``,
    0.5 rad for ``phi_ref``), the last ``frames`` of them stacked newest
    first, then the previous action in ``[-1, 1]`` if ``prev_action``.
    Before the first step the history holds copies of the first sample and
    the previous action is 0.

    Parameters
    ----------
    frames : int
        Number of stacked observations (10 ms apart).
    prev_action : bool
        Append the previous (normalised) action.
    scale, center : sequence of 7 floats
        Per-channel scaling, in the units of the observation.
    clip : float
        Bound of the scaled features.
    """

    frames: int = 8
    prev_action: bool = True
    scale: tuple[float, ...] = field(default_factory=_default_scales)
    center: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 15.0, 0.0)
    clip: float = 10.0

    def __post_init__(self) -> None:
        if isinstance(self.frames, bool) or not isinstance(self.frames, int) or self.frames < 1:
            raise PolicyError(f"ObsEncoder.frames must be an integer >= 1, got {self.frames!r}")
        self.scale = tuple(float(s) for s in self.scale)
        self.center = tuple(float(c) for c in self.center)
        if len(self.scale) != 7 or len(self.center) != 7 or min(self.scale) <= 0:
            raise PolicyError("ObsEncoder.scale and center must hold 7 numbers (scales > 0)")
        self._inv_scale = 1.0 / np.array(self.scale, dtype=np.float32)
        self._center = np.array(self.center, dtype=np.float32)
        self._buf = np.zeros(self.dim, dtype=np.float32)

    @property
    def dim(self) -> int:
        """Length of the encoded observation."""
        return 7 * self.frames + (1 if self.prev_action else 0)

    def config(self) -> dict[str, Any]:
        """JSON-able settings (stored in the policy file)."""
        return {"format": ENCODER_FORMAT, "frames": self.frames, "prev_action": self.prev_action,
                "scale": list(self.scale), "center": list(self.center), "clip": self.clip}

    @classmethod
    def for_speeds(cls, vmin: float, vmax: float, vehicle: Any = None, **kwargs: Any) -> "ObsEncoder":
        """The encoder whose ``vx`` feature spans ``[vmin, vmax]`` [m/s] as ``[-1, 1]`` (centre the middle, scale
        half the width) and whose other channels are scaled by ``vehicle``'s channel ranges
        (:func:`ptw_env.sensors.channel_ranges`); for training on a vehicle's speed range."""
        if not (0 < vmin < vmax and math.isfinite(vmax)):
            raise PolicyError(f"ObsEncoder.for_speeds needs 0 < vmin < vmax [m/s], got {vmin!r}, {vmax!r}")
        base = cls(**{"scale": _default_scales(channel_ranges(vehicle)), **kwargs})
        scale, center = list(base.scale), list(base.center)
        i = OBS_CHANNELS.index("vx")
        center[i], scale[i] = 0.5 * (vmin + vmax), 0.5 * (vmax - vmin)
        return cls(**{**kwargs, "scale": tuple(scale), "center": tuple(center)})

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "ObsEncoder":
        if cfg.get("format") != ENCODER_FORMAT:
            raise PolicyError(f"policy observation format {cfg.get('format')!r} is not {ENCODER_FORMAT} (this version)")
        return cls(frames=int(cfg["frames"]), prev_action=bool(cfg["prev_action"]), scale=tuple(cfg["scale"]),
                   center=tuple(cfg["center"]), clip=float(cfg["clip"]))

    def _scaled(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        if obs.shape[-1:] != (7,):
            raise PolicyError(f"expected the 7-channel observation {OBS_CHANNELS}, got shape {obs.shape}")
        z = (obs - self._center) * self._inv_scale
        np.minimum(z, self.clip, out=z)
        np.maximum(z, -self.clip, out=z)
        return z

    def reset_into(self, obs: np.ndarray, buf: np.ndarray) -> None:
        """Start episodes at observations ``obs`` (N, 7): their encoded vectors into ``buf`` (N, :attr:`dim`)."""
        z = self._scaled(obs)
        buf[:, : 7 * self.frames] = np.tile(z, (1, self.frames))
        if self.prev_action:
            buf[:, -1] = 0.0

    def step_into(self, obs: np.ndarray, action: np.ndarray, buf: np.ndarray) -> None:
        """Push observations ``obs`` (N, 7) that followed normalised actions ``action`` (N,) into ``buf``
        (N, :attr:`dim`): the history shifts by one frame, the newest first."""
        n = 7 * self.frames
        buf[:, 7:n] = buf[:, : n - 7]
        buf[:, :7] = self._scaled(obs)
        if self.prev_action:
            buf[:, -1] = np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0)

    def reset(self, obs: np.ndarray) -> np.ndarray:
        """Start an episode at observation ``obs``; returns the encoded vector."""
        self.reset_into(np.asarray(obs)[None], self._buf[None])
        return self._buf.copy()

    def step(self, obs: np.ndarray, action: float) -> np.ndarray:
        """Push observation ``obs`` that followed normalised ``action``; returns the encoded vector."""
        self.step_into(np.asarray(obs)[None], np.array([float(action)]), self._buf[None])
        return self._buf.copy()


# ----------------------------------------------------------------------------- training env
@dataclass
class RLPolicy:
    """A loaded policy: the SB3 model, its observation encoder and its metadata.

    ``act(obs)`` maps a raw environment observation to the steering torque
    [N m] (deterministic); call ``reset`` at the start of every episode.
    """

    model: Any
    encoder: ObsEncoder
    meta: dict[str, Any]
    path: Path | None = None

    @property
    def algo(self) -> str:
        return str(self.meta.get("algo", "?"))

    @property
    def tau_max(self) -> float:
        return float(self.meta.get("tau_max", 60.0))

    def __post_init__(self) -> None:
        self._layers = _numpy_actor(self.model)

    def normalized_action(self, encoded: np.ndarray) -> float:
        """Deterministic action in ``[-1, 1]`` for an encoded observation.

        Runs the actor network in numpy (``model.predict`` computes the same
        to float32 rounding, ~20x slower per call); falls back to
        ``model.predict`` for networks it does not know.
        """
        if self._layers is None:
            a, _ = self.model.predict(encoded, deterministic=True)
            a = float(np.ravel(a)[0])
        else:
            h = np.asarray(encoded, dtype=np.float32)
            for kind, W, b in self._layers:
                if kind == "linear":
                    h = W @ h + b
                elif kind == "tanh":
                    h = np.tanh(h)
                else:
                    h = np.maximum(h, 0.0)
            a = float(h[0])
        return min(max(a, -1.0), 1.0)


def _numpy_actor(model: Any) -> list[tuple[str, np.ndarray | None, np.ndarray | None]] | None:
    """The deterministic actor of a PPO or SAC MLP policy as numpy layers (None if not recognised)."""
    import torch.nn as nn
    from stable_baselines3 import PPO, SAC

    pol = model.policy
    if isinstance(model, PPO):
        if type(pol.features_extractor).__name__ != "FlattenExtractor":
            return None
        mods = list(pol.mlp_extractor.policy_net) + [pol.action_net]
        squash = False
    elif isinstance(model, SAC):
        actor = pol.actor
        if type(actor.features_extractor).__name__ != "FlattenExtractor" or actor.use_sde:
            return None
        mods = list(actor.latent_pi) + [actor.mu]
        squash = True
    else:
        return None
    layers: list[tuple[str, np.ndarray | None, np.ndarray | None]] = []
    for m in mods:
        if isinstance(m, nn.Linear):
            layers.append(("linear", m.weight.detach().cpu().numpy().astype(np.float32),
                           m.bias.detach().cpu().numpy().astype(np.float32)))
        elif isinstance(m, nn.Tanh):
            layers.append(("tanh", None, None))
        elif isinstance(m, nn.ReLU):
            layers.append(("relu", None, None))
        else:
            return None
    if squash:
        layers.append(("tanh", None, None))
    return layers


def _load_meta(path: Path) -> tuple[dict[str, Any] | None, Any]:
    from stable_baselines3.common.save_util import load_from_zip_file

    try:
        data, _, _ = load_from_zip_file(path, device="cpu", load_data=True)
    except Exception as exc:  # zipfile.BadZipFile, KeyError, ...
        raise PolicyError(f"{path}: not a stable-baselines3 policy file ({type(exc).__name__}: {exc})") from None
    if not data:
        raise PolicyError(f"{path}: not a stable-baselines3 policy file (no model data)")
    return data.get("ptw_rl"), data.get("observation_space")


def load_policy(path: str | os.PathLike | None = None) -> RLPolicy:
    """Load a policy written by :func:`train` (default: the shipped :data:`DEFAULT_POLICY`).

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    PolicyError
        Not a stable-baselines3 file, or trained for another observation
        (shape or encoding) than this version's :class:`ObsEncoder`.
    RLUnavailableError
        stable-baselines3 / torch are not installed.
    """
    require_sb3()
    p = Path(path) if path is not None else DEFAULT_POLICY
    if not p.is_file():
        raise FileNotFoundError(f"policy file {p} not found" + (" (the shipped policy is missing from the install)"
                                                                   if path is None else ""))
    meta, obs_space = _load_meta(p)
    shape = tuple(getattr(obs_space, "shape", ()) or ())
    if not meta:
        expect = ObsEncoder().dim
        raise PolicyError(
            f"{p}: trained for observations of shape {shape}, not by ptw-assist train-rl (no encoder settings); "
            f"this version's RL encoder gives shape ({expect},): train a policy with 'ptw-assist train-rl'"
        )
    _check_meta(p, meta)
    try:
        encoder = ObsEncoder.from_config(meta["encoder"])
    except PolicyError as e:
        raise PolicyError(f"{p}: {e}") from None
    except (KeyError, TypeError, ValueError) as e:
        raise PolicyError(f"{p}: unusable encoder settings in the policy file ({type(e).__name__}: {e})") from None
    if shape != (encoder.dim,):
        raise PolicyError(f"{p}: the policy expects observations of shape {shape} but its encoder gives ({encoder.dim},)")
    algo = meta.get("algo")
    if algo not in ALGOS:
        raise PolicyError(f"{p}: unknown algorithm {algo!r} in the policy file; known: {', '.join(ALGOS)}")
    cls = _algo_class(algo)
    try:
        model = cls.load(p, device="cpu")
    except Exception as e:  # a damaged zip, a model of another algorithm than its metadata says
        raise PolicyError(f"{p}: stable-baselines3 cannot load it as a {algo} model ({type(e).__name__}: {e})") from None
    return RLPolicy(model=model, encoder=encoder, meta=dict(meta), path=p)


def _check_meta(p: Path, meta: Any) -> None:
    """One clear :class:`PolicyError` naming the file and the key for unusable ptw-assist metadata."""
    if not isinstance(meta, Mapping):
        raise PolicyError(f"{p}: the policy's ptw-assist settings are a {type(meta).__name__}, not a mapping")
    if not isinstance(meta.get("encoder"), Mapping):
        raise PolicyError(f"{p}: no encoder settings ('encoder') in the policy file")
    for key in ("dt", "tau_max"):
        v = meta.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise PolicyError(f"{p}: '{key}' in the policy file must be a positive number, got {v!r}")


def _algo_class(algo: str):
    sb3, _ = require_sb3()
    return {"ppo": sb3.PPO, "sac": sb3.SAC}[algo]



class RLAdapter:
    """The RL policy as a controller of :func:`assist.evaluate.run_episode` (``"rl"``).

    Parameters
    ----------
    env : PTWRollEnv
        The evaluation environment (torque action in N m, ``dt`` 10 ms).
    policy : str, path or RLPolicy, optional
        A policy file from ``ptw-assist train-rl`` (default: the shipped policy). It must have been
        trained on the environment's vehicle (the policy's ``vehicle``; a policy without one was trained
        on the reference scooter).
    """

    name = "rl"

    def __init__(self, env: PTWRollEnv, policy: str | os.PathLike | RLPolicy | None = None) -> None:
        self.policy = policy if isinstance(policy, RLPolicy) else load_policy(policy)
        if env.observe_roll:
            raise PolicyError("the RL policy is trained without the roll angle; use observe_roll=False")
        trained_on = self.policy.meta.get("vehicle") or REFERENCE_SCOOTER.identity()  # before 'vehicle' was kept
        if not isinstance(trained_on, Mapping) or \
                trained_on.get("model_sha256") != env.vehicle.identity()["model_sha256"]:
            name = trained_on.get("name") if isinstance(trained_on, Mapping) else trained_on
            raise PolicyError(f"the policy was trained on the vehicle {name!r}, the environment rides "
                              f"{env.vehicle.name!r}: train one for it with 'ptw-assist train-rl --vehicle'")
        dt = float(self.policy.meta.get("dt", 0.01))
        if abs(env.dt - dt) > 1e-12:
            raise PolicyError(f"the policy runs at dt = {dt} s, the environment at {env.dt} s")
        self._normalized = env.normalize_action  # then the action is the policy's, else N m
        self._enc = ObsEncoder.from_config(self.policy.encoder.config())  # own history: policies can be shared
        self._started = False
        self._a = 0.0

    def reset(self) -> None:
        self._started = False
        self._a = 0.0

    def act(self, obs: np.ndarray, info: dict[str, Any]) -> float:
        enc = self._enc
        x = enc.step(obs, self._a) if self._started else enc.reset(obs)
        self._started = True
        self._a = self.policy.normalized_action(x)
        return self._a if self._normalized else self._a * self.policy.tau_max

    @property
    def x_hat(self) -> None:
        return None


# ----------------------------------------------------------------------------- training

__all__ = ["ALGOS", "DEFAULT_POLICY", "ENCODER_FORMAT", "OBS_CHANNELS", "ObsEncoder", "PolicyError", "RLAdapter",
           "RLPolicy", "RLUnavailableError", "load_policy", "require_sb3"]
