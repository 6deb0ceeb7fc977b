"""The allocation agent's decision record (:class:`Decision`) and its integer codes.

One :func:`daa_sil.agent.step.agent_step` returns one :class:`Decision`: every field an array with a
leading encounter axis ``(N,)`` (``alert_level`` ``(N, M)``, the band fields ``(N, K)``). The record
is a read-only mapping too (``dec["decision"]``, ``dict(dec)``), so every reader that took the old
dict of the same keys reads it unchanged; :data:`DECISION_FIELDS` is derived from the fields, in
their order, which is the order of the columns and of the wire. Codes name their values through
:data:`CODE_NAMES`; :func:`decode` turns them into strings. Angles rad, times s, speeds m/s unless
the name says ``_deg``/``_dps``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from daa_sil.daa.config import AXIS_NAMES, DIR_NAMES, RULE_NAMES

DECISION_NAMES = ("none", "wait", "no_wait", "pilot", "blend", "daa_override", "daa", "stale", "link_lost")
(D_NONE, D_WAIT, D_NO_WAIT, D_PILOT, D_BLEND, D_DAA_OVERRIDE, D_DAA, D_STALE, D_LINK_LOST) = range(9)
#: ``kept``: the DAA kept the authority it held (policy ``daa_authority = "until-clear"``)
DECIDED_BY_NAMES = ("none", "map", "projl", "both", "neither", "kept")
BY_NONE, BY_MAP, BY_PROJL, BY_BOTH, BY_NEITHER, BY_KEPT = range(6)
AUTHORITY_NAMES = ("pilot", "daa", "waiting")
A_PILOT, A_DAA, A_WAITING = range(3)


@dataclass(eq=False)
class Decision(Mapping):
    """What the agent decided at one step, for N encounters (see the module docstring)."""

    active: np.ndarray  #: bool, the agent decides this step (corrective alert, wait/blend in progress, ...)
    decision: np.ndarray  #: int8, :data:`DECISION_NAMES` code
    rule: np.ndarray  #: int8, the blend's rule (:data:`daa_sil.daa.config.RULE_NAMES`), 0 when no blend
    authority: np.ndarray  #: int8, :data:`AUTHORITY_NAMES` code
    wait_s: np.ndarray  #: the wait function's w (s; a countdown's remainder), nan when not read
    projl: np.ndarray  #: bool, a LoWC is projected within the group's look-ahead N
    decided_by: np.ndarray  #: int8, :data:`DECIDED_BY_NAMES`: what vetoed a wait (map, projl, both, neither)
    wait_p_lowc: np.ndarray  #: the map's P(LoWC within H while waiting), nan when not a map read
    wait_in_box: np.ndarray  #: bool, the map read a state inside its box
    wait_turn_dps: np.ndarray  #: estimated turn rate of the intruder read, deg/s
    wait_map_turn_dps: np.ndarray  #: turn rate of the map read, deg/s
    link_lost: np.ndarray  #: bool, no GCS packet for ``link_timeout_s``
    max_alert: np.ndarray  #: int8, the highest alert level over intruders
    alert_level: np.ndarray  #: (N, M) alert level of each intruder
    pilot_cmd_received: np.ndarray  #: bool, a pilot command arrived this step
    pilot_cmd_fresh: np.ndarray  #: bool, ... and is not stale
    pilot_cmd_age_s: np.ndarray  #: its age by its send time (s), nan when none arrived
    sm_pilot: np.ndarray  #: SM of a fresh pilot command (s), nan otherwise
    sm_exec: np.ndarray  #: SM of the command flown (s), nan when inactive
    pilot_axis: np.ndarray  #: int8, the pilot's maneuver axis (AXIS_NAMES), none when no fresh command
    pilot_dir: np.ndarray  #: int8, its direction (DIR_NAMES)
    exec_axis: np.ndarray  #: int8, the axis of the command flown
    exec_dir: np.ndarray  #: int8, its direction
    exact_match: np.ndarray  #: bool, a blend kept the pilot's axis and direction
    cmd_trk: np.ndarray  #: the command flown: track (rad)
    cmd_vs: np.ndarray  #: vertical speed (m/s)
    cmd_gs: np.ndarray  #: ground speed (m/s)
    pilot_trk: np.ndarray  #: the pilot's last fresh command
    pilot_vs: np.ndarray
    pilot_gs: np.ndarray
    daa_trk: np.ndarray  #: the DAA resolution (nan when inactive)
    daa_vs: np.ndarray
    daa_gs: np.ndarray
    bands_trk: "np.ndarray | None"  #: (N, K) track band samples, deg (None when not recorded)
    bands_trk_region: "np.ndarray | None"  #: (N, K) int8 their regions (-1 = none)

    def __getitem__(self, key: str):
        if key not in _FIELD_SET:
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self):
        return iter(DECISION_FIELDS)

    def __len__(self) -> int:
        return len(DECISION_FIELDS)


#: names of the decision record's fields, in order (the columns and the wire read them in this order)
DECISION_FIELDS = tuple(f.name for f in fields(Decision))
_FIELD_SET = frozenset(DECISION_FIELDS)

#: name tables for the integer-coded fields
CODE_NAMES = {"decision": DECISION_NAMES, "rule": RULE_NAMES, "authority": AUTHORITY_NAMES, "decided_by": DECIDED_BY_NAMES,
              "pilot_axis": AXIS_NAMES, "exec_axis": AXIS_NAMES, "pilot_dir": DIR_NAMES, "exec_dir": DIR_NAMES}


#: the name tables as object arrays, made once (decode indexes them on every step of the SIL vehicle)
_NAME_ARRAYS = {key: np.asarray(names, dtype=object) for key, names in CODE_NAMES.items()}


def decode(decisions: Mapping) -> dict:
    """Copy of a decision record (as a dict) with the integer-coded fields as string arrays."""
    out = dict(decisions)
    for key, names in _NAME_ARRAYS.items():
        if key in out:
            out[key] = names[np.asarray(out[key], int)]
    return out


__all__ = ["Decision", "DECISION_FIELDS", "DECISION_NAMES", "DECIDED_BY_NAMES", "AUTHORITY_NAMES", "CODE_NAMES",
           "decode", "D_NONE", "D_WAIT", "D_NO_WAIT", "D_PILOT", "D_BLEND", "D_DAA_OVERRIDE", "D_DAA", "D_STALE",
           "D_LINK_LOST", "BY_NONE", "BY_MAP", "BY_PROJL", "BY_BOTH", "BY_NEITHER", "BY_KEPT", "A_PILOT", "A_DAA", "A_WAITING"]
