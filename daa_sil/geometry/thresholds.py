"""Well-clear and NMAC threshold presets.

Three presets (``daa_sil.geometry.thresholds.PRESETS``):

``do365`` (default)
    RTCA DO-365 Phase I cooperative DAA well clear as the standard's text states it: DMOD = HMD* =
    4000 ft (1219.2 m), ZTHR = h* = 450 ft (137.16 m), TAUMOD* = 35 s, TCOA = 0; NMAC 500 ft
    horizontal / 100 ft vertical (RTCA SC-147).
``paper``
    Tabassum & Bai: HMD* = 1220 m, d_h* = 122 m, tau_mod* = 35 s; NMAC 500 ft / 120 ft.
``daidalus``
    NASA DAIDALUS v2.0.4 ``DO_365B_no_SUM.conf``: the same volume with DMOD = HMD* = 0.66 nmi
    (1222.32 m, 3.1 m more than 4000 ft), ZTHR 450 ft, TTHR 35 s, TCOA 0; NMAC 500 ft / 100 ft.
    With this preset the onboard DAA also uses DAIDALUS's band grids, horizons, recovery and
    hysteresis (:meth:`daa_sil.daa.DaaConfig.for_preset`).

Every output of daa-sil records the preset name it used. Boundaries are closed (``<=``) for both
the well-clear violation and NMAC.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

from daa_sil.config.settings import PRESET
from daa_sil.errors import UsageError
from .units import FT, NMI


@dataclass(frozen=True)
class Thresholds:
    """A well-clear volume plus the NMAC cylinder. Distances in metres, times in seconds."""

    name: str
    dthr: float  #: horizontal distance threshold DTHR = DMOD = HMD*, m
    zthr: float  #: vertical threshold ZTHR = h* (the paper's d_h*), m
    tthr: float  #: modified-tau threshold TTHR = tau_mod*, s
    tcoa: float = 0.0  #: time-to-co-altitude threshold, s (0 in DO-365)
    nmac_h: float = 500.0 * FT  #: NMAC horizontal separation, m
    nmac_v: float = 100.0 * FT  #: NMAC vertical separation, m

    def to_dict(self) -> dict:
        """Plain dict (for JSON metadata)."""
        return asdict(self)

    def with_(self, **changes) -> "Thresholds":
        """A copy with some fields changed (name becomes ``<name>+custom``)."""
        name = changes.pop("name", None) or (self.name if not changes else f"{self.name}+custom")
        return replace(self, name=name, **changes)


DO365 = Thresholds(name="do365", dthr=4000.0 * FT, zthr=450.0 * FT, tthr=35.0, tcoa=0.0,
                   nmac_h=500.0 * FT, nmac_v=100.0 * FT)
PAPER = Thresholds(name="paper", dthr=1220.0, zthr=122.0, tthr=35.0, tcoa=0.0,
                   nmac_h=500.0 * FT, nmac_v=120.0 * FT)

DAIDALUS = Thresholds(name="daidalus", dthr=0.66 * NMI, zthr=450.0 * FT, tthr=35.0, tcoa=0.0,
                      nmac_h=500.0 * FT, nmac_v=100.0 * FT)

PRESETS: dict[str, Thresholds] = {"do365": DO365, "paper": PAPER, "daidalus": DAIDALUS}
#: the preset a run flies when none is named (defined in :mod:`daa_sil.config.settings`)
DEFAULT_PRESET = PRESET.default


def get_thresholds(preset: "str | Thresholds | None" = None) -> Thresholds:
    """Return the named preset (:data:`DEFAULT_PRESET`, ``paper``, when None); a Thresholds passes through unchanged."""
    if preset is None:
        return PRESETS[DEFAULT_PRESET]
    if isinstance(preset, Thresholds):
        return preset
    try:
        return PRESETS[str(preset).lower()]
    except KeyError:
        allowed = ", ".join(PRESETS)
        raise UsageError(f"unknown threshold preset {preset!r}; allowed: {allowed}") from None
