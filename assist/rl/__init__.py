"""Reinforcement-learning baseline: a stable-baselines3 policy for roll tracking from the noisy sensors.

Needs the optional extra ``pip install "ptw-assist[rl]"`` (stable-baselines3
and torch); everything else in the package works without it, and this module
imports without it too (the error comes when a function needs the extra).

What the policy sees
--------------------
Only the noisy observation of :class:`ptw_env.env.PTWRollEnv`,
``[delta, delta_rate, yaw_rate, roll_rate, ay, vx, phi_ref]`` (never
``info["state"]``), through :class:`ObsEncoder`: each channel scaled by its
sensor range (:data:`ptw_env.sensors.CHANNEL_RANGES`), the last
``frames`` (8, i.e. 80 ms) observations stacked, and the policy's own
previous action. The roll angle is not measured, and one noisy sample says
little about it, so a memoryless policy has to guess it; a short history
lets the network average the noise and form rates, and the previous action
tells it where the steering torque was (what a recurrent policy would
remember). A one-off design measurement at 1 M training steps, same seed and
settings (the encoder's ``frames`` changed by hand; no script reruns it): with 8
frames the deterministic policy earned 3962 per evaluation ride, with 1
frame 1759, no better than the untrained network (1754): it did not learn
to track. The action is the steering torque normalised to ``[-1, 1]``
(times ``tau_max`` = 60 N m).

Training distribution
---------------------
:class:`TrainingEnv` draws every episode (from its seeded generator) from
:class:`TrainingDistribution`: double lane change, slalom, constant radius
with acceleration, urban ride and the handling track, at speeds within
30-90 km/h (the shipped policy's; by default now the vehicle's design range, 28.8-118.8 km/h on the
reference scooter, ``train-rl --speeds 30,90`` for the shipped one's), sensor noise uniform in 0-6 % of
each channel's range, and mirrored (left/right) with probability 1/2. Kept *out* of training to
measure robustness: speeds below 30 and above 90 km/h (``scripts/eval_rl.py``
rides the lane change from 20 to 120 km/h; the default constant-radius test
accelerates to 100 km/h and 38 deg of lean, beyond the 35 deg of the
training turns) and noise above 6 % (10 and 15 %).

Reward: the environment's own, ``exp(-(phi - phi_ref)^2 / (2 (2 deg)^2)) -
0.01 (tau / tau_max)^2`` per 10 ms step, minus a training-only penalty
``0.1 (a_k - a_{k-1})^2`` on the change of the normalised action
(:data:`SMOOTH_WEIGHT`) against a torque chattering at 100 Hz. PPO scales
the reward for its value function during training only; nothing of it is
needed at run time. Returns reported by :func:`train` and
:func:`mean_episode_reward` are the environment's reward alone.

Examples
--------
>>> enc = ObsEncoder(frames=2)
>>> enc.dim
15
>>> import numpy as np
>>> x = enc.reset(np.array([0.01, 0, 0, 0, 0, 15.0, 0], dtype=np.float32))
>>> x.shape, round(float(x[0]), 6), float(x[-1])
((15,), 0.2, 0.0)

Layout: :mod:`assist.rl.policy` (the run-time side: encoder, policy, adapter) and :mod:`assist.rl.training`
(the episode distribution, the training environment, :func:`train`); both re-exported here.
"""

from assist.rl.policy import *  # noqa: F401,F403  (run time: encoder, policy, adapter)
from assist.rl.policy import __all__ as _policy_all
from assist.rl.training import *  # noqa: F401,F403  (training)
from assist.rl.training import __all__ as _train_all

__all__ = [*_policy_all, *_train_all]
