"""control: the Takagi-Sugeno observer-based roll-tracking controller and its baselines.

``ts_model`` (TS vertex model, Dabladji et al. eqs. 3-7), ``ts_design`` (Theorems 1-2 as LMIs, cvxpy +
Clarabel, certificates re-checked in numpy), ``ts_discrete`` (the exact sampled-data form shared by the design
and the runtime), ``ts_controller`` (the 100 Hz runtime, reference filter and feedforward), ``lqg`` (LQG and
the full-state tracking LQR).

May import: ``ptw_env`` only (no other family of ``assist``).
"""
