"""What the remote pilot sees: the DAA guidance (bands, regions, preferred sides) as the pilot
model's :class:`~daa_sil.models.pilot_config.Guidance`, from the bands the GCS receives or computed
from the (delayed) traffic picture."""

from __future__ import annotations

import numpy as np

from daa_sil.geometry.kinematics import AircraftState
from daa_sil.models.pilot_config import NO_BAND, Guidance

_REGION_LEVEL = np.array([0.0, 2.0, 3.0, 4.0, 1.0])  # daa REGION_NONE, FAR, MID, NEAR, RECOVERY -> level


def _side_candidate(ax, want: int) -> tuple[np.ndarray, np.ndarray]:
    """Closest candidate (min time to reach) on side ``want`` among those with the side's lowest
    level (0/1 merged), of each encounter's own candidates; returns (value, level) with nan/inf where the
    side is empty."""
    lvl = _REGION_LEVEL[np.asarray(ax.region, int)]
    merged = np.where(lvl <= 1, 0.0, lvl)
    on = (np.asarray(ax.side) == want)[None, :]
    own = ax.own_mask()
    if own is not None:
        on = on & own
    best = np.where(on, merged, np.inf).min(axis=1)
    cost = np.where(on & (merged == best[:, None]), ax.t_man, np.inf)
    k = np.argmin(cost, axis=1)
    found = np.isfinite(np.take_along_axis(cost, k[:, None], 1)[:, 0])
    val = np.take_along_axis(ax.values, k[:, None], 1)[:, 0]
    level = np.take_along_axis(lvl, k[:, None], 1)[:, 0]
    return np.where(found, val, np.nan), np.where(found, level, NO_BAND)


def guidance_from_bands(bands) -> Guidance:
    """:class:`Guidance` from :class:`daa_sil.daa.bands.Bands` (track and vertical-speed axes)."""
    lt, ll = _side_candidate(bands.trk, -1)
    rt, rl = _side_candidate(bands.trk, +1)
    dv, dl = _side_candidate(bands.vs, -1)
    uv, ul = _side_candidate(bands.vs, +1)
    alert = np.asarray(bands.alert)
    lvl = alert.max(axis=1) if alert.ndim == 2 and alert.shape[1] else np.zeros(len(lt))
    return Guidance(alert_level=lvl, left_trk=lt, left_level=ll, right_trk=rt, right_level=rl, up_vs=uv,
                    up_level=ul, down_vs=dv, down_level=dl)


def display_bands(own: AircraftState, intr: AircraftState, cfg):
    """The bands a display computes for ownship (R,) and intruders (R, M): only the track and
    vertical-speed axes, the ones :func:`guidance_from_bands` reads (never ground speed)."""
    from daa_sil.daa.bands import compute_bands  # lazy: start-up time
    from daa_sil.daa.config import AXIS_HORIZONTAL, AXIS_VERTICAL  # lazy: start-up time

    return compute_bands(own, intr, cfg, axes=(AXIS_HORIZONTAL, AXIS_VERTICAL))


def guidance_values(bands) -> dict:
    """``{key: (R,)}`` of :attr:`PilotDisplay.KEYS` from bands of R encounters (track and vertical axes)."""
    g = guidance_from_bands(bands)
    return {key: getattr(g, key) for key in PilotDisplay.KEYS}


class PilotDisplay:
    """What N pilots' displays show, refreshed only for the pilots that see newer telemetry (the GCS
    of the SIL and the fast-time loop both use this, so the pilot reads the same guidance in both).

    Per pilot: the vehicle's DAIDALUS alert level sent with that telemetry, well clear violated on
    the observed states and, at or above ``alert_level_min``, the DAA bands' candidates of the
    observed states (``cfg`` a :class:`daa_sil.daa.config.DaaConfig`); below it the last bands stay.
    The bands of all the pilots refreshed at a step are one call (each row's are what it gets alone).
    """

    #: the band fields of :class:`Guidance` the display shows
    KEYS = ("left_trk", "left_level", "right_trk", "right_level", "up_vs", "up_level", "down_vs", "down_level")

    def __init__(self, n: int, cfg, alert_level_min: int):
        self.cfg = cfg
        self.alert_level_min = int(alert_level_min)
        nan = np.full(n, np.nan)
        #: what every pilot sees now, updated row by row (:meth:`guidance` hands out copies)
        self.current = Guidance(np.zeros(n, np.int64), nan, nan, nan, nan, nan, nan, nan, nan, np.zeros(n, bool))

    @property
    def alert(self) -> np.ndarray:
        """(N,) the vehicle's alert level each pilot was last sent (int64; the display's own array)."""
        return self.current.alert_level

    @property
    def wcv(self) -> np.ndarray:
        """(N,) well clear violated on the observed states (bool; the display's own array)."""
        return self.current.wcv

    @property
    def bands(self) -> dict:
        """``{key: (N,)}`` of :attr:`KEYS` (the display's own arrays)."""
        return {key: getattr(self.current, key) for key in self.KEYS}

    def refresh(self, rows: np.ndarray, own: AircraftState, intr: AircraftState, alert: np.ndarray) -> None:
        """Pilots ``rows`` (indices) now see ownship ``own`` (R,), intruders ``intr`` (R, M) and the
        vehicle's alert level ``alert`` (R,) sent with them."""
        from daa_sil.daa.alerting import relative_state  # lazy: start-up time
        from daa_sil.geometry.wellclear import encounter_geometry  # lazy: start-up time

        rows = np.asarray(rows, np.int64)
        if not rows.size:
            return
        g = self.current
        alert = np.asarray(alert, np.int64)
        g.alert_level[rows] = alert
        # (wellclear.wcv, in the one compiled pass of the step's geometry where the kernels are loaded)
        g.wcv[rows] = encounter_geometry(*relative_state(own, intr), self.cfg.th)["wcv"].any(axis=1)
        k = np.flatnonzero(alert >= self.alert_level_min)
        if k.size:
            got = guidance_values(display_bands(own[k], intr[k], self.cfg))
            for key in self.KEYS:
                getattr(g, key)[rows[k]] = got[key]

    def guidance(self) -> Guidance:
        """The current :class:`Guidance` of every pilot (N,): a copy, unchanged by later refreshes."""
        return self.current.copy()


def guidance_from_daa(own: AircraftState, intr: AircraftState, cfg=None) -> Guidance:
    """Compute :class:`Guidance` with :mod:`daa_sil.daa` for ownship (N,) and intruders (N, M)
    (``cfg``: a :class:`daa_sil.daa.config.DaaConfig`, default DO-365B); ``wcv`` from the preset."""
    from daa_sil.daa.alerting import relative_state  # lazy: start-up time
    from daa_sil.daa.config import DaaConfig  # lazy: start-up time
    from daa_sil.geometry.wellclear import wcv  # lazy: start-up time

    cfg = cfg or DaaConfig()
    g = guidance_from_bands(display_bands(own, intr, cfg))
    s, v = relative_state(own, intr)
    g.wcv = wcv(s, v, cfg.th).any(axis=1)
    return g
