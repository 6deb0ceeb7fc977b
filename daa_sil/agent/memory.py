"""What the allocation agent (:func:`daa_sil.agent.step.agent_step`) reads from the link each step
(:class:`PilotInput`) and carries between steps (:class:`AgentMemory`). Arrays (N,), times s,
angles rad."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from daa_sil.daa import AXIS_NONE, DaaState
from daa_sil.geometry.kinematics import AircraftState, Command


@dataclass
class PilotInput:
    """Pilot data at the vehicle this step, arrays (N,): ``received`` a command arrived this step,
    ``cmd`` the newest one (nan fields = keep current), ``t_sent``/``t_recv`` its send/arrival time (s),
    ``link_alive_t`` arrival time of the last packet of any kind from the GCS (s; nan = unknown)."""

    received: np.ndarray
    cmd: Command
    t_sent: np.ndarray
    t_recv: np.ndarray
    link_alive_t: np.ndarray

    @classmethod
    def nothing(cls, n: int, link_alive_t=np.nan) -> "PilotInput":
        """No command this step."""
        nan = np.full(n, np.nan)
        return cls(np.zeros(n, bool), Command(nan, nan, nan), nan.copy(), nan.copy(), np.full(n, link_alive_t, float))


@dataclass
class AgentMemory:
    """Batched agent state carried between steps (arrays (N,)). Times in s, angles rad."""

    pilot_trk: np.ndarray  #: last fresh pilot command (resolved at reception)
    pilot_vs: np.ndarray
    pilot_gs: np.ndarray
    pilot_t_sent: np.ndarray  #: its send time (nan = none yet)
    last_packet_t: np.ndarray  #: arrival time of the last GCS packet
    authority: np.ndarray  #: A_* code of the last step
    decision: np.ndarray  #: D_* code of the last step
    exec_trk: np.ndarray  #: command executed last step
    exec_vs: np.ndarray
    exec_gs: np.ndarray
    daa_axis: np.ndarray  #: last DAA resolution (axis, direction) codes, for persistence
    daa_dir: np.ndarray
    wait_start: np.ndarray  #: start of the current waiting streak (nan = none)
    intent_axis: "np.ndarray | None" = None  #: the pilot's (axis, direction) preference, AXIS_* / DIR_*
    intent_dir: "np.ndarray | None" = None
    daa_state: "DaaState | None" = None  #: DAA alert/band hysteresis (only with DaaConfig.stateful)
    encounter_over: "np.ndarray | None" = None  #: bool, safe avoidance reached (``active_from="encounter"``)

    def __post_init__(self):
        n = np.shape(self.pilot_trk)
        if self.intent_axis is None:
            self.intent_axis = np.full(n, AXIS_NONE, np.int8)
        if self.intent_dir is None:
            self.intent_dir = np.zeros(n, np.int8)
        if self.encounter_over is None:
            self.encounter_over = np.zeros(n, bool)

    @classmethod
    def initial(cls, n: int, own: AircraftState, t0: float = 0.0) -> "AgentMemory":
        """Start: the 'last pilot command' is the current course; the link counts as alive at ``t0``."""
        z = np.zeros(n, np.int8)
        return cls(own.trk.copy(), own.vs.copy(), own.gs.copy(), np.full(n, np.nan), np.full(n, float(t0)),
                   z.copy(), z.copy(), own.trk.copy(), own.vs.copy(), own.gs.copy(), z.copy(), z.copy(),
                   np.full(n, np.nan))

    def __getitem__(self, idx) -> "AgentMemory":
        return AgentMemory(*(None if getattr(self, f.name) is None else getattr(self, f.name)[idx] for f in fields(self)))


__all__ = ["PilotInput", "AgentMemory"]
