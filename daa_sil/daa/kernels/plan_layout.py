"""The columns of SM's compiled command plan (``command_plan.command_plan_into``'s ``plan[:, i]``), defined
once and without numba, so :mod:`daa_sil.daa.safety` reads them without loading the kernels."""

#: knot spacing (s), knot count, bounds on the horizontal / vertical acceleration (m/s^2) and on the
#: horizontal jerk (m/s^3), the instants the turn and the speed change end (s, inf = none), and the time
#: to reach the commanded vertical speed (s)
H, N_KNOTS, ACC_H, ACC_V, JERK, KINK_TRK, KINK_GS, T_VS = range(8)
N_PLAN = 8

__all__ = ["H", "N_KNOTS", "ACC_H", "ACC_V", "JERK", "KINK_TRK", "KINK_GS", "T_VS", "N_PLAN"]
