"""ptw_env: nonlinear powered-two-wheeler lateral dynamics as a Gymnasium environment.

The model is the reference scooter of ``shared/spec/model.md`` (:mod:`ptw_env.vehicle`),
simulated with the optional effects of ``shared/spec/effects.md``
(:mod:`ptw_env.effects`, :mod:`ptw_env.dynamics`) by a compiled RK4
integrator (:mod:`ptw_env.integrate`). Importing the package registers the
Gymnasium ids ``PTWRoll-v0`` (double lane change), ``PTWRollNorm-v0`` (same,
action normalised to [-1, 1] for RL) and ``PTWRoll-<Scenario>-v0`` for every
scenario, each with a native vector form (``gymnasium.make_vec(id, num_envs=N,
vectorization_mode="vector_entry_point")``, :mod:`ptw_env.vector`).

>>> import numpy as np, ptw_env
>>> x = ptw_env.simulate(np.zeros(8), np.zeros(50), 15.0)
>>> x.shape
(51, 8)
"""

from .dynamics import Plant, compile_plant, linearise
from .effects import Effects
from .integrate import simulate
from .sharp import SharpParameters, sharp_vehicle
from .vehicle import REFERENCE_SCOOTER, STATE_NAMES, Vehicle, reference_scooter
from .vehicle_files import VehicleFileError, load_vehicle, vehicle_names

__all__ = [
    "Effects",
    "Plant",
    "REFERENCE_SCOOTER",
    "STATE_NAMES",
    "SharpParameters",
    "Vehicle",
    "VehicleFileError",
    "compile_plant",
    "linearise",
    "load_vehicle",
    "reference_scooter",
    "sharp_vehicle",
    "simulate",
    "vehicle_names",
]

__version__ = "0.1.0"


def _register() -> None:
    import gymnasium as gym

    from .scenarios import make_scenario, scenario_names

    dt = 0.01

    def steps(name: str) -> int:
        return int(round(make_scenario(name).duration_s / dt))

    ids = {
        "PTWRoll-v0": ("double_lane_change", {}),
        "PTWRollNorm-v0": ("double_lane_change", {"normalize_action": True}),
    }
    for name in scenario_names():
        camel = "".join(w.capitalize() for w in name.split("_"))
        ids[f"PTWRoll-{camel}-v0"] = (name, {})
    for env_id, (scen, extra) in ids.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point="ptw_env.env:PTWRollEnv",
            vector_entry_point="ptw_env.vector:PTWRollVectorEnv",
            max_episode_steps=steps(scen),
            kwargs={"scenario": scen, **extra},
        )


_register()
