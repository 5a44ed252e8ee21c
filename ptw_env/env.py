"""Gymnasium environment: roll-angle tracking on the nonlinear PTW with noisy sensors."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from typing import Any, Mapping, Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .dynamics import compile_plant
from .effects import Effects, as_effects
from .episode import (OBS_REF, OBS_ROLL, OBS_VX, REASONS, SCENARIO_END, Actuator, CostConfig, EpisodeConfigError,
                      actuate, command, end_code, grip_utilisation, observe_into, roll_reward, step_cost)
from .friction import FrictionPlants, FrictionSchedule
from .integrate import Stepper, linear_rate, substeps_for
from .randomize import Randomization, RandomizationError
from .rider import DEFAULT_TAU_MAX
from .scenarios import Scenario, ScenarioError, make_scenario
from .sensors import CHANNELS, SensorConfig, SensorModel
from .vehicle import REFERENCE_SCOOTER, Vehicle
from .vehicle_files import VehicleFileError, load_vehicle

#: Fall threshold [rad]: the model is valid for |phi| <= 45 deg (model.md).
FALL_ANGLE = math.radians(45.0)
#: The observation's channels by index (the table of :class:`PTWRollEnv`); ``roll`` only with ``observe_roll``.
OBS_NAMES: tuple[str, ...] = ("delta", "delta_rate", "yaw_rate", "roll_rate", "ay", "vx", "phi_ref", "roll")


def obs_index(*names: str) -> tuple[int, ...]:
    """Indices of the named observation channels (:data:`OBS_NAMES`), e.g. ``obs_index("yaw_rate", "vx")``
    is ``(2, 5)``: code that reads the observation names what it takes instead of restating indices."""
    try:
        return tuple(OBS_NAMES.index(n) for n in names)
    except ValueError:
        bad = [n for n in names if n not in OBS_NAMES]
        raise ValueError(f"unknown observation channel(s) {bad}; the channels are {OBS_NAMES}") from None


assert obs_index("vx", "phi_ref", "roll") == (OBS_VX, OBS_REF, OBS_ROLL)  # the layout observe_into writes


def draw_ride(rng: np.random.Generator, n_rides: int, mirror: bool) -> tuple[int, bool]:
    """An episode's ride: its index in a pool of ``n_rides`` and whether it is mirrored, drawn from ``rng``
    (one ``integers`` call when there is a choice, one ``random`` call with ``mirror``)."""
    j = int(rng.integers(n_rides)) if n_rides > 1 else 0
    return j, bool(mirror and rng.random() < 0.5)


class EnvConfigError(ValueError):
    """A bad argument to :class:`PTWRollEnv` (names the argument)."""


class InvalidActionError(ValueError):
    """A NaN or infinite action."""


@dataclass(frozen=True)
class Disturbance:
    """An external disturbance, in the spirit of safe-control-gym's ``disturbances``.

    Parameters
    ----------
    channel : {"torque", "roll_moment"}
        ``torque`` is added to the rider torque [N m] (row 6); ``roll_moment``
        is an external moment about the roll axis [N m] (row 5: a gust, a
        rider shifting weight).
    kind : {"white_noise", "step", "impulse"}
        White noise of standard deviation ``magnitude`` held over each period,
        a step of ``magnitude`` from ``start_s`` on, or a pulse of ``magnitude``
        over ``[start_s, start_s + duration_s)``.
    magnitude : float
        N m.
    start_s, duration_s : float
        Seconds.
    """

    channel: str = "torque"
    kind: str = "white_noise"
    magnitude: float = 1.0
    start_s: float = 0.0
    duration_s: float = 0.1

    def __post_init__(self) -> None:
        if self.channel not in ("torque", "roll_moment"):
            raise EnvConfigError(f"Disturbance.channel must be 'torque' or 'roll_moment', got {self.channel!r}")
        if self.kind not in ("white_noise", "step", "impulse"):
            raise EnvConfigError(f"Disturbance.kind must be white_noise, step or impulse, got {self.kind!r}")
        for name in ("magnitude", "start_s", "duration_s"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise EnvConfigError(f"Disturbance.{name} must be a finite number, got {v!r}")
        if self.kind == "white_noise" and self.magnitude < 0:
            raise EnvConfigError(f"Disturbance.magnitude (a standard deviation) must be >= 0, got {self.magnitude}")
        if self.duration_s < 0 or self.start_s < 0:
            raise EnvConfigError("Disturbance.start_s and duration_s must be >= 0")

    def value(self, t: float, rng: np.random.Generator) -> float:
        """Disturbance at time ``t`` [s]; draws from ``rng`` for white noise."""
        if self.kind == "white_noise":
            return float(rng.normal(0.0, self.magnitude)) if t >= self.start_s else 0.0
        if self.kind == "step":
            return self.magnitude if t >= self.start_s else 0.0
        return self.magnitude if self.start_s <= t < self.start_s + self.duration_s else 0.0


def advance_pose(pose: np.ndarray, vx: float, vy: float, r: float, dt: float) -> None:
    """Dead-reckon the planar pose ``(X, Y, psi)`` of the rear contact over ``dt`` [s] in place
    (forward Euler: ``X' = vx cos psi - vy sin psi``, ``Y' = vx sin psi + vy cos psi``, ``psi' = r``; plenty
    for drawing)."""
    psi = pose[2]
    pose[0] += dt * (vx * math.cos(psi) - vy * math.sin(psi))
    pose[1] += dt * (vx * math.sin(psi) + vy * math.cos(psi))
    pose[2] += dt * r


def _as_vehicle(name: str, v: Vehicle | str | os.PathLike | None) -> Vehicle | None:
    """A :class:`Vehicle`, or a preset name / vehicle file (:func:`ptw_env.vehicle_files.load_vehicle`),
    so that ``gymnasium.make("PTWRoll-v0", vehicle="robot-bicycle")`` works."""
    if v is None or isinstance(v, Vehicle):
        return v
    if isinstance(v, (str, os.PathLike)):
        try:
            return load_vehicle(v)
        except VehicleFileError as exc:
            raise EnvConfigError(f"{name}: {exc}") from None
    raise EnvConfigError(f"{name} must be a Vehicle, a preset name or a vehicle file, got {type(v).__name__}")


class PTWRollEnv(gym.Env):
    """Roll-angle tracking with the steering torque on a nonlinear scooter.

    The plant is the reference scooter of ``shared/spec/model.md`` (Sharp-type
    4-DoF lateral model, first-order tire relaxation, sine gravity/trail
    terms), optionally with the effects of ``shared/spec/effects.md``,
    integrated with RK4 (substeps of at most 2.5 ms, shorter for a stiffer model: :attr:`substeps`) while the action and the speed are
    held over each control period ``dt`` = 10 ms. The forward speed follows
    the scenario's profile (exogenous, time-varying); the agent sees only
    noisy sensors (``shared/spec/logs.md``) and the roll reference
    ``phi_ref = atan(vx^2 kappa / g)`` of the scenario's path.

    Action space
    ------------
    ``Box(-tau_max, tau_max, (1,), float32)``: the rider steering torque [N m]
    (``tau_max`` = 60 N m on the reference scooter by default; on another vehicle in
    proportion to its steer torque per radian of lean, ``Vehicle.torque_ratio``). With ``normalize_action=True`` the box
    is ``[-1, 1]`` and scaled by ``tau_max``. Actions outside the box are
    clipped (the rider's strength), and ``info["action_clipped"]`` says so;
    NaN or infinite actions raise :class:`InvalidActionError`.

    Observation space
    -----------------
    ``Box(float32)`` of the noisy sensors and the reference:

    ===  ==========  ======================================  =======  ==========
    idx  symbol      meaning                                  unit     bound +-
    ===  ==========  ======================================  =======  ==========
    0    delta       steering angle, 10-bit encoder + noise   rad      0.6
    1    delta_rate  steering rate, encoder                   rad/s    10
    2    yaw_rate    yaw rate, IMU gyro                       rad/s    5
    3    roll_rate   roll rate, IMU gyro                      rad/s    10
    4    ay          lateral acceleration, IMU (road plane)   m/s^2    50
    5    vx          forward speed, GPS (10 Hz, held)         m/s      60
    6    phi_ref     reference roll angle                     rad      pi/4
    (7)  roll        roll angle, IMU attitude filter          rad      3.2
    ===  ==========  ======================================  =======  ==========

    Index 7 exists only with ``observe_roll=True``: by default the roll angle
    must be estimated (the point of the observers in ``assist``). The true
    state is never in the observation; it is in ``info["state"]``. Each entry
    is clipped to its bound, the sensor's full scale (a saturated sensor);
    the bounds lie far beyond anything a ride that stays upright produces.

    Reward
    ------
    ``r = exp(-(phi - phi_ref)^2 / (2 s^2)) - w (tau / tau_max)^2`` with
    ``s`` = 2 deg (``reward_roll_scale_deg``) and ``w`` = 0.01
    (``reward_effort_weight``): 1 per step for perfect tracking, so staying up
    pays, and a small effort penalty on the commanded torque ``tau``; 0 on the
    step where the model diverges.

    Actuator and cost
    -----------------
    ``actuator=Actuator(delay_s, bandwidth_hz, rate_limit, torque_limit)``
    (:class:`ptw_env.episode.Actuator`) puts a steer actuator between the
    command and the plant (default: ideal). ``info["tau"]`` is the torque the
    plant receives, ``info["tau_command"]`` the command. Every step also reports
    the safety cost ``info["cost"]`` (:class:`ptw_env.episode.CostConfig`,
    ``cost=``: how many of the grip, roll and torque-rate limits the step breaks)
    and ``info["grip_utilisation"]`` (``max |F|/(mu Fz)`` of the two tires), for
    safe / constrained RL.

    Starting state
    --------------
    Upright steady state plus a roll angle drawn uniformly in
    ``+-init_roll_deg`` (default 0.5 deg) from the environment's generator;
    ``reset(options={"x0": array(8)})`` sets it exactly.

    Episode end
    -----------
    *Terminated* when the vehicle falls (``|phi| > 45 deg``), when the state
    is no longer finite, or when the speed leaves the model's valid range;
    ``info["reason"]`` is ``"fell"``, ``"diverged"`` or ``"speed_out_of_range"``.
    *Truncated* when the scenario's path ends (``info["reason"] = "scenario_end"``).

    Arguments
    ---------
    scenario : str or Scenario
        A name of :mod:`ptw_env.scenarios` or a scenario object.
    speed_kmh : float, optional
        Cruise speed of a named scenario [km/h].
    sensors : SensorConfig, optional
        Noise, bias and quantisation (default: the reference logs' sensors).
    noise_pct : float, optional
        Shortcut for ``SensorConfig.from_percent(noise_pct, vehicle=vehicle)`` (percent of the vehicle's
        channel ranges, :func:`ptw_env.sensors.channel_ranges`).
    effects : Effects, dict or list of "CAUSE:PARAM=VALUE", optional
        Effects of effects.md in the *true* plant (dynamic and sensor effects).
    prior_effects, prior_vehicle : optional
        The model a controller is allowed to know (:meth:`get_prior`), for a
        prior-vs-true mismatch as in safe-control-gym; default: the nominal
        reference scooter.
    disturbances : sequence of Disturbance, optional
    friction : FrictionSchedule, optional
        Road friction along the ride (:mod:`ptw_env.friction`): scales the
        true plant's tire stiffness and ``mu_peak`` by ``mu / mu_ref`` at
        each control period (a wet patch); ``info["friction"]`` holds ``mu``.
    vehicle : Vehicle or str, optional
        The true vehicle (default: the reference scooter): a :class:`Vehicle`, a preset name
        (:func:`ptw_env.vehicle_files.vehicle_names`) or a vehicle file; also through
        ``gymnasium.make("PTWRoll-v0", vehicle="robot-bicycle", speed_kmh=14)``. The scenario's
        speeds must lie in the vehicle's range.
    dt : float
        Control period [s] (default 0.01, the 100 Hz sensor rate).
    tau_max, normalize_action, observe_roll, init_roll_deg,
    reward_roll_scale_deg, reward_effort_weight : see above.
    scenario_seed : int, optional
        Seed of a randomised scenario's course (:class:`~ptw_env.scenarios.Urban`), fixed for
        the environment's life (default: the scenario's own ``seed`` field).
    randomize_course : bool
        Draw a new course at every ``reset`` from the environment's generator (``reset(seed=...)``
        reproduces it); for scenarios without randomisation it changes nothing.
    actuator : Actuator, optional
        Steer actuator delay, bandwidth, rate limit and torque saturation (default: ideal).
    cost : CostConfig, optional
        Limits of the safety cost ``info["cost"]`` (default :class:`~ptw_env.episode.CostConfig`).
    scenario_pool : sequence of scenario names or Scenario objects, optional
        Rides drawn per episode: every ``reset`` picks one uniformly from the environment's generator
        (names take ``speed_kmh``); ``scenario`` is then only the first ride before the first reset.
        With ``gymnasium.make`` pass ``max_episode_steps`` for the longest ride (the id's limit is its
        own scenario's).
    mirror : bool
        Mirror each episode left/right with probability 1/2 (:meth:`ptw_env.scenarios.Profile.mirrored`).
    randomize : Randomization, mapping or JSON file, optional
        Domain randomisation (:mod:`ptw_env.randomize`): effect parameters, generalised forces, the
        vehicle's own physical parameters (a vehicle file's), sensor noise and bias drawn from seeded
        distributions for every episode; ``info["randomized"]`` holds the episode's values.
    substeps : int, optional
        At least this many RK4 substeps per control period. Default: as many as the fastest mode of the
        plant needs at the speeds of the episode's ride (:func:`ptw_env.integrate.speed_grid`; the
        vehicle's whole range with ``randomize_course``), and with ``randomize=`` as many as the fastest
        plant it can draw needs there (:func:`ptw_env.integrate.substeps_for`,
        :meth:`ptw_env.randomize.Randomization.stiffest_rate`); :attr:`substeps` says how many the current
        ride uses, :attr:`ride_substeps` each ride's. E.g. to compare a fixed model with a randomised one at
        the same integration step. Not with ``friction=``.
    step_speeds : {"ride", "vehicle"}
        The speeds the RK4 step is sized for: each ride's own (default; :func:`ptw_env.integrate.speed_grid`)
        or the vehicle's whole range (what every ride took before this option; :func:`ptw_env.ride.ride_scenario`
        keeps it, so the ride logs written before reproduce bit for bit): the vehicle's modes at 41 speeds of
        its range and the plant's at its lowest, middle and highest speed (:func:`ptw_env.integrate.linear_rate`).
    render_mode : {"rgb_array", "human", None}

    Version history
    ---------------
    * v0: first release. Since 2026-11-26 the RK4 step is sized for each ride's speeds (``step_speeds``): a
      plant whose fastest mode needs more substeps only near the vehicle's top speed now takes fewer on slower
      rides, the same ODE within the same accuracy bound (trajectories differ by the integration error,
      1e-7-1e-5 of each state's range after 3 s on ``sharp1971`` at 50 km/h; ``step_speeds="vehicle"``
      gives the earlier ones bit for bit).

    Examples
    --------
    >>> import gymnasium as gym, numpy as np
    >>> import ptw_env
    >>> env = gym.make("PTWRoll-v0")
    >>> obs, info = env.reset(seed=1)
    >>> obs.shape, obs.dtype
    ((7,), dtype('float32'))
    >>> obs, reward, terminated, truncated, info = env.step(np.array([0.0], dtype=np.float32))
    >>> sorted(k for k in ("state", "t", "phi_ref") if k in info)
    ['phi_ref', 'state', 't']
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 25}

    def __init__(
        self,
        scenario: str | Scenario = "double_lane_change",
        speed_kmh: float | None = None,
        sensors: SensorConfig | None = None,
        noise_pct: float | None = None,
        effects: Effects | Mapping | list | str | None = None,
        prior_effects: Effects | Mapping | list | str | None = None,
        prior_vehicle: Vehicle | str | None = None,
        disturbances: tuple[Disturbance, ...] | list[Disturbance] = (),
        friction: FrictionSchedule | None = None,
        vehicle: Vehicle | str | None = None,
        dt: float = 0.01,
        tau_max: float | None = None,
        normalize_action: bool = False,
        observe_roll: bool = False,
        init_roll_deg: float = 0.5,
        reward_roll_scale_deg: float = 2.0,
        reward_effort_weight: float = 0.01,
        scenario_seed: int | None = None,
        randomize_course: bool = False,
        actuator: Actuator | None = None,
        cost: CostConfig | None = None,
        randomize: Randomization | Mapping | str | None = None,
        scenario_pool: Sequence[str | Scenario] | None = None,
        mirror: bool = False,
        render_mode: str | None = None,
        substeps: int | None = None,
        step_speeds: str = "ride",
    ) -> None:
        super().__init__()
        if not isinstance(step_speeds, str) or step_speeds not in ("ride", "vehicle"):
            raise EnvConfigError(f"step_speeds must be 'ride' or 'vehicle', got {step_speeds!r}")
        self.step_speeds = step_speeds
        for name, v in (("dt", dt), ("tau_max", 1.0 if tau_max is None else tau_max),
                        ("reward_roll_scale_deg", reward_roll_scale_deg)):
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise EnvConfigError(f"{name} must be a positive number, got {v!r}")
        for name, v in (("init_roll_deg", init_roll_deg), ("reward_effort_weight", reward_effort_weight)):
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise EnvConfigError(f"{name} must be a number >= 0, got {v!r}")
        if init_roll_deg >= 45:
            raise EnvConfigError(f"init_roll_deg must be below the 45 deg fall angle, got {init_roll_deg}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise EnvConfigError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        if sensors is not None and noise_pct is not None:
            raise EnvConfigError("give either sensors= or noise_pct=, not both")
        self.vehicle = _as_vehicle("vehicle", vehicle) or REFERENCE_SCOOTER
        if noise_pct is not None:
            if not isinstance(noise_pct, (int, float)) or not math.isfinite(noise_pct) or noise_pct < 0:
                raise EnvConfigError(f"noise_pct must be a number >= 0 (percent of each channel's range), got {noise_pct!r}")
            sensors = SensorConfig.from_percent(float(noise_pct), vehicle=self.vehicle)  # its channel ranges
        self.sensor_config = SensorConfig() if sensors is None else sensors
        if not isinstance(self.sensor_config, SensorConfig):
            raise EnvConfigError(f"sensors must be a SensorConfig, got {type(sensors).__name__}")

        if isinstance(scenario, str):
            self.scenario = make_scenario(scenario, speed_kmh=speed_kmh)
        elif isinstance(scenario, Scenario):
            if speed_kmh is not None:
                raise EnvConfigError("speed_kmh applies to a scenario name; set the field on the Scenario object instead")
            self.scenario = scenario
        else:
            raise EnvConfigError(f"scenario must be a name or a Scenario, got {type(scenario).__name__}")

        self.effects = as_effects(effects)
        if self.effects.batch_shape:
            raise EnvConfigError("effects in the environment must be scalars (one vehicle)")
        self.prior_vehicle = _as_vehicle("prior_vehicle", prior_vehicle) or self.vehicle
        self.prior_effects = as_effects(prior_effects)
        self.disturbances = tuple(disturbances)
        for d in self.disturbances:
            if not isinstance(d, Disturbance):
                raise EnvConfigError(f"disturbances must be Disturbance objects, got {type(d).__name__}")
        self.dt = float(dt)
        # the actuator range: 60 N m on the reference scooter, in proportion to the steer torque per
        # radian of lean on another vehicle (Vehicle.torque_ratio; 3.2 N m on the robot bicycle)
        self.tau_max = float(DEFAULT_TAU_MAX * self.vehicle.torque_ratio if tau_max is None else tau_max)
        self.normalize_action = bool(normalize_action)
        self.observe_roll = bool(observe_roll)
        self.init_roll = math.radians(init_roll_deg)
        self._roll_scale = math.radians(reward_roll_scale_deg)
        self._effort_w = float(reward_effort_weight)
        self.render_mode = render_mode
        self.scenario_seed = scenario_seed
        self.randomize_course = bool(randomize_course)

        self.actuator = Actuator() if actuator is None else actuator
        self.cost_config = CostConfig() if cost is None else cost
        if not isinstance(self.actuator, Actuator):
            raise EnvConfigError(f"actuator must be a ptw_env.episode.Actuator, got {type(actuator).__name__}")
        if not isinstance(self.cost_config, CostConfig):
            raise EnvConfigError(f"cost must be a ptw_env.episode.CostConfig, got {type(cost).__name__}")
        try:
            delay, self._act_alpha, self._act_rate, self._act_limit = self.actuator.discrete(self.dt, self.tau_max)
        except EpisodeConfigError as exc:
            raise EnvConfigError(str(exc)) from None
        self._act_buf = np.zeros(delay + 1)
        cc = self.cost_config
        #: ``(grip_limit, roll_limit [rad], torque step limit [N m per period], road_mu)`` of the cost
        self.cost_limits = (cc.grip_limit, math.radians(cc.roll_limit_deg), cc.torque_rate_limit * self.tau_max * self.dt,
                            cc.road_mu)
        try:
            self.randomization = Randomization.coerce(randomize)
        except RandomizationError as exc:
            raise EnvConfigError(str(exc)) from None
        if self.randomization is not None:
            try:
                self.randomization.check_vehicle(self.vehicle)  # every vehicle it can draw, before any work
            except RandomizationError as exc:
                raise EnvConfigError(str(exc)) from None
        if self.randomization is not None and friction is not None:
            raise EnvConfigError("randomize= and friction= together are not supported: randomise "
                                 "tire_saturation:mu_peak for the road's friction instead")
        self.randomized: dict[str, float] = {}
        self._next_sample: dict[str, float] | None = None

        self.plant = compile_plant(self.vehicle, self.effects.dynamic)
        if substeps is not None:
            if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
                raise EnvConfigError(f"substeps must be a positive whole number, got {substeps!r}")
            if friction is not None:
                raise EnvConfigError("substeps= and friction= together are not supported (the friction schedule's "
                                     "plants size their own substeps)")
        self._min_substeps = 1 if substeps is None else int(substeps)
        self.friction = friction
        self._sensors = SensorModel(self.sensor_config, self.effects.sensor, dt=self.dt)
        self.profile = self.scenario.profile(self.dt, seed=scenario_seed)
        try:
            self.profile.check_vehicle(self.vehicle)
        except ScenarioError as exc:
            raise EnvConfigError(str(exc)) from None
        self.max_steps = len(self.profile.t) - 1
        self.mirror = bool(mirror)
        #: the rides an episode is drawn from (each (profile, mirrored profile)); one ride without a pool
        self.pool: list[tuple[Any, Any]] = []
        if scenario_pool is not None:
            if self.randomize_course:
                raise EnvConfigError("scenario_pool= and randomize_course= together are not supported")
            if isinstance(scenario_pool, (str, Scenario)) or not len(scenario_pool):
                raise EnvConfigError("scenario_pool must be a non-empty list of scenario names or Scenario objects")
            for j, sc in enumerate(scenario_pool):
                if isinstance(sc, str):
                    sc = make_scenario(sc, speed_kmh=speed_kmh)
                elif not isinstance(sc, Scenario):
                    raise EnvConfigError(f"scenario_pool[{j}] must be a scenario name or a Scenario, got {type(sc).__name__}")
                prof = sc.profile(self.dt, seed=scenario_seed)
                try:
                    prof.check_vehicle(self.vehicle)
                except ScenarioError as exc:
                    raise EnvConfigError(f"scenario_pool[{j}]: {exc}") from None
                self.pool.append((prof, prof.mirrored()))
        else:
            self.pool.append((self.profile, self.profile.mirrored()))
        self.ride_index, self.mirrored = 0, False
        #: RK4 substeps per control period of each ride of :attr:`pool` (a mirrored ride has the same speeds)
        by_ride = self.step_speeds == "ride" and not self.randomize_course
        self.ride_substeps: tuple[int, ...] = tuple(
            self._substeps_at(prof.vx if by_ride else None) for prof, _ in self.pool)
        self._stepper = Stepper(self.plant, self.dt, substeps=self.ride_substeps[0])
        self._friction = None if friction is None else FrictionPlants(
            friction, self.vehicle, self.effects, self.dt,
            speeds=np.concatenate([prof.vx for prof, _ in self.pool]) if by_ride else None)

        a = 1.0 if self.normalize_action else self.tau_max
        self.action_space = spaces.Box(-a, a, shape=(1,), dtype=np.float32)
        nobs = 8 if self.observe_roll else 7
        hi = np.array([0.6, 10.0, 5.0, 10.0, 50.0, 60.0, FALL_ANGLE, 3.2][:nobs], dtype=np.float32)
        self.observation_space = spaces.Box(-hi, hi, dtype=np.float32)
        self._obs_hi, self._obs_lo = hi, -hi
        assert CHANNELS == ("delta", "delta_rate", "yaw_rate", "roll_rate", "ay", "roll", "vx")

        self.state = np.zeros(8)
        self._k = 0
        self._trace: list[tuple[float, float, float]] = []
        self._pose = np.zeros(3)  # X, Y, psi
        self._fig = None

    # ------------------------------------------------------------------
    def get_prior(self):
        """The model a controller may use (:class:`~ptw_env.dynamics.Plant` of the prior vehicle
        and prior effects): the design model, separate from the true plant."""
        return compile_plant(self.prior_vehicle, self.prior_effects.dynamic)

    def episode_models(self, samples: Mapping[str, Any]) -> tuple[Effects, SensorModel]:
        """The true effects and the sensor model of an episode with the randomised ``samples``
        (:meth:`ptw_env.randomize.Randomization.sample`): the environment's effects with the sampled
        parameters in place, its sensors with the noise scaled and the biases added."""
        assert self.randomization is not None
        eff = self.randomization.effects(self.effects, samples)
        scale, bias = self.randomization.sensor_terms(samples)
        cfg = self.sensor_config
        if scale != 1.0 or bias:
            cfg = replace(cfg, noise_std={c: v * scale for c, v in cfg.noise_std.items()},
                          bias={c: v + bias.get(c, 0.0) for c, v in cfg.bias.items()})
        return eff, SensorModel(cfg, eff.sensor, dt=self.dt)

    def _observe(self) -> np.ndarray:
        x = self.state
        y = self._sensors.measure(x, float(self.profile.vx[self._k]), float(self.plant.ay(x)))
        obs = np.empty(len(self._obs_hi), dtype=np.float32)
        observe_into(y, float(self.profile.phi_ref[self._k]), self.observe_roll, self._obs_hi, obs)
        self._last_measurement = y
        return obs

    def _info(self) -> dict[str, Any]:
        k = self._k
        return {
            "state": self.state.copy(),
            "t": k * self.dt,
            "phi_ref": float(self.profile.phi_ref[k]),
            "vx": float(self.profile.vx[k]),
            "measurement": self._last_measurement.copy(),
            **({} if self.friction is None else {"friction": self.friction.mu(k * self.dt, float(self.profile.s[k]))}),
            **({} if self.randomization is None else {"randomized": dict(self.randomized)}),
            **({} if len(self.pool) == 1 and not self.mirror else {"ride": self.ride_index, "mirrored": self.mirrored}),
        }

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        x0 = options.pop("x0", None)
        if options:
            raise EnvConfigError(f"unknown reset option(s): {sorted(options)}; known: x0")
        if len(self.pool) > 1 or self.mirror:  # the ride: first draws of the episode
            self.ride_index, self.mirrored = draw_ride(self.np_random, len(self.pool), self.mirror)
            self.profile = self.pool[self.ride_index][1 if self.mirrored else 0]
            self.max_steps = len(self.profile.t) - 1
            self._stepper.nsub = self.ride_substeps[self.ride_index]
        if self.randomization is not None:  # then the randomised values (ptw_env.randomize)
            if seed is not None or self._next_sample is None:  # the first episode's values (or a new seed's)
                self._next_sample = self.randomization.sample(self.np_random)
            self.randomized = self._next_sample
            self._next_sample = self.randomization.sample(self.np_random)  # the next episode's, drawn now
            _, self._sensors = self.episode_models(self.randomized)
            if self.randomization.changes_plant:
                self.plant = self.randomization.plant(self.vehicle, self.effects, self.randomized)
                self._stepper = Stepper(self.plant, self.dt, substeps=self._stepper.nsub)
        if x0 is None:
            self.state = np.zeros(8)
            self.state[0] = self.np_random.uniform(-self.init_roll, self.init_roll)
        else:
            x0 = np.asarray(x0, dtype=float)
            if x0.shape != (8,) or not np.all(np.isfinite(x0)):
                raise EnvConfigError(f"reset option x0 must be 8 finite numbers (the state of model.md), got {x0!r}")
            self.state = x0.copy()
        if self.randomize_course:
            # a new course from the environment's one generator (STYLE: everything from np_random)
            self.profile = self.scenario.profile(self.dt, seed=int(self.np_random.integers(2**31 - 1)))
            try:
                self.profile.check_vehicle(self.vehicle)
            except ScenarioError as exc:
                raise EnvConfigError(f"randomize_course: {exc}") from None
            self.max_steps = len(self.profile.t) - 1
        self._k = 0
        self._act_buf[:] = 0.0
        self._act_prev = 0.0
        self._sensors.reset(self.np_random)
        self._pose[:] = (self.profile.X[0], self.profile.Y[0], self.profile.psi[0])
        self._trace = [(self._pose[0], self._pose[1], self.state[0])]
        obs = self._observe()
        return obs, self._info()

    def step(self, action):
        try:
            (u,) = np.ravel(action)
            u = float(u)
        except (ValueError, TypeError):
            raise InvalidActionError(
                f"action must hold one number (the steering torque), got {np.shape(action)} {action!r}"
            ) from None
        if not math.isfinite(u):
            raise InvalidActionError(f"action is not finite: {u!r} (step {self._k}, t = {self._k * self.dt:.2f} s)")
        tau, clipped = command(u, float(self.action_space.high[0]), self.tau_max, self.normalize_action)

        k = self._k
        vx = float(self.profile.vx[k])
        t = k * self.dt
        d_tau = d_roll = 0.0
        for d in self.disturbances:
            if d.channel == "torque":
                d_tau += d.value(t, self.np_random)
            else:
                d_roll += d.value(t, self.np_random)
        x = self.state
        stepper = self._stepper
        if self._friction is not None:
            stepper = self._friction.stepper(self.friction.mu(t, float(self.profile.s[k])))
        prev = self._act_prev
        applied = actuate(tau, self._act_buf, k, prev, self._act_alpha, self._act_rate, self._act_limit)
        self._act_prev = applied
        finite = stepper.step(x, applied + d_tau, vx, d_roll)
        advance_pose(self._pose, vx, x[2], x[3], self.dt)
        self._k = k + 1

        phi = x[0]
        nxt = min(self._k, self.max_steps)
        code = end_code(finite, phi, FALL_ANGLE, self.profile.vx[nxt], self.vehicle.vmin, self.vehicle.vmax,
                        self._k, self.max_steps)
        terminated = 0 < code < SCENARIO_END
        truncated = code == SCENARIO_END
        reason = REASONS[code] if code else None
        reward = roll_reward(phi, self.profile.phi_ref[nxt], tau / self.tau_max, self._roll_scale, self._effort_w)
        if not finite:
            self.state = np.nan_to_num(x, nan=0.0, posinf=0.0, neginf=0.0)
        self._k = nxt
        grip, roll_lim, dtau_lim, road_mu = self.cost_limits
        util = grip_utilisation(self.state, stepper.plant.fmax, stepper.plant.fz, road_mu)
        cost = step_cost(util, phi, applied - prev, grip, roll_lim, dtau_lim)
        obs = self._observe()
        info = self._info()
        info["tau"] = applied
        info["tau_command"] = tau
        info["action_clipped"] = clipped
        info["cost"] = cost
        info["grip_utilisation"] = util
        if reason is not None:
            info["reason"] = reason
        self._trace.append((self._pose[0], self._pose[1], x[0]))
        if self.render_mode == "human":
            self.render()
        return obs, float(reward), bool(terminated), bool(truncated), info

    # ------------------------------------------------------------------ public view (render, tools)
    @property
    def substeps(self) -> int:
        """RK4 substeps per control period of the current ride (:attr:`ride_substeps`; with ``friction=``
        each friction's plant has its own stepper, sized on the speeds of all the rides)."""
        return self._stepper.nsub

    def _substeps_at(self, speeds) -> int:
        """Substeps for a ride meeting ``speeds`` [m/s] (``None``: the vehicle's whole range): the plant's and
        its vehicle's fastest mode there and, with a randomisation that changes the plant, the fastest plant
        and vehicle it can draw (:meth:`ptw_env.randomize.Randomization.stiffest_rate`, ``check_vehicle``); at
        least ``substeps=``."""
        # a fixed dynamic effect may be the stiffest mode; without one the plant is the vehicle (its modes below)
        rate = float(linear_rate(self.plant, speeds)) if self.effects.dynamic else 0.0
        rnd = self.randomization
        if rnd is not None and rnd.changes_plant:
            try:
                rate = max(rate, rnd.stiffest_rate(self.vehicle, self.effects, speeds), rnd.check_vehicle(self.vehicle, speeds))
            except RandomizationError as exc:
                raise EnvConfigError(str(exc)) from None
        return max(self._min_substeps, substeps_for(self.dt, vehicle=self.vehicle, extra_rate=rate, speeds=speeds))

    @property
    def axle_loads(self) -> np.ndarray:
        """Static normal loads ``(Fzf, Fzr)`` [N] of the vehicle's tires (this episode's vehicle when it is
        randomised)."""
        return self.plant.fz

    @property
    def sensor_model(self) -> SensorModel:
        """The current episode's sensor model."""
        return self._sensors

    @property
    def obs_bound(self) -> np.ndarray:
        """Bound of each observation channel (the sensors' full scale), float32."""
        return self._obs_hi

    @property
    def reward_params(self) -> tuple[float, float]:
        """``(s [rad], w)`` of the reward ``exp(-(phi - phi_ref)^2 / (2 s^2)) - w (tau / tau_max)^2``."""
        return self._roll_scale, self._effort_w

    @property
    def step_index(self) -> int:
        """Index ``k`` of the current sample (time ``k dt`` [s]) in the episode's profile."""
        return self._k

    @property
    def pose(self) -> tuple[float, float, float]:
        """Ground pose ``(X [m], Y [m], psi [rad])`` of the rear contact, dead-reckoned from ``vx``, ``vy``, ``r``."""
        return float(self._pose[0]), float(self._pose[1]), float(self._pose[2])

    @property
    def trace(self) -> np.ndarray:
        """Path so far, shape (n, 3): ``X`` [m], ``Y`` [m] and roll ``phi`` [rad] at every step of the episode."""
        return np.asarray(self._trace, dtype=float).reshape(-1, 3)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        from .render import draw_frame

        frame = draw_frame(self)
        if self.render_mode == "rgb_array":
            return frame
        from .render import show_frame

        self._fig = show_frame(frame, self._fig)
        return None

    def close(self) -> None:
        if self._fig is not None:
            import matplotlib.pyplot as plt

            plt.close(self._fig)
            self._fig = None
