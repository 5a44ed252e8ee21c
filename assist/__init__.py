"""assist: rider-assistance algorithms for ptw_env vehicles, one folder per family.

``control/`` (TS observer-based controller, LQG/LQR), ``estimation/`` (LPV adaptive observer of states and
tire stiffness, baselines, Cramér-Rao bounds), ``unknown_input/`` (HOSM observer of roll angle and rider
torque, structural analysis), ``risk/`` (risk warning; imports estimation), ``diagnose/`` (model
discrepancy), ``rl/`` (RL baseline; the shipped policy in ``policies/``), ``evaluate.py`` (closed-loop
episodes of any controller through ``env.step``; imports control and rl), ``cli/`` (the ``ptw-assist``
program, on top). A family imports ``ptw_env`` and only the families named here; the modules at the old
flat paths (``assist.ts_design``, ...) re-export the new ones for one release with a DeprecationWarning.
``tests/test_architecture.py`` checks these rules.
"""
