"""Named readings of what the paper leaves open about its simulator (Tabassum & Bai Sec. IV-V).

The paper does not say in which unit its Table 6 gives the HMD and VMD ranges, from when its pilot
model streams commands, whether a "hold the current course" command counts as a pilot command,
or over which part of an encounter it counts commands. Each of these is one small, explicit setting
of a :class:`Reading`; a reading is recorded in ``campaign.json`` (``config.reading`` and
``config.readings``) and the report shows the readings side by side.

Settings that change the **simulation** (one campaign each):

* ``units`` -- Table 6's HMD U[0, 2750] and VMD U[-915, 915]: ``metres`` (literal) or ``feet``
  (838 m and 279 m; every CPA then lies inside DMOD);
* ``pilot_start`` -- when the pilot model streams: ``corrective`` (from the corrective alert, the
  agent's active phase), ``preventive`` (from the first, preventive alert: it also maneuvers from
  then) or ``detection`` ("hold" from the first telemetry, maneuvering from the corrective alert:
  the model "captures pilot response from the beginning of an encounter till safe avoidance");
* ``hold_commands`` -- the GCS streams "hold" as a pilot command until the pilot's first maneuver
  (true) or sends only maneuvers (false);
* ``waitmap`` -- the wait maps' grid: the paper's own ±1,500 m grid read at the nearest point of the
  box for states outside it (``paper``, the literal reading of "the agent matches the current state
  with a state in the wait map"), or unset (the campaign's ``--waitmap``, default ``alerting``).

Settings that change only the **counting** (the report recounts the same results):

* ``window`` -- ``active`` (the agent's active phase) or ``whole`` (the whole encounter);
* ``received`` -- ``arrived`` (every fresh command that reached the vehicle), ``pilot+blend`` (the
  paper's Table 5 arithmetic, received = pilot + blending) or ``executed`` (executed as sent).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

from daa_sil.errors import UsageError
from daa_sil.geometry.units import FT

UNITS = ("metres", "feet")
PILOT_STARTS = ("corrective", "preventive", "detection")
WINDOWS = ("active", "whole")
RECEIVED = ("arrived", "pilot+blend", "executed")


@dataclass(frozen=True)
class Reading:
    """One reading of the paper's simulator (see the module docstring)."""

    name: str = "literal"
    units: str = "metres"
    pilot_start: str = "corrective"
    hold_commands: bool = True
    waitmap: "str | None" = None
    window: str = "active"
    received: str = "arrived"
    description: str = ""

    def __post_init__(self):
        for key, allowed in (("units", UNITS), ("pilot_start", PILOT_STARTS), ("window", WINDOWS),
                             ("received", RECEIVED)):
            if getattr(self, key) not in allowed:
                raise UsageError(f"reading {self.name}: {key} must be one of {', '.join(allowed)}, "
                                 f"got {getattr(self, key)!r}")
        if not isinstance(self.hold_commands, bool):
            raise UsageError(f"reading {self.name}: hold_commands must be true or false, got {self.hold_commands!r}")

    # --- what the reading changes in the simulation ---------------------------------------------
    def encounter_overrides(self) -> dict:
        """:class:`daa_sil.models.encounters.EncounterConfig` fields (Table 6 HMD / VMD ranges, m)."""
        if self.units == "feet":
            return {"hmd_max_m": 2750.0 * FT, "vmd_max_m": 915.0 * FT}
        return {}

    def pilot_config(self, base=None):
        """The :class:`daa_sil.models.pilot_config.PilotConfig` of this reading (from ``base``, default PilotConfig())."""
        from daa_sil.models.pilot_config import PilotConfig

        base = base if base is not None else PilotConfig()
        level = 1 if self.pilot_start == "preventive" else 2
        stream = 0 if self.pilot_start == "detection" else None
        return replace(base, alert_level_min=level, stream_level_min=stream, stream_hold=self.hold_commands)

    def simulation_key(self) -> tuple:
        """The settings that change what is simulated (two readings with the same key share results)."""
        return (self.units, self.pilot_start, self.hold_commands, self.waitmap)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "Reading":
        known = {f.name for f in fields(cls)}
        bad = set(d) - known
        if bad:
            raise UsageError(f"unknown reading setting {sorted(bad)[0]!r}; allowed: {', '.join(sorted(known - {'name'}))}")
        return cls(**d)


#: named bundles; ``literal`` is what the simulator does by default
READINGS: dict[str, Reading] = {r.name: r for r in (
    Reading("literal", description="Table 6 in metres; the pilot streams from the corrective alert, "
                                   "'hold' included; counted over the active phase, every arrival"),
    Reading("paper-counts", window="whole", received="pilot+blend",
            description="as literal, counted like the paper's Table 5: over the whole encounter, "
                        "received = pilot + blending"),
    Reading("preventive", pilot_start="preventive", window="whole", received="pilot+blend",
            description="the pilot streams from the first (preventive) alert; paper counting"),
    Reading("feet", units="feet", pilot_start="preventive", window="whole", received="pilot+blend",
            description="Table 6 HMD/VMD in feet, the pilot from the preventive alert; paper counting"),
    Reading("detection", pilot_start="detection", window="whole", received="pilot+blend",
            description="the pilot streams 'hold' from the first telemetry, maneuvers from the corrective "
                        "alert; paper counting"),
    Reading("no-hold", hold_commands=False,
            description="as literal, but the GCS sends only the pilot's maneuvers, no 'hold'"),
    Reading("paper-grid", waitmap="paper",
            description="as literal, on the paper's own +-1,500 m wait-map grid (nearest point of the box outside)"),
)}


def reading_for(name: str = "literal", **overrides) -> Reading:
    """A named reading with optional setting overrides (``units="feet"``, ...)."""
    if name not in READINGS:
        raise UsageError(f"unknown reading {name!r}; allowed: {', '.join(READINGS)}")
    r = READINGS[name]
    return replace(r, **overrides) if overrides else r


def parse_reading_settings(text: "str | None") -> dict:
    """``--reading-set units=feet,hold_commands=false`` -> ``{"units": "feet", "hold_commands": False}``."""
    out: dict = {}
    if not text:
        return out
    known = {f.name for f in fields(Reading)} - {"name", "description"}
    for item in (p.strip() for p in text.split(",") if p.strip()):
        key, sep, val = item.partition("=")
        key = key.strip()
        if not sep or key not in known:
            raise UsageError(f"--reading-set item {item!r} must be KEY=VALUE with KEY one of {', '.join(sorted(known))}")
        val = val.strip()
        if key == "hold_commands":
            if val.lower() not in ("true", "false", "yes", "no"):
                raise UsageError(f"--reading-set hold_commands must be true or false, got {val!r}")
            out[key] = val.lower() in ("true", "yes")
        else:
            out[key] = val
    return out


__all__ = ["Reading", "READINGS", "reading_for", "parse_reading_settings", "UNITS", "PILOT_STARTS", "WINDOWS",
           "RECEIVED"]
