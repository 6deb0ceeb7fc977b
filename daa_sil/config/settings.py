"""Every setting that more than one input reads, defined once: its default, its allowed range, its
unit, its help, and where a user sets it (command-line flag, YAML key and old keys, MAVLink
parameter).

A :class:`Setting` is a value, not a parser. The inputs read it:

* a dataclass field takes its default from it (:meth:`Setting.field`, which also records the
  setting in the field's metadata, so ``config show --full`` and the docs can list it);
* a command-line flag takes its name, range and help (:attr:`Setting.flag`, :meth:`Setting.flag_help`);
* a YAML key (scenario, group file, run configuration) and a MAVLink parameter check the same range
  (:meth:`Setting.check`, :meth:`Setting.contains`).

A **per-group** setting (``per_group=True``: W_T, ProjL N, the constant wait, the link timeouts) is a
field of the agent's :class:`~daa_sil.config.policy.AllocationPolicy`; registering one
(:func:`register`) is all it takes for it to be a policy field, a group-file key, a run
configuration key, a scenario key, a flag of the commands that fly groups and a MAVLink parameter
(:mod:`daa_sil.config.overrides` reads the registry for each of them).

This module imports nothing of ours but :mod:`daa_sil.errors`, so any layer may read it.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from typing import Any

from daa_sil.errors import UsageError


@dataclass(frozen=True)
class Setting:
    """One setting: ``name`` (the field / YAML key), ``default``, the closed range ``[lo, hi]`` in
    ``unit`` (None = not a number), and a one-sentence ``help``."""

    name: str
    default: Any
    unit: str = ""
    lo: "float | None" = None
    hi: "float | None" = None
    help: str = ""
    #: the command-line flag that sets it (``--wt``), None = none
    flag: "str | None" = None
    #: old YAML keys still read, each with a one-line notice (``wt`` for ``wait_threshold_s``)
    aliases: tuple = ()
    #: old command-line flags still read, each with a one-line notice
    old_flags: tuple = ()
    #: the vehicle's MAVLink parameter (<= 16 characters), None = none
    mavlink: "str | None" = None
    #: False: the MAVLink parameter is reported, a PARAM_SET of it refused
    writable: bool = True
    #: the run-configuration section it sits in (``allocation``, ``link``, ``study``, ...)
    section: str = ""
    #: a field of the agent's AllocationPolicy, set per group (see the module docstring)
    per_group: bool = False
    #: which groups a run-wide value (flag, run configuration) changes: ``all``, ``waiting`` (a group
    #: with a wait function) or ``constant`` (a group with the constant wait function)
    applies: str = "all"

    @property
    def keys(self) -> tuple:
        """Every YAML key it is read under: its name, then the old ones."""
        return (self.name, *self.aliases)

    @property
    def range(self) -> tuple[float, float]:
        """``(lo, hi)``, both inclusive."""
        if self.lo is None or self.hi is None:
            raise TypeError(f"setting {self.name} has no numeric range")
        return (self.lo, self.hi) if self.integer else (float(self.lo), float(self.hi))

    def contains(self, value: Any) -> bool:
        """True when ``value`` is a finite number (not a bool) within the range (a whole one for a count)."""
        lo, hi = self.range
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            return False
        try:  # an int too large for a float (10**400 in a YAML file) is out of every range
            ok = math.isfinite(value) and lo <= value <= hi
            return ok and (not self.integer or float(value).is_integer())
        except OverflowError:
            return False

    def check(self, value: Any, where: str = "", key: "str | None" = None) -> float:
        """``value`` as a float, or a one-line :class:`UsageError` naming ``where`` and ``key``."""
        if not self.contains(value):
            at = f"{where}: " if where else ""
            lo, hi = self.range
            kind = "an integer" if self.integer else "a number"
            raise UsageError(f"{at}{key or self.name} must be {kind} within [{self.shown(lo)}, {self.shown(hi)}], "
                             f"got {value!r}")
        return int(value) if self.integer else float(value)

    def shown(self, x: float) -> str:
        """A bound as people read it: ``10,000,000`` for a count, ``120`` or ``1e-06`` for a number."""
        return f"{int(x):,}" if self.integer else f"{x:g}"

    def field(self, **kw) -> Any:
        """A dataclass field with this default, the setting in its metadata (``metadata["setting"]``)."""
        return dataclasses.field(default=self.default, metadata={"setting": self}, **kw)

    def override_field(self) -> Any:
        """A dataclass field that overrides this setting: default None (keep each group's), the
        setting (its range, help) in the metadata."""
        return dataclasses.field(default=None, metadata={"setting": self})

    @property
    def integer(self) -> bool:
        """True for a count (the default is an int)."""
        return isinstance(self.default, int) and not isinstance(self.default, bool)

    def flag_help(self, what: str = "") -> str:
        """Help text of a command-line flag: the help (or ``what``), unit, range and default."""
        unit = f", {self.unit}" if self.unit else ""
        rng = f" within [{self.shown(self.lo)}, {self.shown(self.hi)}]" if self.lo is not None and self.hi is not None else ""
        return f"{what or self.help}{unit}{rng} (default {self.default})"


#: W_T, the wait threshold of paper Eq. 11. 120 s loses nothing: the largest W_T the study sweeps is
#: 16 s, and no map value exceeds its horizon (60 s for the paper grid, 120 s for the alerting grid),
#: so a larger W_T could never be met and would mean "never wait".
WAIT_THRESHOLD = Setting("wait_threshold_s", 4.0, "s", 0.0, 120.0,
                         "W_T: the agent waits only while the wait function w(S) >= W_T", flag="--wt",
                         aliases=("wt",), mavlink="DAA_WT", section="allocation", per_group=True, applies="waiting")
#: N, the ProjL look-ahead: 25 s is the DO-365 warning alerting time, a LoWC predicted that soon leaves
#: no time to wait for a command delayed by up to 10 s plus a 5-10 s maneuver
PROJL_HORIZON = Setting("projl_horizon_s", 25.0, "s", 0.0, 120.0,
                        "ProjL look-ahead N: no wait while a LoWC is projected within N", flag="--projl-horizon",
                        aliases=("projl_lookahead",), old_flags=("--projl-lookahead",), mavlink="DAA_PROJL_S",
                        section="allocation", per_group=True)
#: the wait of the ``constant`` wait function (IC-1); capped like W_T, above which it means "always"
CONSTANT_WAIT = Setting("constant_wait_s", 5.0, "s", 0.0, 120.0, "the constant wait function's value w",
                        flag="--constant-wait", aliases=("wait_constant_s",), mavlink="DAA_WAIT_CONST", writable=False,
                        section="allocation", per_group=True, applies="constant")
#: the agent's stale-command limit and link-lost timeout (by a command's send time / the last packet).
#: At least one sim step: the GCS sends at most once per step, so a shorter link timeout declares
#: the link lost between any two packets, and a shorter stale limit makes every command stale.
STALE_COMMAND = Setting("stale_command_s", 15.0, "s", 1.0, 120.0, "a pilot command older than this is never flown",
                        flag="--stale-command", mavlink="DAA_STALE_S", section="link", per_group=True)
LINK_TIMEOUT = Setting("link_timeout_s", 20.0, "s", 1.0, 120.0, "no packet from the GCS for this long: link lost",
                       flag="--link-timeout", mavlink="DAA_LINK_TO", section="link", per_group=True)
#: a link delay process keeps one drawn delay for an epoch (0 = a draw per datagram)
DELAY_EPOCH = Setting("epoch_s", 10.0, "s", 0.0, 600.0, "delay epoch: one drawn delay holds this long (0 = per datagram)")
#: the encounter length T (paper Sec. IV); the closest point of approach is at T/2
DURATION = Setting("duration_s", 240.0, "s", 1.0, 3600.0, "encounter length T (CPA at T/2)")
#: a campaign's size and seeds (``study`` section, ``campaign run`` flags)
ENCOUNTERS = Setting("encounters", 10_000, "", 1, 10_000_000, "encounters per group")
SEED = Setting("seed", 0, "", 0, 2**63 - 1, "campaign seed (every encounter's streams derive from it)")
INTRUDERS = Setting("intruders", 1, "", 1, 8, "intruders per encounter")
#: encounters per task: the per-step numpy overhead is paid once per chunk, so bigger chunks are
#: faster (500 -> 2000 about 1.9x per core); one 2000-encounter chunk peaks at about 0.2 GB RSS
CHUNK_SIZE = Setting("chunk_size", 2000, "", 1, 10_000_000, "encounters per chunk (one result file per group and chunk)")
#: encounter rows per task of a campaign (several chunks of several groups side by side): peak memory
#: grows with them (:mod:`daa_sil.study.campaign.plan`); results do not depend on them
BATCH_ROWS = Setting("batch_rows", 10_000, "", 1, 10_000_000, "encounter rows per task (results do not depend on it)")
#: worker processes (campaign, wait-map build): at most this many per usable core. More only adds
#: processes that wait for a core and memory (one worker holds 0.3-1 GB), and on 2 cores 1,000
#: workers (1,049 processes) ended in a broken process pool
WORKERS_PER_CORE = 4
#: points on one axis of a wait-map grid (a grid file or an inline spec): 1,000 is 80 times the
#: paper's 12; the grid's product of axes is bounded by the memory estimate of the build
GRID_AXIS_POINTS = Setting("n", 12, "", 2, 1000, "points on one wait-map grid axis")
#: bootstrap replicates of a report's confidence intervals (each is a weight vector over the encounters)
BOOTSTRAP_REPLICATES = Setting("replicates", 2000, "", 100, 100_000, "bootstrap replicates of every CI")
#: the wait maps the map groups read: a map preset (``alerting``: the box covers the DAA alerting
#: region, horizon 120 s), a grid spec or a ``waitmap build`` directory
WAITMAP = Setting("source", "alerting", help="wait maps of the map groups: a map preset, a grid spec or a directory")
#: the wait map's MDP discount (None = the map preset's)
GAMMA = Setting("gamma", None, "", 1e-6, 0.999999, "MDP discount of the wait maps (default: the map preset's)")
#: the well-clear threshold preset a run configuration and a campaign fly when none is named
PRESET = Setting("thresholds", "paper", help="well-clear threshold preset")
#: the standard's well-clear volume (DO-365): what a scenario file that names no preset flies, the
#: encounter model's default (``EncounterConfig``), and the default of ``daa-sil geometry`` and of
#: ``daa-sil viz steplog`` for a log that records none
STANDARD_PRESET = Setting("thresholds", "do365", help="well-clear threshold preset of a scenario and of 'geometry'")
#: a scenario's group when it names none, and its uplink delay when its link names none
SCENARIO_GROUP = Setting("group", "ID-1", help="the experiment group a scenario flies")
SCENARIO_LINK = Setting("up", "const:4", help="uplink delay spec (GCS -> vehicle)")
#: the simulation step dt: paper Sec. IV flies 1 s steps; fast-time, the lockstep SIL and the
#: vehicle's clock all step by it (a campaign records it as ``dt_s``; no input changes it today)
STEP = Setting("dt_s", 1.0, "s", help="simulation step dt")
#: the SIL's UDP ports on 127.0.0.1: the shim listens for the vehicle and for the GCS; the vehicle's
#: default output is the port ground stations listen on (QGroundControl, MAVProxy)
SHIM_VEHICLE_PORT = Setting("listen_vehicle", 14601, "", 0, 65535, "UDP port the shim listens on for the vehicle")
SHIM_GCS_PORT = Setting("listen_gcs", 14602, "", 0, 65535, "UDP port the shim listens on for the GCS")
GCS_PORT = Setting("out", 14550, "", 1, 65535, "UDP port of the vehicle's default output (a ground station's)")
#: the vehicle's MAVLink system id (the GCS's is 255, a ground station's usual one)
VEHICLE_SYSID = Setting("system_id", 1, "", 1, 255, "the vehicle's MAVLink system id")
#: the host every socket binds and sends to by default
LOOPBACK = "127.0.0.1"


def udp(port: "int | Setting", scheme: str = "udp") -> str:
    """``udp:127.0.0.1:PORT`` of a port (or a port setting's default)."""
    return f"{scheme}:{LOOPBACK}:{port.default if isinstance(port, Setting) else int(port)}"

#: every setting above by where it is set (the key ``config show --full`` lists it under)
ALL = {"allocation.wait_threshold_s": WAIT_THRESHOLD, "allocation.projl_horizon_s": PROJL_HORIZON,
       "allocation.constant_wait_s": CONSTANT_WAIT, "link.stale_command_s": STALE_COMMAND,
       "link.link_timeout_s": LINK_TIMEOUT, "link.epoch_s": DELAY_EPOCH, "waitmap.source": WAITMAP, "waitmap.gamma": GAMMA,
       "study.encounters": ENCOUNTERS, "study.seed": SEED, "study.duration_s": DURATION,
       "study.intruders": INTRUDERS, "study.chunk_size": CHUNK_SIZE,
       "thresholds": PRESET, "scenario.thresholds": STANDARD_PRESET, "scenario.allocation.group": SCENARIO_GROUP,
       "scenario.link.up": SCENARIO_LINK, "study.dt_s": STEP, "sil.listen_vehicle": SHIM_VEHICLE_PORT,
       "sil.listen_gcs": SHIM_GCS_PORT, "sil.out": GCS_PORT, "sil.system_id": VEHICLE_SYSID}


def register(setting: Setting) -> Setting:
    """Add a setting to :data:`ALL` under ``section.name`` (one line: an already used key or flag);
    a per-group one becomes a field of the AllocationPolicy and every input's key (module docstring).
    Register before :mod:`daa_sil.config.policy` is imported: the policy's fields are built then."""
    key = f"{setting.section}.{setting.name}" if setting.section else setting.name
    if key in ALL:
        raise UsageError(f"setting {key} is defined twice")
    taken = {f for s in ALL.values() for f in (s.flag, *s.old_flags) if f} | {s.mavlink for s in ALL.values() if s.mavlink}
    clash = [x for x in (setting.flag, *setting.old_flags, setting.mavlink) if x and x in taken]
    if clash:
        raise UsageError(f"setting {key}: {clash[0]} already names another setting")
    if setting.per_group and (setting.lo is None or setting.applies not in APPLIES):
        raise UsageError(f"setting {key}: a per-group setting needs a numeric range and applies in {APPLIES}")
    if setting.per_group and "daa_sil.config.policy" in sys.modules:  # its field would be missing: say so
        raise UsageError(f"setting {key}: register a per-group setting before daa_sil.config.policy is imported")
    ALL[key] = setting
    return setting


#: the ``applies`` values of a per-group setting
APPLIES = ("all", "waiting", "constant")


def group_settings() -> tuple:
    """The per-group settings, in registration order (the AllocationPolicy's order of them)."""
    return tuple(s for s in ALL.values() if s.per_group)


def describe() -> dict:
    """``{key: {default, unit, range, help}}`` of :data:`ALL` (``config show --full``)."""
    return {key: {"default": s.default, "unit": s.unit or None, "range": None if s.lo is None else [s.lo, s.hi],
                  "help": s.help, "flag": s.flag, "mavlink": s.mavlink} for key, s in ALL.items()}


__all__ = ["Setting", "WAIT_THRESHOLD", "PROJL_HORIZON", "CONSTANT_WAIT", "STALE_COMMAND", "LINK_TIMEOUT",
           "DELAY_EPOCH", "DURATION", "ENCOUNTERS", "SEED", "INTRUDERS", "CHUNK_SIZE", "BATCH_ROWS", "WORKERS_PER_CORE",
           "GRID_AXIS_POINTS", "BOOTSTRAP_REPLICATES", "WAITMAP", "GAMMA", "PRESET", "STANDARD_PRESET", "SCENARIO_GROUP", "SCENARIO_LINK", "ALL",
           "STEP", "SHIM_VEHICLE_PORT", "SHIM_GCS_PORT", "GCS_PORT", "VEHICLE_SYSID", "LOOPBACK", "udp", "register",
           "APPLIES", "group_settings", "describe"]
