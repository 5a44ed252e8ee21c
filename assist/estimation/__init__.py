"""estimation: states and tire stiffness from the measured outputs.

``lpv_model`` (the LPV form of the one model, Fouka et al.), ``adaptive_design`` (Theorem 2 and Kalman
vertex gains), ``adaptive_observer`` (the LPV adaptive observer), ``identification`` (direct, inversion and
joint-EKF baselines), ``identifiability`` (Cramér-Rao bounds), ``friction_imm`` (road friction, bank and
yaw-gyro offset by interacting multiple models of the saturating tire), ``figures`` (the estimate's figure, the
sidecar's stiffness truth).

May import: ``ptw_env`` only.
"""
