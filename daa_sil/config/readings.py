"""Named readings of the paper's simulator (Tabassum & Bai): every setting the text fixes, infers
or leaves open, as data.

A :class:`Reading` is a small bundle of explicit settings; it is recorded in ``campaign.json``
(``config.reading``, ``config.readings`` and, for every setting, its basis: ``basis``, from
:mod:`daa_sil.config.basis`, the one definition the study page prints too). The report shows
readings side by side. This docstring names the settings; :mod:`daa_sil.config.basis` says what each
value of the ``paper`` reading rests on.

Settings that change the **simulation** (one campaign each):

* ``units`` -- the HMD / VMD ranges of the paper's table "Intruder Parameters for Trajectory
  Generation" (0-2,750 and +-915), labelled ``HMD (m)`` and ``VMD (m)`` there: ``metres`` (the
  text) or ``feet`` (838 m and 279 m: every CPA then lies inside the horizontal well-clear
  distance). ``feet`` contradicts the table's labels; it is kept to measure what the unit does;
* ``pilot_start`` -- when the pilot model streams: ``corrective`` (from the corrective alert, the
  agent's active phase), ``preventive`` (from the first, preventive alert: it also maneuvers from
  then) or ``detection`` ("hold" from the first telemetry, maneuvering from the corrective alert);
* ``pilot_engage`` -- the alert level from which the pilot maneuvers: unset (``preventive`` for the
  ``preventive`` start, else ``corrective``), ``corrective`` / ``preventive``, or ``never`` (the
  pilot never maneuvers: with ``hold_commands`` false it sends nothing; the unmitigated experiment);
* ``pilot_stop`` -- when it stops: ``alert`` (a maneuvering pilot when its alert clears; a
  ``detection`` pilot's "hold" runs to the end of the encounter) or ``safe-avoidance`` (the
  paper's "The model captures pilot response from the beginning of an encounter till safe
  avoidance": the stream ends when the pilot's display shows no alert and every intruder past its
  closest point of approach, :mod:`daa_sil.models.pilot`);
* ``hold_commands`` -- the GCS streams "hold" as a pilot command until the pilot's first maneuver
  (true) or sends only maneuvers (false);
* ``unsafe_hold`` -- what the agent does with a fresh "hold" (a command without a maneuver intent)
  that is unsafe: ``blend`` (Algorithm 1 as for any command: blended in the integrated groups,
  overridden in the baselines) or ``no-command`` (as if no command had arrived: the agent decides
  wait / no wait);
* ``waitmap`` -- the wait maps' grid: ``paper`` (the simulation-parameters paragraph's ranges and
  bins) or unset (the campaign's ``--waitmap``, default ``alerting``, our extension);
* ``wait_horizon_s`` -- the wait maps' horizon H (s), the largest wait a map holds: unset (the map
  preset's: 60 s for ``paper``) or a number (40 s: "The maximum wait time is 40 seconds");
* ``outside`` -- the wait read for a state outside the map's box
  (:data:`daa_sil.config.choices.OUTSIDE_BOX`): ``clamp`` (the nearest state of the box), ``far``
  (w = H) or ``approach`` (the straight-line time to enter the box plus the wait at the entry
  point, at most H);
* ``latency`` -- :data:`daa_sil.models.latency.LATENCY_RULES`: ``one-way`` (a group's value on each
  link) or ``round-trip`` (the group's value is the round trip, split evenly between the links);
* ``delay_draw`` -- a Gaussian (any drawn) delay is redrawn every delay epoch (``epoch``, 10 s) or
  drawn once per encounter (``encounter``);
* ``wait_rule`` -- unset (each group's, ``threshold``: Eq. "W(k)" every step) or ``countdown``
  (the wait read from the map is a budget counted from the start of a wait, :mod:`daa_sil.agent.step`);
* ``agent_active`` -- when the agent decides: from the ``corrective`` alert (its active phase) or over
  the whole ``encounter``, from its start until safe avoidance (:data:`daa_sil.config.choices.AGENT_ACTIVE`);
* ``daa_authority`` -- ``per-step`` (Algorithm 1 every step) or ``until-clear`` (our extension: the
  DAA keeps an authority it holds, on steps without a fresh command, until no alert is raised).

Settings that change only the **counting** (the report recounts the same results):

* ``window`` -- ``active`` (the agent's active phase) or ``whole`` (the whole encounter);
* ``received`` -- ``arrived`` (every fresh command that reached the vehicle), ``pilot+blend`` (the
  paper's arithmetic: the pilot-command-reception table equals the command-execution table's
  "Pilot" column, plus "Blending" in the integrated groups) or ``executed`` (executed as sent);
* ``blends`` -- ``all`` blends, or ``maneuvers`` only (blends of a command carrying a maneuver
  intent; a blended "hold" is then counted in no column);
* ``superseded`` -- a command the link releases in the same step as a newer one (a FIFO burst after
  the delay drops): ``dropped`` (only the newest counts) or ``fate`` (every released command counts,
  an older one with the fate of the newest: executed as sent, blended or overridden with it).

Old names stay accepted (:data:`ALIASES`): ``literal`` is ``extended`` and gives exactly the results
it gave under its old name.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

from daa_sil.config.choices import OUTSIDE_BOX as OUTSIDE
from daa_sil.config.choices import AGENT_ACTIVE, DAA_AUTHORITY, DELAY_DRAWS, PILOT_STOPS, UNSAFE_HOLDS, WAIT_RULES
from daa_sil.errors import UsageError
from daa_sil.geometry.units import FT
from daa_sil.models.link_rule import LATENCY_RULES as LATENCIES

UNITS = ("metres", "feet")
PILOT_STARTS = ("corrective", "preventive", "detection")
WINDOWS = ("active", "whole")
RECEIVED = ("arrived", "pilot+blend", "executed")
BLENDS = ("all", "maneuvers")
SUPERSEDED = ("dropped", "fate")
PILOT_ENGAGES = ("corrective", "preventive", "never")
#: the reading a campaign runs when none is named
DEFAULT_READING = "paper"
#: the reading a campaign.json that records none flew: campaigns were written before readings were
#: recorded only under the simulator's first reading, called ``extended`` now
LEGACY_READING = "extended"
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
    wait_horizon_s: "float | None" = None
    outside: str = "clamp"
    latency: str = "one-way"
    delay_draw: str = "epoch"
    wait_rule: "str | None" = None
    agent_active: str = "corrective"
    daa_authority: str = "per-step"
    window: str = "active"
    received: str = "arrived"
    blends: str = "all"
    superseded: str = "dropped"
    description: str = ""

    def __post_init__(self):
        for key, allowed in (("units", UNITS), ("pilot_start", PILOT_STARTS), ("pilot_stop", PILOT_STOPS),
                             ("unsafe_hold", UNSAFE_HOLDS), ("outside", OUTSIDE), ("latency", LATENCIES),
                             ("window", WINDOWS), ("received", RECEIVED), ("blends", BLENDS),
                             ("agent_active", AGENT_ACTIVE), ("delay_draw", DELAY_DRAWS),
                             ("daa_authority", DAA_AUTHORITY), ("superseded", SUPERSEDED)):
            if getattr(self, key) not in allowed:
                raise UsageError(f"reading {self.name}: {key} must be one of {', '.join(allowed)}, "
                                 f"got {getattr(self, key)!r}")
        if self.pilot_engage is not None and self.pilot_engage not in PILOT_ENGAGES:
            raise UsageError(f"reading {self.name}: pilot_engage must be one of {', '.join(PILOT_ENGAGES)}, "
                             f"got {self.pilot_engage!r}")
        if self.wait_horizon_s is not None:
            h = self.wait_horizon_s
            if isinstance(h, bool) or not isinstance(h, (int, float)) or not 1.0 <= float(h) <= 600.0:
                raise UsageError(f"reading {self.name}: wait_horizon_s must be a number of seconds within [1, 600] "
                                 f"(or unset), got {h!r}")
            object.__setattr__(self, "wait_horizon_s", float(h))
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
        from daa_sil.models.pilot_config import PilotConfig  # lazy: start-up time

        base = base if base is not None else PilotConfig()
        engage = self.pilot_engage or ("preventive" if self.pilot_start == "preventive" else "corrective")
        level = {"preventive": 1, "corrective": 2, "never": NEVER_LEVEL}[engage]
        stream = 0 if self.pilot_start == "detection" else None
        return replace(base, alert_level_min=level, stream_level_min=stream, stream_hold=self.hold_commands,
                       stream_until=self.pilot_stop)

    def policy_overrides(self) -> dict:
        """:class:`daa_sil.agent.step.AllocationPolicy` fields this reading sets (for groups that wait)."""
        out = {"unsafe_hold": self.unsafe_hold} if self.unsafe_hold != "blend" else {}
        if self.agent_active != "corrective":
            out["active_from"] = self.agent_active
        if self.wait_rule is not None:
            out["wait_rule"] = self.wait_rule
        if self.daa_authority != "per-step":
            out["daa_authority"] = self.daa_authority
        return out

    def epoch_s(self, epoch_s: float, duration_s: float, dt_s: float) -> float:
        """The delay epoch (s) a campaign's links use: ``epoch_s`` (the link's), or, with
        ``delay_draw = "encounter"``, one epoch longer than the encounter (one draw: the first draw
        of the same stream, so the two readings pair encounter by encounter)."""
        return float(epoch_s) if self.delay_draw == "epoch" else float(duration_s) + 2.0 * float(dt_s)

    def simulation_key(self) -> tuple:
        """The settings that change what is simulated (two readings with the same key share results)."""
        key = (self.units, self.pilot_start, self.pilot_engage, self.pilot_stop, self.hold_commands,
               self.unsafe_hold, self.waitmap, self.outside, self.latency, self.wait_rule, self.agent_active)
        extra = tuple((k, getattr(self, k)) for k, default in _NEW_SIMULATION_SETTINGS if getattr(self, k) != default)
        return key + extra if extra else key

    def to_dict(self) -> dict:
        return asdict(self)

    def counting(self) -> dict:
        """The counting settings (``window``, ``received``, ``blends``, ``superseded``)."""
        return {k: getattr(self, k) for k in COUNTING_KEYS}

    @classmethod
    def from_dict(cls, d: dict) -> "Reading":
        known = {f.name for f in fields(cls)}
        bad = set(d) - known
        if bad:
            raise UsageError(f"unknown reading setting {sorted(bad)[0]!r}; allowed: {', '.join(sorted(known - {'name'}))}")
        return cls(**d)


#: a pilot alert level no DAA alert reaches (``pilot_engage = "never"``: the pilot never maneuvers)
NEVER_LEVEL = 9
#: the counting settings of a reading (the rest change the simulation)
COUNTING_KEYS = ("window", "received", "blends", "superseded")
#: simulation settings added after the first readings, with the value that leaves a reading's results as
#: they were: a reading at these values keeps its old simulation key (and its results)
_NEW_SIMULATION_SETTINGS = (("wait_horizon_s", None), ("delay_draw", "epoch"), ("daa_authority", "per-step"))

#: the paper reading's settings; :mod:`daa_sil.config.basis` gives each its basis
_PAPER = dict(waitmap="paper", wait_horizon_s=40.0, latency="round-trip", pilot_start="detection",
              pilot_stop="safe-avoidance", unsafe_hold="blend", outside="approach", agent_active="encounter",
              window="whole", received="pilot+blend", superseded="fate")
#: the settings of ``paper`` that the text contradicts or that lose commands, as they are in
#: ``paper-contradicted`` (each also alone, in its own reading)
_CONTRADICTED = dict(outside="clamp", unsafe_hold="no-command", wait_horizon_s=None, superseded="dropped")

#: named bundles, ``paper`` first (the default), then its alternatives, then the older readings
READINGS: dict[str, Reading] = {r.name: r for r in (
    Reading("paper", **_PAPER,
            description="the paper's method: paper grid with H = 40 s, outside the box the time to reach it plus "
                        "the wait there, round trip split between the links, pilot streams and agent decides from "
                        "the start till safe avoidance, an unsafe command (a 'hold' too) blended or overridden, "
                        "received = pilot + blend counting every released command"),
    Reading("paper-outside-far", **{**_PAPER, "outside": "far"},
            description="as paper, but a state outside the map's box reads w = H (ProjL still vetoes)"),
    Reading("paper-clamp", **{**_PAPER, "outside": "clamp"},
            description="as paper, but a state outside the map's box reads the nearest state of the box (the wait "
                        "then stops decreasing as the intruder approaches: against the text)"),
    Reading("paper-hold-none", **{**_PAPER, "unsafe_hold": "no-command"},
            description="as paper, but an unsafe 'hold' counts as no command (wait / no wait): against Algorithm 1"),
    Reading("paper-h60", **{**_PAPER, "wait_horizon_s": None},
            description="as paper, but the maps' horizon H = 60 s (a 60 s maximum wait: against the text's 40 s)"),
    Reading("paper-one-per-step", **{**_PAPER, "superseded": "dropped"},
            description="as paper, but a command superseded by a newer one in the same step is not counted"),
    Reading("paper-contradicted", **{**_PAPER, **_CONTRADICTED},
            description="as paper with the four settings above at their contradicted values together: clamp, an "
                        "unsafe 'hold' as no command, H = 60 s, one command counted per step"),
    Reading("paper-delay-per-encounter", **{**_PAPER, "delay_draw": "encounter"},
            description="as paper, but a Gaussian delay drawn once per encounter (constant over it: against "
                        "'the time varying latency groups')"),
    Reading("paper-keep-daa", **{**_PAPER, "daa_authority": "until-clear"},
            description="our extension of paper: the DAA, once in authority, keeps it on steps without a fresh "
                        "command until no alert is raised"),
    Reading("paper-one-way", **{**_PAPER, "latency": "one-way"},
            description="as paper, but each group's delay applied one-way on both links (doubles the round trip)"),
    Reading("paper-countdown", **{**_PAPER, "wait_rule": "countdown"},
            description="as paper, but the wait read from the map is a budget counted down from the start of a wait"),
    Reading("paper-hold-blend", **{**_PAPER, "blends": "maneuvers"},
            description="as paper, counting blends over maneuvers only (a blended 'hold' counts in no column)"),
    Reading("paper-no-hold", **{**_PAPER, "hold_commands": False},
            description="as paper, but the GCS sends no 'hold' (only the pilot's maneuvers)"),
    Reading("paper-preventive", **{**_PAPER, "pilot_engage": "preventive"},
            description="as paper, but the pilot maneuvers from the preventive alert"),
    Reading("paper-corrective", **{**_PAPER, "agent_active": "corrective"},
            description="as paper, but the agent decides only from the corrective alert (its active phase) on"),
    Reading("paper-alerting", **{**_PAPER, "waitmap": None, "wait_horizon_s": None},
            description="as paper, on our alerting-region wait-map grid (the campaign's --waitmap, default "
                        "alerting, its own horizon)"),
    Reading("paper-feet", **{**_PAPER, "units": "feet"},
            description="as paper, HMD/VMD ranges in feet (contradicts the table's metres; measures the unit alone)"),
    Reading("extended",
            description="our extension: alerting grid, one-way delays, pilot streams from the "
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
        elif key in ("waitmap", "wait_rule", "pilot_engage", "wait_horizon_s") and val.lower() in ("", "none", "default"):
            out[key] = None
        elif key == "wait_horizon_s":
            try:
                out[key] = float(val)
            except ValueError:
                raise UsageError(f"--reading-set wait_horizon_s must be a number of seconds, got {val!r}") from None
        else:
            out[key] = val
    return out


def readings_help() -> str:
    """One line per reading: its name and what it is (``campaign run --help``)."""
    return "\n".join(f"  {r.name:26s} {r.description}" for r in READINGS.values()) + "\n" + "\n".join(
        f"  {old:26s} old name of '{new}' (accepted, with a notice)" for old, new in ALIASES.items())


__all__ = ["Reading", "READINGS", "ALIASES", "DEFAULT_READING", "LEGACY_READING", "reading_for", "canonical_name",
           "parse_reading_settings", "readings_help", "UNITS", "PILOT_STARTS", "PILOT_STOPS", "UNSAFE_HOLDS", "AGENT_ACTIVE",
           "OUTSIDE", "LATENCIES", "WAIT_RULES", "WINDOWS", "RECEIVED", "BLENDS", "SUPERSEDED", "PILOT_ENGAGES",
           "DAA_AUTHORITY", "DELAY_DRAWS", "COUNTING_KEYS", "NEVER_LEVEL"]
