"""unknown_input: the unknown-input high-order sliding-mode observer (roll angle, rider torque).

``structure`` (invariant zeros, relative degrees, strong observability/detectability), ``observability``
(the HOSM cases per speed), ``differentiator`` (Levant's differentiator, Livne-Levant discretisation),
``hosm`` (the UIHOSMO of Nehaoua et al. 2014).

May import: ``ptw_env`` only.
"""
