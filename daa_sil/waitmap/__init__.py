"""MDP wait maps (Tabassum & Bai Sec. II and IV): how long the UAS may wait for its delayed remote pilot.

State ``(dx, dy, dh, vi, vh, theta)`` in the paper's relative frame (``daa_sil.geometry.frames``: X ahead,
Y left, theta CCW from the ownship track, + turn rate = left), actions wait / evade, paper Eq. 1-8
kinematics with ownship 55 m/s along +X and dt = 1 s, intruder maneuvers from paper Table 1
(horizontal pair OR vertical per step), multilinear mass splitting, EXIT outside the box,
absorbing LoWC (paper Eq. 9 with the chosen threshold preset) and OUT (after evade).

Our interpretations (all configurable in :class:`MdpParams`):

* Rewards: ``R_w(S') = -min(C1/HMD(S'), C2/|d_h(S')|) + C3 dt`` (HMD within the tau_mod*
  look-ahead; HMD and |d_h| floored at 1 m),
  averaged over the continuous next states; ``R_e = 0``; terminal values LoWC
  ``-C3 dt/(1-gamma)`` (a loss of well clear forfeits the whole discounted wait bonus), EXIT 0, OUT 0.
* Wait time (``wait_definition``, :mod:`.solve`): ``paper`` (default) = E[T_LoWC | LoWC within H]
  under the waiting chain, W = 0 where evading is optimal, W = H where P(LoWC within H) < ``p_min``
  (1e-3); ``until_evade`` = expected time until LoWC or an evade-optimal state (an earlier reading).
  ``p_lowc`` = P(LoWC within H if the UAS keeps waiting).
* A map for initial turn rate omega0 uses ``P(dtheta) = 0.8 [dtheta = omega0] + 0.2 Table1``
  every step (see :mod:`.model`); Table 1 is symmetric, so the +-omega0 maps are mirror images
  and the 0 map is symmetric.
* Lookups outside the box read the nearest point of the box (clamped, :mod:`.lookup`); the
  ``alerting`` map preset (the default, :data:`MAP_PRESETS`) covers the DO-365 alerting region so
  that this is rare; ``paper`` is the paper's own +-1,500 m grid.

API::

    fam = waitmap.family_for("alerting", preset="paper")  # cached in $DAA_SIL_CACHE or ~/.cache/daa-sil
    res = fam.lookup(paper_states, turn_rate)              # (..., 6) states, turn rate rad/s (+ = left)
    res.wait_s, res.p_lowc, res.evade, res.in_box, res.map_turn_deg
"""

from .build import build_family, build_map, build_members
from .source import DEFAULT_MAP, MAP_PRESETS, default_family, describe, family_for, is_cached, map_params
from .cache import cache_dir
from .grid import GRID_PRESETS, Axis, Grid, alerting_grid, fine_grid, paper_grid, resolve_grid
from .lookup import LookupResult, WaitMap, WaitMapFamily
from .model import PAPER_TURN_RATES, WAIT_DEFINITIONS, MdpParams
from .family_files import check_family, load_family, save_family
from .store import FORMAT_VERSION, load, save

__all__ = [
    "Axis", "DEFAULT_MAP", "FORMAT_VERSION", "GRID_PRESETS", "Grid", "LookupResult", "MAP_PRESETS", "MdpParams",
    "PAPER_TURN_RATES", "WAIT_DEFINITIONS", "WaitMap", "WaitMapFamily", "alerting_grid", "build_family", "build_map",
    "build_members", "cache_dir", "check_family", "default_family", "describe", "family_for", "fine_grid", "is_cached", "load", "load_family", "map_params",
    "paper_grid", "resolve_grid", "save", "save_family",
]
