"""ptw_env: nonlinear powered-two-wheeler lateral dynamics as a Gymnasium environment."""
from .vehicle import REFERENCE_SCOOTER, STATE_NAMES, Vehicle, reference_scooter
from .effects import Effects
from .dynamics import Plant, compile_plant, linearise
from .integrate import simulate
