"""A native vector environment: N roll-tracking episodes stepped by one compiled, parallel kernel.

``gymnasium.make_vec("PTWRoll-v0", num_envs=N, vectorization_mode="vector_entry_point")`` (or
:class:`PTWRollVectorEnv` directly) steps all N vehicles at once: the same nonlinear plant
(:func:`ptw_env.kernels.advance`), sensors (:func:`ptw_env.sensors.sense_into`), actuator, reward,
episode end and safety cost (:mod:`ptw_env.episode`) as :class:`ptw_env.env.PTWRollEnv`, whose
constructor checks every argument (one copy of the rules).

Conventions (gymnasium 1.x vector API)
--------------------------------------
* ``observation_space``/``action_space`` are the single spaces batched; ``single_*`` the single ones.
* Autoreset: :attr:`gymnasium.vector.AutoresetMode.NEXT_STEP` (gymnasium's default): the step after an
  episode ends resets that env and returns its first observation with reward 0, ``terminated`` and
  ``truncated`` False; that step's action is ignored for it.
* Seeding: ``reset(seed=s)`` seeds env ``i`` with ``s + i`` (a list gives one seed per env), exactly as
  ``SyncVectorEnv`` does, so env ``i`` follows the single environment reset with ``seed=s + i`` and then
  reset without a seed at each episode end, to round-off (``tests/test_vector_env.py``). Each env keeps
  its own generator (``np_random_seed`` lists the seeds).
* ``reset(options={"reset_mask": mask})`` resets only the masked envs.
* ``info``: ``t``, ``phi_ref``, ``vx``, ``state`` (N, 8), ``tau``, ``tau_command``, ``action_clipped``,
  ``cost``, ``grip_utilisation`` for every env, ``reason`` where an episode ended, ``randomized``
  (key -> array) with ``randomize=``; each with its ``_key`` mask.
* ``render()`` draws env :attr:`render_env` (``rgb_array``).
* Domain randomisation (``randomize=``): as in the single env, a reset draws the *next* episode's values
  (:mod:`ptw_env.randomize`); the vector env compiles the next episodes' plants and sensor terms of
  :data:`COMPILE_BATCH` envs at a time (or, for an env that ends its episode before its batch is full, at its
  reset), so that the numpy work of a randomised plant is paid once per batch, not once per reset.

Not in the vector environment (a clear error): ``disturbances``, ``friction`` schedules and
``randomize_course`` (per-step or per-episode Python work that would undo the batching).

Example
-------
>>> import gymnasium as gym, numpy as np, ptw_env
>>> envs = gym.make_vec("PTWRoll-v0", num_envs=4, vectorization_mode="vector_entry_point")
>>> obs, info = envs.reset(seed=0)
>>> obs.shape, envs.single_observation_space.shape
((4, 7), (7,))
>>> obs, reward, terminated, truncated, info = envs.step(np.zeros((4, 1), dtype=np.float32))
>>> reward.shape, info["cost"].shape
((4,), (4,))
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numba
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numba import njit, prange

from .env import FALL_ANGLE, EnvConfigError, PTWRollEnv, advance_pose, draw_ride
from .episode import (REASONS, SCENARIO_END, actuate, command, end_code, grip_utilisation, observe_into, roll_reward,
                      step_cost)
from .kernels import advance, scratch
from .sensors import CHANNELS, NOISE_BLOCK, draw_noise, sense_into, sensor_terms

#: Envs whose next episode's randomised plant and sensors are compiled together (module docstring): numpy's
#: per-call overhead is shared by the batch (scripts/bench_vector.py measures what a reset then costs).
COMPILE_BATCH = 256


@njit(cache=True)
def take_next(idx, plant, sensors, rtable, nxt, W, nW, s, ns, f, nf, b, nb, mass, nmass, fz, nfz,
              offset, noff, std, nstd, gain, ngain):
    """Rows ``idx`` of the next-episode tables copied into this episode's: the randomised values
    (``rtable <- nxt``), with ``plant`` the compiled plants (``W``, ``inv_sigma``, ``fmax``, ``bank``, ``mass``,
    ``fz``), with ``sensors`` the sensor terms (``offset``, ``std``, ``gain``). One compiled call instead of a
    numpy fancy-index copy per array (what a randomised reset costs: ``scripts/bench_vector.py``)."""
    for i in idx:
        rtable[i, :] = nxt[i, :]
        if plant:
            W[i, :, :] = nW[i, :, :]
            s[i, :] = ns[i, :]
            f[i, :] = nf[i, :]
            b[i] = nb[i]
            mass[i] = nmass[i]
            fz[i, :] = nfz[i, :]
        if sensors:
            offset[i, :] = noff[i, :]
            std[i, :] = nstd[i, :]
            gain[i] = ngain[i]



@njit(cache=True, parallel=True)
def vector_step(actions, mode, x, k, pidx, W, inv_sigma, fmax, bank, mass, fz, dt, nsub,
                prof, vx_prof, ref_prof, fall, vmin, vmax, max_steps,
                lim, tau_max, normalize, roll_scale, effort_w,
                abuf, aprev, alpha, rate_step, alimit,
                grip_limit, roll_limit, dtau_limit, road_mu,
                gain, n_delay, frac, hist, offset, noise, counters, held, q, q_first, gps_step, true, meas,
                obs_hi, observe_roll,
                obs, rew, code, cost, util, tau_cmd, tau_app, clipped, nth):
    """One period of the envs (module docstring), by ``mode[i]``: 2 steps env ``i`` (actuator, plant, end,
    reward and cost), 1 starts its episode (nothing moves), 0 leaves it untouched (a partial reset of
    others); every env of mode 1 or 2 is then observed (sensors, observation clipped to ``obs_hi``), in ``nth`` chunks of envs (one per
    thread, each with its own work arrays). Per env ``i``: state ``x[i]``, sample ``k[i]``, plant ``pidx[i]``
    of ``W`` etc., ride ``prof[i]`` of the speed and reference profiles ``vx_prof``, ``ref_prof`` (rides x
    samples), of ``max_steps`` and of the RK4 substeps ``nsub``. Everything else as :class:`PTWRollEnv.step`."""
    N = x.shape[0]
    chunk = (N + nth - 1) // nth
    for th in prange(nth):
        M, c, g, ks = scratch()
        for i in range(th * chunk, min(N, (th + 1) * chunk)):
            p = pidx[i]
            pr = prof[i]
            ms = max_steps[pr]
            if mode[i] == 0:
                continue
            if mode[i] == 1:
                rew[i] = 0.0
                code[i] = 0
                cost[i] = 0.0
                tau_cmd[i] = 0.0
                tau_app[i] = 0.0
                clipped[i] = False
                util[i] = grip_utilisation(x[i], fmax[p], fz[p], road_mu)
            else:
                tau, cl = command(actions[i], lim, tau_max, normalize)
                kk = k[i]
                prev = aprev[i]
                a = actuate(tau, abuf[i], kk, prev, alpha, rate_step, alimit)
                aprev[i] = a
                finite = advance(x[i], a, vx_prof[pr, kk], 0.0, W[p], inv_sigma[p], fmax[p], bank[p], dt, nsub[pr],
                                 M, c, g, ks)
                phi = x[i, 0]
                k1 = kk + 1
                nxt = k1 if k1 < ms else ms
                cd = end_code(finite, phi, fall, vx_prof[pr, nxt], vmin, vmax, k1, ms)
                rew[i] = roll_reward(phi, ref_prof[pr, nxt], tau / tau_max, roll_scale, effort_w)
                if not finite:
                    for j in range(8):
                        if not np.isfinite(x[i, j]):
                            x[i, j] = 0.0
                k[i] = nxt
                ut = grip_utilisation(x[i], fmax[p], fz[p], road_mu)
                util[i] = ut
                cost[i] = step_cost(ut, phi, a - prev, grip_limit, roll_limit, dtau_limit)
                code[i] = cd
                tau_cmd[i] = tau
                tau_app[i] = a
                clipped[i] = cl
            kk = k[i]
            sense_into(x[i], vx_prof[pr, kk], (x[i, 6] + x[i, 7]) / mass[p], gain[i], n_delay, frac, hist[i],
                       offset[i], noise[i], counters[i], held[i], q, q_first, gps_step, true[i], meas[i])
            observe_into(meas[i], ref_prof[pr, kk], observe_roll, obs_hi, obs[i])


class PTWRollVectorEnv(VectorEnv):
    """N roll-tracking environments in one batched kernel (module docstring).

    Parameters
    ----------
    num_envs : int
    max_episode_steps : int, optional
        Truncate episodes after this many steps (``gymnasium.make_vec`` passes the registered limit).
    render_env : int
        Which env :meth:`render` draws.
    **kwargs
        Every argument of :class:`ptw_env.env.PTWRollEnv` (scenario, vehicle, sensors, noise_pct, effects,
        actuator, cost, randomize, ...), with the same meaning and checks.

    Attributes
    ----------
    nsub : ndarray of int, shape (2 x rides,)
        RK4 substeps per control period of each ride of the pool and its mirror image (row ``2 j`` is ride ``j``,
        ``2 j + 1`` its mirror; :attr:`ptw_env.env.PTWRollEnv.ride_substeps`): an env steps with its ride's count.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, *, max_episode_steps: int | None = None, render_env: int = 0,
                 **kwargs: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise EnvConfigError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if kwargs.get("render_mode") not in (None, "rgb_array"):
            raise EnvConfigError(f"render_mode of the vector env must be 'rgb_array' or None, got {kwargs['render_mode']!r}")
        for name in ("disturbances", "friction", "randomize_course"):
            if kwargs.get(name):
                raise EnvConfigError(f"{name}= is not supported by the vector env (use the single env through "
                                     f"gymnasium.vector.SyncVectorEnv, or randomize= for per-episode variation)")
        n = int(num_envs)
        if not (isinstance(render_env, (int, np.integer)) and 0 <= render_env < n):
            raise EnvConfigError(f"render_env must be an env index in [0, {n}), got {render_env!r}")
        self.template = PTWRollEnv(**kwargs)  # checks every argument; the single env's rules
        tpl = self.template
        if max_episode_steps is not None:
            if isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, (int, np.integer)) or max_episode_steps < 1:
                raise EnvConfigError(f"max_episode_steps must be an integer >= 1, got {max_episode_steps!r}")
        # the rides: row 2 j of the profile tables is ride j of the pool, row 2 j + 1 its mirror image,
        # each padded with its last sample to the longest ride
        profs = [pr for pair in tpl.pool for pr in pair]
        T = max(len(pr.t) for pr in profs)
        self._vx_prof = np.empty((len(profs), T))
        self._ref_prof = np.empty((len(profs), T))
        for j, pr in enumerate(profs):
            m = len(pr.t)
            self._vx_prof[j, :m], self._vx_prof[j, m:] = pr.vx, pr.vx[-1]
            self._ref_prof[j, :m], self._ref_prof[j, m:] = pr.phi_ref, pr.phi_ref[-1]
        limit = int(max_episode_steps) if max_episode_steps is not None else T
        self._max_steps = np.array([min(len(pr.t) - 1, limit) for pr in profs], dtype=np.int64)
        self._profiles = profs
        self.num_envs = n
        self.render_mode = tpl.render_mode
        self.render_env = int(render_env)
        self.single_action_space = tpl.action_space
        self.single_observation_space = tpl.observation_space
        self.action_space = batch_space(self.single_action_space, n)
        self.observation_space = batch_space(self.single_observation_space, n)
        self.randomization = tpl.randomization
        self.dt = tpl.dt

        # the plant: one shared, or one per env when randomisation changes it (the next episode's compiled ahead
        # into _nW etc., copied in at the reset); RK4 substeps per ride (profile 2 j + mirrored: the single
        # env's ride_substeps)
        self.nsub = np.repeat(np.asarray(tpl.ride_substeps, dtype=np.int64), 2)
        per_env = self.randomization is not None and self.randomization.changes_plant
        W, s, f, b = tpl.plant.flat()
        K = n if per_env else 1
        self._W = np.ascontiguousarray(np.repeat(W, K, axis=0))
        self._inv_sigma = np.repeat(s, K, axis=0)
        self._fmax = np.repeat(f, K, axis=0)
        self._bank = np.repeat(b, K, axis=0)
        self._mass = np.full(K, float(tpl.plant.mass))
        self._fz = np.repeat(tpl.plant.fz[None], K, axis=0)
        self._pidx = np.arange(n) if per_env else np.zeros(n, dtype=np.int64)
        # the next episode's plants (take_next); without per-env plants, empty arrays of the same kinds stand
        # in (never read)
        rows = slice(None) if per_env else slice(0, 0)
        self._nW, self._ns, self._nf = self._W[rows].copy(), self._inv_sigma[rows].copy(), self._fmax[rows].copy()
        self._nb, self._nmass, self._nfz = self._bank[rows].copy(), self._mass[rows].copy(), self._fz[rows].copy()
        sm = tpl.sensor_model
        self._n_delay, self._frac, self._q, self._q_first, self._gps_step = (
            sm.n_delay, sm.frac_delay, sm.quantum, sm.quantise_first, sm.gps_step)
        self._base_offset, self._base_std, self._base_gain = sm.offset, sm.std, sm.gravity_gain
        self._noisy = sm.noisy  # a noise scale multiplies the noise: none stays none
        delay, self._alpha, self._rate_step, self._alimit = tpl.actuator.discrete(tpl.dt, tpl.tau_max)
        nobs = self.single_observation_space.shape[0]

        # per-env state
        self.state = np.zeros((n, 8))
        self._k = np.zeros(n, dtype=np.int64)
        self._prof = np.zeros(n, dtype=np.int64)
        self._abuf = np.zeros((n, delay + 1))
        self._aprev = np.zeros(n)
        self._gain = np.full(n, self._base_gain)
        self._offset = np.repeat(self._base_offset[None], n, axis=0)
        self._std = np.repeat(self._base_std[None], n, axis=0)
        self._hist = np.zeros((n, sm.hist_len, 6))
        self._noise = np.zeros((n, NOISE_BLOCK if self._noisy else 0, len(CHANNELS)))
        self._counters = np.zeros((n, 3), dtype=np.int64)
        self._held = np.zeros((n, 1))
        self._true = np.zeros((n, len(CHANNELS)))
        self._meas = np.zeros((n, len(CHANNELS)))
        self._obs = np.zeros((n, nobs), dtype=np.float32)
        self._rew = np.zeros(n)
        self._code = np.zeros(n, dtype=np.int64)
        self._cost = np.zeros(n)
        self._util = np.zeros(n)
        self._tau_cmd = np.zeros(n)
        self._tau_app = np.zeros(n)
        self._clipped = np.zeros(n, dtype=np.bool_)
        self._prev_done = np.zeros(n, dtype=np.bool_)
        self._rngs: list[np.random.Generator] = []
        self._seeds: list[int | None] = []
        keys = self.randomization.keys if self.randomization else ()
        self._rtable = np.zeros((n, len(keys)))  # this episode's randomised values, a column per key
        self._randomized = {key: self._rtable[:, j] for j, key in enumerate(keys)}
        # randomisation: each env draws its next episode's values at a reset; they are compiled in batches
        # of COMPILE_BATCH envs (or at the reset that needs them) into these next-episode tables
        self._next = np.zeros((n, len(keys)))  # the next episode's, drawn at the last reset (compiled: values)
        self._next_u = np.zeros((n, len(keys)))  # ... as drawn: uniforms, mapped to values when compiled
        self._pending = np.zeros(n, dtype=np.bool_)
        self._per_env_plant = per_env
        self._sensor_keys = self.randomization is not None and any(
            k.startswith("sensor") or k.partition(":")[0] in ("gyro_bias", "ay_frame") for k in self.randomization.keys)
        # the next episode's sensor terms (take_next); empty arrays stand in when no key changes them (never read)
        rows = slice(None) if self._sensor_keys else slice(0, 0)
        self._noff, self._nstd, self._ngain = self._offset[rows].copy(), self._std[rows].copy(), self._gain[rows].copy()
        self._batch = min(n, COMPILE_BATCH)
        self._pose = np.zeros(3)
        self._trace: list[tuple[float, float, float]] = []
        self._fig = None
        self._obs_hi = tpl.obs_bound.astype(np.float32)
        self._all = np.ones(n, dtype=np.bool_)
        self._ready = False

    # ------------------------------------------------------------------ public view
    @property
    def step_index(self) -> np.ndarray:
        """Sample index ``k`` of every env's episode (time ``k dt`` [s])."""
        return self._k.copy()

    def profile_of(self, i: int) -> Any:
        """The ride (:class:`ptw_env.scenarios.Profile`, mirrored when drawn so) env ``i`` is on this episode."""
        return self._profiles[self._prof[i]]

    def plant_of(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """``(W, inv_sigma, fmax, bank)`` of env ``i``'s plant this episode (:meth:`ptw_env.dynamics.Plant.flat`)."""
        p = self._pidx[i]
        return self._W[p].copy(), self._inv_sigma[p].copy(), self._fmax[p].copy(), float(self._bank[p])

    @property
    def np_random_seed(self) -> tuple[int | None, ...]:
        """The seed each env's generator was last created from (``None``: from the OS)."""
        return tuple(self._seeds)

    @property
    def memory_bytes(self) -> int:
        """Bytes of per-env arrays (state, plant, sensors, actuator, outputs) held by this vector env."""
        arrays = [v for v in vars(self).values() if isinstance(v, np.ndarray)]
        return int(sum(a.nbytes for a in arrays))

    # ------------------------------------------------------------------ resets
    def _reset_envs(self, idx: np.ndarray, seeds: Sequence[int | None] | None, x0: np.ndarray | None) -> None:
        """Reset the envs ``idx``: new generators when ``seeds`` is given, then (in the single env's order)
        randomised values, starting roll, actuator and sensors."""
        tpl = self.template
        if seeds is not None:
            for i, sd in zip(idx, seeds):
                self._rngs[i], self._seeds[i] = seeding.np_random(sd)
        if len(tpl.pool) > 1 or tpl.mirror:  # the ride, first (the single env's order)
            for i in idx:
                j, m = draw_ride(self._rngs[i], len(tpl.pool), tpl.mirror)
                self._prof[i] = 2 * j + int(m)
        rnd = self.randomization
        if rnd is not None:
            if seeds is not None:  # new generators (also the first reset): what the old ones drew is void;
                self._draw(idx)  # this episode's values first
            if self._pending[idx].any():
                self._compile_pending()
            # the next episode's values, plant and sensor terms, compiled ahead
            take_next(idx, self._per_env_plant, self._sensor_keys, self._rtable, self._next,
                      self._W, self._nW, self._inv_sigma, self._ns, self._fmax, self._nf, self._bank, self._nb,
                      self._mass, self._nmass, self._fz, self._nfz,
                      self._offset, self._noff, self._std, self._nstd, self._gain, self._ngain)
            self._draw(idx)  # the next episode's values, compiled later with other envs' (_compile_pending)
        for j, i in enumerate(idx):
            if x0 is None:
                self.state[i] = 0.0
                self.state[i, 0] = self._rngs[i].uniform(-tpl.init_roll, tpl.init_roll)
            else:
                self.state[i] = x0
        self._k[idx] = 0
        self._abuf[idx] = 0.0
        self._aprev[idx] = 0.0
        self._hist[idx] = 0.0
        self._counters[idx] = (0, -1, self._noise.shape[1])
        self._held[idx] = math.nan
        self._prev_done[idx] = False
        if self.render_env in idx:
            pr = self.profile_of(self.render_env)
            self._pose[:] = (pr.X[0], pr.Y[0], pr.psi[0])
            self._trace = [(self._pose[0], self._pose[1], self.state[self.render_env, 0])]

    def _draw(self, idx: np.ndarray) -> None:
        """Draw the next episode's randomised values of the envs ``idx`` from their generators (one
        ``random(number of keys)`` each, :meth:`ptw_env.randomize.Randomization.uniforms`; mapped to values
        with the other pending envs' when compiled, :meth:`_compile_pending`: what
        :meth:`~ptw_env.randomize.Randomization.sample_many` gives)."""
        if not len(idx):
            return
        self.randomization.uniforms_into([self._rngs[i] for i in idx], idx, self._next_u)
        self._pending[idx] = True

    def _compile_pending(self) -> None:
        """Plants and sensor terms of every drawn, not yet compiled next episode, in one batch (a reset needs
        its episode's plant at once; compiling the next one ahead, many envs together, spreads the cost of the
        numpy work of :meth:`ptw_env.randomize.Randomization.plant` over the batch)."""
        idx = np.flatnonzero(self._pending)
        if not len(idx):
            return
        rnd, tpl = self.randomization, self.template
        self._next[idx] = rnd.from_uniforms(self._next_u[idx])
        samples = {key: self._next[idx, j] for j, key in enumerate(rnd.keys)}
        eff = rnd.effects(tpl.effects, samples)
        if self._per_env_plant:
            plant = rnd.plant(tpl.vehicle, tpl.effects, samples, effects=eff)
            W, s, f, b = plant.flat()
            self._nW[idx], self._ns[idx], self._nf[idx], self._nb[idx] = W, s, f, b
            self._nmass[idx] = np.broadcast_to(plant.mass, (len(idx),))
            self._nfz[idx] = np.broadcast_to(plant.fz, (len(idx), 2))
        if self._sensor_keys:  # as PTWRollEnv.episode_models, for all these envs at once
            scale, bias = rnd.sensor_terms(samples)
            cfg = tpl.sensor_config
            off, std, gain = sensor_terms(cfg, eff.sensor, len(idx))
            for c, b in bias.items():
                j = CHANNELS.index(c)
                off[:, j] = cfg.bias[c] + b
                if c in ("yaw_rate", "roll_rate"):
                    off[:, j] += np.broadcast_to(eff.sensor.value("gyro_bias", f"{c}_bias"), (len(idx),))
            self._noff[idx], self._nstd[idx] = off, std * np.asarray(scale, dtype=float).reshape(-1, 1)
            self._ngain[idx] = gain
        self._pending[idx] = False

    def _refill_noise(self, active: np.ndarray) -> None:
        """New noise blocks for the ``active`` envs that used theirs up, from each env's generator (an env
        whose noise is all zero draws nothing, as :class:`~ptw_env.sensors.SensorModel` does)."""
        B = self._noise.shape[1]
        if B == 0:
            return
        for i in np.flatnonzero(active & (self._counters[:, 2] >= B)):
            draw_noise(self._rngs[i], self._std[i], self._noise[i])
            self._counters[i, 2] = 0

    def _run(self, actions: np.ndarray, mode: np.ndarray) -> None:
        tpl = self.template
        self._refill_noise(mode > 0)
        vmin, vmax = tpl.vehicle.vmin, tpl.vehicle.vmax
        grip, roll_lim, dtau_lim, road_mu = tpl.cost_limits
        vector_step(actions, mode, self.state, self._k, self._pidx, self._W, self._inv_sigma, self._fmax,
                    self._bank, self._mass, self._fz, tpl.dt, self.nsub, self._prof, self._vx_prof, self._ref_prof,
                    FALL_ANGLE, vmin, vmax, self._max_steps,
                    float(self.single_action_space.high[0]), tpl.tau_max, tpl.normalize_action, *tpl.reward_params,
                    self._abuf, self._aprev, self._alpha, self._rate_step, self._alimit,
                    grip, roll_lim, dtau_lim, road_mu,
                    self._gain, self._n_delay, self._frac, self._hist, self._offset, self._noise, self._counters,
                    self._held, self._q, self._q_first, self._gps_step, self._true, self._meas,
                    self._obs_hi, tpl.observe_roll,
                    self._obs, self._rew, self._code, self._cost, self._util, self._tau_cmd, self._tau_app,
                    self._clipped, min(numba.get_num_threads(), self.num_envs))

    def _info(self, done: np.ndarray | None) -> dict[str, Any]:
        k = self._k
        info: dict[str, Any] = {
            "t": k * self.dt,
            "phi_ref": self._ref_prof[self._prof, k],
            "vx": self._vx_prof[self._prof, k],
            "state": self.state.copy(),
            "tau": self._tau_app.copy(),
            "tau_command": self._tau_cmd.copy(),
            "action_clipped": self._clipped.copy(),
            "cost": self._cost.copy(),
            "grip_utilisation": self._util.copy(),
        }
        if len(self.template.pool) > 1 or self.template.mirror:
            info["ride"], info["mirrored"] = self._prof // 2, self._prof % 2 == 1
        for key in list(info):
            info["_" + key] = self._all
        if self._randomized:
            table = self._rtable.copy()
            info["randomized"] = {key: table[:, j] for j, key in enumerate(self._randomized)}
            info["_randomized"] = self._all
        if done is not None and done.any():
            reason = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(done):
                reason[i] = REASONS[self._code[i]]
            info["reason"] = reason
            info["_reason"] = done.copy()
        return info

    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every env (or those of ``options["reset_mask"]``); ``options["x0"]``: one starting state (8,)."""
        n = self.num_envs
        if options is not None and not isinstance(options, dict):
            raise EnvConfigError(f"reset options must be a dict (keys reset_mask, x0), got {options!r}")
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        x0 = options_x0 = options.pop("x0", None)
        if options:
            raise EnvConfigError(f"unknown reset option(s): {sorted(options)}; known: reset_mask, x0")
        if mask is None:
            mask = self._all
        elif not (isinstance(mask, np.ndarray) and mask.dtype == np.bool_ and mask.shape == (n,) and mask.any()):
            raise EnvConfigError(f"options['reset_mask'] must be a bool array of shape ({n},) with a True value, got {mask!r}")
        if x0 is not None:
            try:
                x0 = np.asarray(x0, dtype=float)
            except (TypeError, ValueError):
                x0 = np.full(0, np.nan)  # not numbers: refused below
            if x0.shape != (8,) or not np.all(np.isfinite(x0)):
                raise EnvConfigError(f"reset option x0 must be 8 finite numbers (the state of model.md), got "
                                     f"{options_x0!r}")
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds: list[int | None] = [int(seed) + i for i in range(n)]
        elif seed is None:
            seeds = [None] * n
        elif isinstance(seed, Sequence) and len(seed) == n:
            seeds = list(seed)
        else:
            raise EnvConfigError(f"seed must be an int, None or a list of {n} seeds, got {seed!r}")
        bad = [s for s in seeds if s is not None and (isinstance(s, bool) or not isinstance(s, (int, np.integer))
                                                     or s < 0)]
        if bad:  # checked before any generator is replaced: a refused reset changes nothing
            raise EnvConfigError(f"seeds must be integers >= 0 or None, got {bad[0]!r}")
        first = not self._rngs
        if first:  # the first reset creates every env's generator
            self._rngs = [np.random.default_rng(0)] * n
            self._seeds = [None] * n
            mask = self._all
        idx = np.flatnonzero(mask)
        # a seed (or the first reset) makes new generators; otherwise each env's generator goes on
        fresh = [seeds[i] for i in idx] if (seed is not None or first) else None
        self._reset_envs(idx, fresh, x0)
        mode = np.zeros(n, dtype=np.int64)  # only the reset envs: the others stay where they are
        mode[idx] = 1
        self._run(np.zeros(n), mode)
        self._ready = True
        return self._obs.copy(), self._info(None)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One period of every env (``actions``: (N, 1) torques, or normalised with ``normalize_action``); an env
        whose episode ended on the previous step is reset instead (NEXT_STEP autoreset, its action ignored).
        Returns ``(obs, reward, terminated, truncated, info)``, batched (module docstring)."""
        if not self._ready:
            raise EnvConfigError("step() called before reset()")
        a = np.asarray(actions, dtype=np.float64)
        if a.size != self.num_envs:
            raise EnvConfigError(f"actions must have shape ({self.num_envs}, 1) (one torque per env), got {np.shape(actions)}")
        a = a.reshape(self.num_envs, 1)
        a = a[:, 0]
        if not np.all(np.isfinite(a)):
            bad = int(np.flatnonzero(~np.isfinite(a))[0])
            raise EnvConfigError(f"action of env {bad} is not finite: {a[bad]!r}")
        resetting = self._prev_done.copy()
        idx = np.flatnonzero(resetting)
        if len(idx):
            self._reset_envs(idx, None, None)
        if self._pending.sum() >= self._batch:
            self._compile_pending()
        self._run(np.ascontiguousarray(a), np.where(resetting, 1, 2).astype(np.int64))
        code = self._code
        terminated = (code > 0) & (code < SCENARIO_END)
        truncated = code == SCENARIO_END
        done = terminated | truncated
        self._prev_done = done
        if self.render_mode is not None:
            r = self.render_env
            if not resetting[r]:
                x = self.state[r]
                advance_pose(self._pose, float(self._vx_prof[self._prof[r], max(self._k[r] - 1, 0)]), x[2], x[3], self.dt)
                self._trace.append((self._pose[0], self._pose[1], x[0]))
        return self._obs.copy(), self._rew.copy(), terminated, truncated, self._info(done)

    def render(self) -> np.ndarray | None:
        """The frame of env :attr:`render_env` (``rgb_array``), drawn as the single env draws."""
        if self.render_mode is None:
            return None
        from .render import draw_frame

        return draw_frame(_View(self))

    def close_extras(self, **kwargs: Any) -> None:
        self.template.close()


class _View:
    """What :func:`ptw_env.render.draw_frame` reads, for the env the vector env renders."""

    def __init__(self, venv: PTWRollVectorEnv) -> None:
        r = venv.render_env
        tpl = venv.template
        self.profile, self.scenario, self.dt = venv.profile_of(r), tpl.scenario, tpl.dt
        self.state = venv.state[r]
        self.step_index = int(venv._k[r])
        self.pose = tuple(float(v) for v in venv._pose)
        self.trace = np.asarray(venv._trace, dtype=float).reshape(-1, 3)


__all__ = ["PTWRollVectorEnv", "vector_step"]
