"""The remote pilot's random draws and maneuver choice (Guendel 2017, simplified; docs/models.md):
response-time components and the per-plane direction choice from the guidance, batched and seeded."""

from __future__ import annotations

import numpy as np

from daa_sil.errors import UsageError
from daa_sil.geometry.frames import wrap_2pi, wrap_pi
from daa_sil.geometry.kinematics import Command
from daa_sil.geometry.units import DEG, FPM
from daa_sil.models.pilot_config import NO_BAND, Guidance, PilotConfig


def sample_response_components(rng: np.random.Generator, size, cfg: PilotConfig) -> dict:
    """Response-delay components (s) for ``size`` draws from one generator, in the fixed order
    T_init, T_coord, T_exec, Rayleigh: ``{"init", "coord", "exec", "rayleigh"}``."""
    return {"init": rng.exponential(cfg.init_mean_s, size), "coord": rng.gamma(cfg.coord_k, cfg.coord_theta_s, size),
            "exec": rng.exponential(cfg.exec_mean_s, size), "rayleigh": rng.rayleigh(cfg.rayleigh_sigma_s, size)}


_K = 32


#: the pilot's per-decision random draws, in the order they are drawn
DRAW_KEYS = ("exec", "update", "u_turn", "u_follow_h", "u_tie_h", "u_follow_v", "u_tie_v", "g_primary",
               "g_opposite", "g_vertical")


def draw_decisions(rng: np.random.Generator, cfg: PilotConfig, k: int = _K) -> dict:
    """Per-decision draws for ``k`` decisions (fixed order: :data:`DRAW_KEYS`). ``update`` is
    a unit-mean exponential scaled by the level's mean at use; gammas are in deg / ft with the
    offset already subtracted."""
    return {"exec": rng.exponential(cfg.exec_mean_s, k), "update": rng.exponential(1.0, k),
            "u_turn": rng.random(k), "u_follow_h": rng.random(k), "u_tie_h": rng.random(k),
            "u_follow_v": rng.random(k), "u_tie_v": rng.random(k),
            "g_primary": rng.gamma(cfg.turn_primary[0], cfg.turn_primary[1], k) - cfg.turn_primary[2],
            "g_opposite": rng.gamma(cfg.turn_opposite[0], cfg.turn_opposite[1], k) - cfg.turn_opposite[2],
            "g_vertical": rng.gamma(cfg.vertical[0], cfg.vertical[1], k) - cfg.vertical[2]}


def as_generator(s) -> np.random.Generator:
    """A pilot's generator from a seed (non-negative int), a ``SeedSequence`` or a ``Generator`` (as is)."""
    if isinstance(s, np.random.Generator):
        return s
    if isinstance(s, np.random.SeedSequence):
        return np.random.Generator(np.random.PCG64(s))
    try:
        v = int(s)
    except (TypeError, ValueError):
        raise UsageError(f"pilot seed must be a non-negative int, SeedSequence or Generator, got {s!r}") from None
    if v < 0:
        raise UsageError(f"pilot seed must be a non-negative int, got {s!r}")
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(v)))


def choose_maneuver(cur_trk, cur_vs, cur_gs, g: Guidance, draws: dict, cfg: PilotConfig
                    ) -> tuple[Command, np.ndarray, np.ndarray]:
    """The maneuver decided from guidance ``g`` (all (n,) arrays; ``draws`` one value per pilot of
    each :data:`DRAW_KEYS` entry). Returns ``(cmd, axis, direction)`` codes; axis 0 (hold the
    current state) when no candidate exists. Pure and vectorised."""
    det = cfg.deterministic
    cur_trk, cur_vs, cur_gs = (np.asarray(a, float) for a in (cur_trk, cur_vs, cur_gs))
    merge = lambda lv: np.where(lv <= 1, 0.0, lv)  # noqa: E731 - clear and recovery count equal
    lL, lR, lU, lD = merge(g.left_level), merge(g.right_level), merge(g.up_level), merge(g.down_level)
    lL = np.where(np.isnan(g.left_trk), NO_BAND, lL)
    lR = np.where(np.isnan(g.right_trk), NO_BAND, lR)
    lU = np.where(np.isnan(g.up_vs), NO_BAND, lU)
    lD = np.where(np.isnan(g.down_vs), NO_BAND, lD)
    aL = np.nan_to_num(wrap_2pi(cur_trk - g.left_trk), nan=np.inf)
    aR = np.nan_to_num(wrap_2pi(g.right_trk - cur_trk), nan=np.inf)
    dU = np.nan_to_num(np.abs(g.up_vs - cur_vs), nan=np.inf)
    dD = np.nan_to_num(np.abs(cur_vs - g.down_vs), nan=np.inf)

    # horizontal direction: +1 right, -1 left
    mindev_h = np.where(aL < aR, -1.0, np.where(aR < aL, 1.0,
                        np.where(det | (draws["u_tie_h"] < cfg.prob_left), -1.0, 1.0)))
    far = np.abs(aL - aR) > cfg.max_relative_hdg_deg * DEG
    follow = det | far | (draws["u_follow_h"] < cfg.prob_follow_min_dev)
    same_h = np.where(follow, mindev_h, -mindev_h)
    h_dir = np.where(lL < lR, -1.0, np.where(lR < lL, 1.0, same_h))
    primary = h_dir == mindev_h
    h_min = np.where(h_dir < 0, aL, aR)
    h_lvl = np.where(h_dir < 0, lL, lR)
    # vertical direction: +1 up, -1 down
    mindev_v = np.where(dU < dD, 1.0, np.where(dD < dU, -1.0,
                        np.where(det | (draws["u_tie_v"] >= cfg.prob_descend), 1.0, -1.0)))
    follow_v = det | (draws["u_follow_v"] < cfg.prob_follow_min_dev)
    same_v = np.where(follow_v, mindev_v, -mindev_v)
    v_dir = np.where(lU < lD, 1.0, np.where(lD < lU, -1.0, same_v))
    v_sugg = np.where(v_dir > 0, g.up_vs, g.down_vs)
    v_lvl = np.where(v_dir > 0, lU, lD)
    # plane
    prefer_turn = det | (draws["u_turn"] < cfg.prob_turn)
    turn = (prefer_turn & (h_lvl <= v_lvl)) | (~prefer_turn & (h_lvl < v_lvl))
    none = ~np.isfinite(h_lvl) & ~np.isfinite(v_lvl)

    # turn magnitude
    if det:
        delta = np.where(primary, cfg.det_turn_primary_deg, cfg.det_turn_opposite_deg) * DEG
    else:
        delta = np.where(primary, draws["g_primary"], draws["g_opposite"]) * DEG
    h_min_f = np.where(np.isfinite(h_min), h_min, 0.0)
    mag = h_min_f + delta
    mag = np.where(mag < 0.0, h_min_f, mag)
    mag = np.minimum(mag, cfg.max_turn_deg * DEG)
    trk = cur_trk + h_dir * mag
    if cfg.heading_round_deg > 0:
        q = cfg.heading_round_deg * DEG
        r = np.round(trk / q) * q
        # rounding must not turn the command across the current track (or below zero turn)
        away = np.where(h_dir > 0, np.ceil(trk / q), np.floor(trk / q)) * q
        r = np.where(h_dir * wrap_pi(r - cur_trk) < 0, away, r)
        trk = r
    trk = wrap_2pi(trk)
    # vertical magnitude (ft overshoot read as fpm)
    dv = (cfg.det_vertical_ft if det else draws["g_vertical"]) * FPM
    v_sugg_f = np.where(np.isfinite(v_sugg), v_sugg, cur_vs)
    vs = v_sugg_f + v_dir * dv
    vs = np.where(v_dir * (vs - cur_vs) < 0, v_sugg_f, vs)

    cmd_trk = np.where(none, cur_trk, np.where(turn, trk, cur_trk))
    cmd_vs = np.where(none, cur_vs, np.where(turn, cur_vs, vs))
    axis = np.where(none, 0, np.where(turn, 1, 2)).astype(np.int64)
    direction = np.where(none, 0, np.where(turn, np.where(h_dir < 0, 1, 2), np.where(v_dir > 0, 3, 4))).astype(np.int64)
    return Command(cmd_trk, cmd_vs, cur_gs.copy()), axis, direction
