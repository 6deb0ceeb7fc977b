"""Named readings of the paper's simulator (Tabassum & Bai): every setting the text fixes, infers
or leaves open, as data.

A :class:`Reading` is a small bundle of explicit settings; it is recorded in ``campaign.json``
(``config.reading`` and ``config.readings``) and the report shows readings side by side.
``docs/results/paper-study.md`` ("The readings") quotes the sentence each setting of the ``paper``
reading rests on; this docstring names the settings.

Settings that change the **simulation** (one campaign each):

* ``units`` -- the HMD / VMD ranges of the paper's table "Intruder Parameters for Trajectory
  Generation" (0-2,750 and +-915), labelled ``HMD (m)`` and ``VMD (m)`` there: ``metres`` (the
  text) or ``feet`` (838 m and 279 m: every CPA then lies inside the horizontal well-clear
  distance). ``feet`` contradicts the table's labels; it is kept to measure what the unit does;
* ``pilot_start`` -- when the pilot model streams: ``corrective`` (from the corrective alert, the
  agent's active phase), ``preventive`` (from the first, preventive alert: it also maneuvers from
  then) or ``detection`` ("hold" from the first telemetry, maneuvering from the corrective alert);
* ``pilot_engage`` -- the alert level from which the pilot maneuvers: unset (``preventive`` for the
  ``preventive`` start, else ``corrective``) or ``corrective`` / ``preventive`` (a ``detection`` pilot
  streams "hold" from the first telemetry either way);
* ``pilot_stop`` -- when it stops: ``alert`` (a maneuvering pilot when its alert clears; a
  ``detection`` pilot's "hold" runs to the end of the encounter) or ``safe-avoidance`` (the
  paper's "The model captures pilot response from the beginning of an encounter till safe
  avoidance": the stream ends when the pilot's display shows no alert and every intruder past its
  closest point of approach, :mod:`daa_sil.models.pilot`);
* ``hold_commands`` -- the GCS streams "hold" as a pilot command until the pilot's first maneuver
  (true) or sends only maneuvers (false);
* ``unsafe_hold`` -- what the agent does with a fresh "hold" (a command without a maneuver intent)
  that is unsafe: ``blend`` (Algorithm 1 as for any command) or ``no-command`` (as if no command
  had arrived: the agent decides wait / no wait);
* ``waitmap`` -- the wait maps' grid: ``paper`` (the simulation-parameters paragraph's ranges and
  bins) or unset (the campaign's ``--waitmap``, default ``alerting``, our extension);
* ``outside`` -- the wait read for a state outside the map's box: ``clamp`` (the nearest state of
  the box: "the agent matches the current state with a state in the wait map") or ``far`` (the map
  does not model that intruder: w = H; ProjL still vetoes);
* ``latency`` -- :data:`daa_sil.models.latency.LATENCY_RULES`: ``one-way`` (a group's value on each
  link) or ``round-trip`` (the group's value is the round trip, split evenly between the links);
* ``wait_rule`` -- unset (each group's, ``threshold``: Eq. "W(k)" every step) or ``countdown``
  (the wait read from the map is a budget counted from the start of a wait, :mod:`daa_sil.agent`);
* ``agent_active`` -- when the agent decides: from the ``corrective`` alert (its active phase) or over
  the whole ``encounter``, from its start until safe avoidance (:data:`daa_sil.config.choices.AGENT_ACTIVE`).

Settings that change only the **counting** (the report recounts the same results):

* ``window`` -- ``active`` (the agent's active phase) or ``whole`` (the whole encounter);
* ``received`` -- ``arrived`` (every fresh command that reached the vehicle), ``pilot+blend`` (the
  paper's arithmetic: the pilot-command-reception table equals the command-execution table's
  "Pilot" column, plus "Blending" in the integrated groups) or ``executed`` (executed as sent);
* ``blends`` -- ``all`` blends, or ``maneuvers`` only (blends of a command carrying a maneuver
  intent; a blended "hold" is then counted in no column).

Old names stay accepted (:data:`ALIASES`): ``literal`` is ``extended`` and gives exactly the results
it gave under its old name.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

from daa_sil.config.choices import OUTSIDE_BOX as OUTSIDE
from daa_sil.config.choices import AGENT_ACTIVE, PILOT_STOPS, UNSAFE_HOLDS, WAIT_RULES
from daa_sil.errors import UsageError
from daa_sil.geometry.units import FT
from daa_sil.models.link_rule import LATENCY_RULES as LATENCIES

UNITS = ("metres", "feet")
PILOT_STARTS = ("corrective", "preventive", "detection")
WINDOWS = ("active", "whole")
RECEIVED = ("arrived", "pilot+blend", "executed")
BLENDS = ("all", "maneuvers")
#: the reading a campaign runs when none is named
DEFAULT_READING = "paper"
#: old reading names -> their current names (accepted with a one-line notice)
ALIASES = {"literal": "extended"}


@dataclass(frozen=True)
class Reading:
    """One reading of the paper's simulator (see the module docstring)."""

    name: str = "extended"
    units: str = "metres"
    pilot_start: str = "corrective"
    pilot_engage: "str | None" = None
    pilot_stop: str = "alert"
    hold_commands: bool = True
    unsafe_hold: str = "blend"
    waitmap: "str | None" = None
    outside: str = "clamp"
    latency: str = "one-way"
    wait_rule: "str | None" = None
    agent_active: str = "corrective"
    window: str = "active"
    received: str = "arrived"
    blends: str = "all"
    description: str = ""

    def __post_init__(self):
        for key, allowed in (("units", UNITS), ("pilot_start", PILOT_STARTS), ("pilot_stop", PILOT_STOPS),
                             ("unsafe_hold", UNSAFE_HOLDS), ("outside", OUTSIDE), ("latency", LATENCIES),
                             ("window", WINDOWS), ("received", RECEIVED), ("blends", BLENDS),
                             ("agent_active", AGENT_ACTIVE)):
            if getattr(self, key) not in allowed:
                raise UsageError(f"reading {self.name}: {key} must be one of {', '.join(allowed)}, "
                                 f"got {getattr(self, key)!r}")
        if self.pilot_engage is not None and self.pilot_engage not in ("corrective", "preventive"):
            raise UsageError(f"reading {self.name}: pilot_engage must be corrective or preventive, "
                             f"got {self.pilot_engage!r}")
        if self.wait_rule is not None and self.wait_rule not in WAIT_RULES:
            raise UsageError(f"reading {self.name}: wait_rule must be one of {', '.join(WAIT_RULES)}, "
                             f"got {self.wait_rule!r}")
        if not isinstance(self.hold_commands, bool):
            raise UsageError(f"reading {self.name}: hold_commands must be true or false, got {self.hold_commands!r}")

    # --- what the reading changes in the simulation ---------------------------------------------
    def encounter_overrides(self) -> dict:
        """:class:`daa_sil.models.encounters.EncounterConfig` fields (HMD / VMD ranges, m)."""
        if self.units == "feet":
            return {"hmd_max_m": 2750.0 * FT, "vmd_max_m": 915.0 * FT}
        return {}

    def pilot_config(self, base=None):
        """The :class:`daa_sil.models.pilot_config.PilotConfig` of this reading (from ``base``, default PilotConfig())."""
        from daa_sil.models.pilot_config import PilotConfig

        base = base if base is not None else PilotConfig()
        engage = self.pilot_engage or ("preventive" if self.pilot_start == "preventive" else "corrective")
        level = 1 if engage == "preventive" else 2
        stream = 0 if self.pilot_start == "detection" else None
        return replace(base, alert_level_min=level, stream_level_min=stream, stream_hold=self.hold_commands,
                       stream_until=self.pilot_stop)

    def policy_overrides(self) -> dict:
        """:class:`daa_sil.agent.AllocationPolicy` fields this reading sets (for groups that wait)."""
        out = {"unsafe_hold": self.unsafe_hold} if self.unsafe_hold != "blend" else {}
        if self.agent_active != "corrective":
            out["active_from"] = self.agent_active
        if self.wait_rule is not None:
            out["wait_rule"] = self.wait_rule
        return out

    def simulation_key(self) -> tuple:
        """The settings that change what is simulated (two readings with the same key share results)."""
        return (self.units, self.pilot_start, self.pilot_engage, self.pilot_stop, self.hold_commands,
                self.unsafe_hold, self.waitmap, self.outside, self.latency, self.wait_rule, self.agent_active)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "Reading":
        known = {f.name for f in fields(cls)}
        bad = set(d) - known
        if bad:
            raise UsageError(f"unknown reading setting {sorted(bad)[0]!r}; allowed: {', '.join(sorted(known - {'name'}))}")
        return cls(**d)


_PAPER = dict(waitmap="paper", latency="round-trip", pilot_start="detection", pilot_stop="safe-avoidance",
              unsafe_hold="no-command", agent_active="encounter", window="whole", received="pilot+blend")

#: named bundles, ``paper`` first (the default), then its alternatives, then the older readings
READINGS: dict[str, Reading] = {r.name: r for r in (
    Reading("paper", **_PAPER,
            description="the paper's method: paper grid, round trip split between the links, pilot streams and agent "
                        "decides from the start till safe avoidance, unsafe 'hold' = no command, received = pilot + blend"),
    Reading("paper-outside-far", **{**_PAPER, "outside": "far"},
            description="as paper, but a state outside the map's box reads w = H (ProjL still vetoes)"),
    Reading("paper-one-way", **{**_PAPER, "latency": "one-way"},
            description="as paper, but each group's delay applied one-way on both links (doubles the round trip)"),
    Reading("paper-countdown", **{**_PAPER, "wait_rule": "countdown"},
            description="as paper, but the wait read from the map is a budget counted down from the start of a wait"),
    Reading("paper-hold-blend", **{**_PAPER, "unsafe_hold": "blend", "blends": "maneuvers"},
            description="as paper, but an unsafe 'hold' is blended like any command and blends are counted "
                        "over maneuvers only"),
    Reading("paper-no-hold", **{**_PAPER, "hold_commands": False},
            description="as paper, but the GCS sends no 'hold' (only the pilot's maneuvers)"),
    Reading("paper-preventive", **{**_PAPER, "pilot_engage": "preventive"},
            description="as paper, but the pilot maneuvers from the preventive alert"),
    Reading("paper-corrective", **{**_PAPER, "agent_active": "corrective"},
            description="as paper, but the agent decides only from the corrective alert (its active phase) on"),
    Reading("paper-alerting", **{**_PAPER, "waitmap": None},
            description="as paper, on our alerting-region wait-map grid (the campaign's --waitmap, default alerting)"),
    Reading("paper-feet", **{**_PAPER, "units": "feet"},
            description="as paper, HMD/VMD ranges in feet (contradicts the table's metres; measures the unit alone)"),
    Reading("extended",
            description="our extension (formerly 'literal'): alerting grid, one-way delays, pilot streams from the "
                        "corrective alert; counted over the active phase, every arrival"),
    Reading("paper-counts", window="whole", received="pilot+blend",
            description="as extended, counted like the paper: whole encounter, received = pilot + blend"),
    Reading("preventive", pilot_start="preventive", window="whole", received="pilot+blend",
            description="as extended, the pilot from the preventive alert; paper counting"),
    Reading("feet", units="feet", pilot_start="preventive", window="whole", received="pilot+blend",
            description="as preventive, HMD/VMD in feet (against preventive: the unit alone)"),
    Reading("detection", pilot_start="detection", window="whole", received="pilot+blend",
            description="as extended, 'hold' from the first telemetry to the end, maneuvers from the corrective "
                        "alert; paper counting"),
    Reading("no-hold", hold_commands=False,
            description="as extended, but the GCS sends only the pilot's maneuvers, no 'hold'"),
    Reading("paper-grid", waitmap="paper",
            description="as extended, on the paper's +-1,500 m wait-map grid (nearest point of the box outside)"),
)}


def canonical_name(name: str) -> "tuple[str, str | None]":
    """``(current name, notice or None)`` of a reading name; unknown names raise UsageError."""
    key = str(name).strip()
    if key in ALIASES:
        new = ALIASES[key]
        return new, f"reading '{key}' is now called '{new}' (same settings, same results)"
    if key not in READINGS:
        raise UsageError(f"unknown reading {name!r}; allowed: {', '.join(READINGS)} (or the old name "
                         f"{', '.join(ALIASES)})")
    return key, None


def reading_for(name: str = DEFAULT_READING, **overrides) -> Reading:
    """A named reading (old names accepted) with optional setting overrides (``units="feet"``, ...)."""
    r = READINGS[canonical_name(name)[0]]
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
        elif key in ("waitmap", "wait_rule") and val.lower() in ("", "none", "default"):
            out[key] = None
        else:
            out[key] = val
    return out


def readings_help() -> str:
    """One line per reading: its name and what it is (``campaign run --help``)."""
    return "\n".join(f"  {r.name:18s} {r.description}" for r in READINGS.values()) + "\n" + "\n".join(
        f"  {old:18s} old name of '{new}' (accepted, with a notice)" for old, new in ALIASES.items())


__all__ = ["Reading", "READINGS", "ALIASES", "DEFAULT_READING", "reading_for", "canonical_name",
           "parse_reading_settings", "readings_help", "UNITS", "PILOT_STARTS", "PILOT_STOPS", "UNSAFE_HOLDS", "AGENT_ACTIVE",
           "OUTSIDE", "LATENCIES", "WAIT_RULES", "WINDOWS", "RECEIVED", "BLENDS"]
