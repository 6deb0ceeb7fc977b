"""Glue between a scenario and :class:`daa_sil.onboard.OnboardCore` with N = 1 (no I/O).

:class:`VehicleCore` builds the onboard core from a scenario exactly as fast-time does
(:func:`daa_sil.sil.scenario.encounter_set` for truth and scripts, the group's
:class:`~daa_sil.agent.step.AllocationPolicy` with the scenario's overrides, the cached wait-map
family), turns accepted pilot commands into the agent's :class:`~daa_sil.agent.step.PilotInput`, keeps
one step-log row per step and encodes the telemetry of a step as MAVLink messages.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from daa_sil.agent import step as A
from daa_sil.config.groups import policy_for_group
from daa_sil.config.settings import STEP
from daa_sil.config.overrides import Overrides, group_policy
from daa_sil.config.policy import AllocationPolicy
from daa_sil.geometry.kinematics import Command
from daa_sil.sil.scenario import Scenario, encounter_set

from .commands import PilotCommand
from daa_sil.daa import kernels
from daa_sil.sil.scenario import link_legs
from daa_sil.geometry.kinematics import AircraftState


def scenario_policy(sc: Scenario) -> AllocationPolicy:
    """The group's policy with the scenario's wait function, blending and ProjL veto (its per-group
    settings come later, in :func:`resolve_policy`'s order)."""
    al = sc.allocation
    return replace(policy_for_group(al.group), wait_mode=al.wait, blending=al.blending, projl=al.projl)


def build_policy(sc: Scenario) -> AllocationPolicy:
    """The scenario's own policy: :func:`scenario_policy` with the per-group settings it gives (W_T, N,
    the timeouts, ...), no run configuration."""
    return sc.allocation.settings.applied(scenario_policy(sc), run_wide=False)


def build_onboard(sc: Scenario, policy=None, waitmap: "str | None" = None, config=None,
                  flags: "Overrides | None" = None):
    """``(OnboardCore, EncounterSet, policy, wait-map family or None)`` for scenario ``sc`` (N = 1). ``waitmap`` is a
    ``--waitmap`` value (map preset, grid spec or family directory; None = the configuration's, else
    the default map), read exactly as fast-time reads it (:func:`daa_sil.waitmap.family_for`, LoWC
    preset ``paper``). ``config`` (a :class:`daa_sil.config.run_config.RunConfig`) contributes its
    ``daa`` changes on top of the scenario's threshold preset, its per-group settings (``allocation``,
    ``link``) where the scenario gives none, and its wait-map source; ``flags`` the command line's
    per-group settings (:func:`resolve_policy`)."""
    from daa_sil.onboard import OnboardCore  # lazy: start-up time

    # load the compiled DAA now, not at the first conflict (a realtime run would stall); Algorithm 2's search
    # too, lazy elsewhere: a blend can come at any step, and a parameter can switch blending on mid-run
    kernels.get().search_into.compile()
    es = encounter_set(sc)
    config = run_config(config)
    policy = resolve_policy(sc, policy, config, flags)
    waitmap = waitmap if waitmap is not None else config.map_source
    daa_cfg = config.daa_config(sc.thresholds)
    lookup = family = None
    if policy.wait_mode == "map":
        from daa_sil import waitmap as wm  # lazy: start-up time

        family = wm.family_for(waitmap, preset="paper", horizon=config.map_horizon(waitmap))
        lookup = A.make_wait_lookup(family, cfg=daa_cfg, outside=config.effective_reading.outside)
    core = OnboardCore(es.own, es.intr, es.intruder_controls, policy, daa_cfg, lookup, thresholds=sc.thresholds,
                       outcomes=False)  # (the step log reads lowc / nmac; the PI and minimum range are fast-time's)
    return core, es, policy, family


def run_config(config=None):
    """``config``, or the defaults: the study's default reading (its maps, its agent rules)."""
    if config is not None:
        return config
    from daa_sil.config.run_config import load_config  # lazy: start-up time

    return load_config(None)


def resolve_policy(sc: Scenario, policy=None, config=None, flags: "Overrides | None" = None) -> AllocationPolicy:
    """The agent's policy for ``sc``: ``policy``, else the scenario's group (:func:`scenario_policy`),
    through :func:`daa_sil.config.overrides.group_policy`: the run configuration's reading rules and
    per-group settings (``config`` None: the defaults, :func:`run_config`), then the scenario's, then
    the ``flags``' (the order fast-time follows too). Cheap (no kernels, no maps): the booting vehicle
    answers parameters from it."""
    config = run_config(config)
    return group_policy(policy or scenario_policy(sc), reading=config.effective_reading, file=config.group_settings,
                        scenario=None if policy is not None else sc.allocation.settings, flags=flags)


def link_delay_processes(sc: Scenario) -> "dict | None":
    """The scenario link's delay processes, ``{"up": DelayProcess, "down": DelayProcess}`` (None if per-packet).

    These are the processes a shim seeded with the scenario's seed applies (and fast-time, for the
    same encounter seed): the step log's ``delay_up_s`` / ``delay_down_s`` at ``t`` are their values
    (s), i.e. the *configured* one-way delay of a packet sent at ``t`` before the FIFO rule, not a
    measurement. With ``link.epoch_s = 0`` (a draw per datagram) there is no per-step value: None.
    """
    from daa_sil.models.delay_process import link_delay_processes  # lazy: start-up time
    from daa_sil.sil.shim_config import delay_stream_seeds  # lazy: start-up time

    if sc.link.epoch_s <= 0:
        return None
    seeds = delay_stream_seeds(sc.seed)
    return link_delay_processes(link_legs(sc), seeds["up"], seeds["down"], epoch_s=sc.link.epoch_s)


#: step-log rows kept in memory (a day at 1 s steps); a vehicle that flies on past its scenario keeps
#: flying, and its step log holds the first MAX_ROWS steps (``rows_dropped`` counts the rest)
MAX_ROWS = 86_400


class VehicleCore:
    """Scenario + OnboardCore (N = 1) + pilot-command intake + step-log rows + telemetry encoding.

    Steps may go on past the scenario's ``n_steps``: the ownship flies its last command (or its plan),
    the intruders fly on straight once their scripts end, and :meth:`inject_intruder` adds traffic."""

    booting = False  #: (:class:`vehicle.boot.BootPlant` is the plant before this one is ready)

    def __init__(self, sc: Scenario, policy=None, waitmap: "str | None" = None, config=None,
                 flags: "Overrides | None" = None):
        self.sc = sc
        self.config = config
        self.core, self.es, self.policy, family = build_onboard(sc, policy, waitmap, config, flags)
        #: the wait maps flown (``waitmap.describe``: grid, parameters, turn rates, the content hashes
        #: the load verified), None without a map; the step log's ``waitmap`` metadata
        self.waitmap_record = None
        if family is not None:
            from daa_sil.waitmap import describe  # lazy: start-up time

            self.waitmap_record = describe(family)
        self.dt = STEP.default
        self.n_steps = sc.n_steps
        self._new: list[PilotCommand] = []
        self.last_cmd: "PilotCommand | None" = None
        self.last_gcs_data_t = math.nan
        self.last_authority = "pilot"
        self.last_decision = "none"
        self.rows: list[dict] = []
        self.last_row: "dict | None" = None  #: the newest step's row (also past MAX_ROWS)
        self.rows_dropped = 0
        self.delay_up_s = math.nan
        self.delay_down_s = math.nan
        self._delay_procs = link_delay_processes(sc)
        self.icao = [i.id for i in sc.intruders]
        self.callsigns = [i.callsign for i in sc.intruders]

    # -- what the protocol reads and writes (:class:`vehicle.services.Plant`) -----------------------
    def set_policy(self, policy) -> None:
        """Swap the agent's AllocationPolicy (at a step boundary: it holds from this step)."""
        self.core.policy = policy
        self.policy = policy

    def mode(self) -> int:
        """The ArduPlane mode the vehicle shows now (:func:`vehicle.identity.mode_of` of the last authority)."""
        from .identity import mode_of  # lazy: start-up time

        return mode_of(self.last_authority, bool(self.core.policy.enabled))

    def own_position(self) -> "tuple[float, float, float]":
        """The ownship's position now (ENU m)."""
        o = self.core.own
        return float(o.x[0]), float(o.y[0]), float(o.z[0])

    # -- inputs -----------------------------------------------------------------------------------
    def note_gcs_data(self, t: float) -> None:
        """A data packet (not lockstep control) from the GCS arrived at vehicle sim time ``t`` (s)."""
        self.last_gcs_data_t = t

    def add_command(self, cmd: PilotCommand) -> None:
        """An accepted (gate-checked) pilot command; the newest per step goes to the agent."""
        self._new.append(cmd)

    def pilot_input(self, t: float) -> "A.PilotInput":
        """The agent's input for step ``t``: the newest command accepted since the last step."""
        alive = self.last_gcs_data_t
        if not self._new:
            return A.PilotInput.nothing(1, link_alive_t=alive)
        c = max(self._new, key=lambda x: (x.t_sent, x.seq))
        self._new.clear()
        self.last_cmd = c
        trk = math.radians(c.track_deg) if math.isfinite(c.track_deg) else math.nan
        return A.PilotInput(np.array([True]), Command(np.array([trk]), np.array([c.vs_mps]), np.array([c.gs_mps])),
                            np.array([c.t_sent]), np.array([t]), np.array([alive], float))

    # -- step ---------------------------------------------------------------------------------------
    def step(self, t: float):
        """One OnboardCore step at ``t`` (s); returns its StepOutput and records the step-log row."""
        if self._delay_procs is not None:
            self.delay_up_s = self._delay_procs["up"].delay(t)
            self.delay_down_s = self._delay_procs["down"].delay(t)
        out = self.core.step(t, self.pilot_input(t))
        dec = out.decisions
        self.last_authority = A.AUTHORITY_NAMES[int(dec.authority[0])]
        self.last_decision = A.DECISION_NAMES[int(dec.decision[0])]
        self.last_row = self._row(out)
        if len(self.rows) < MAX_ROWS:
            self.rows.append(self.last_row)
        else:
            self.rows_dropped += 1
        return out

    def inject_intruder(self, intr) -> None:
        """Fly a :class:`vehicle.traffic.Intruder` from this step on (straight, constant velocity)."""

        self.core.add_intruders(AircraftState(*(np.full((1, 1), float(v)) for v in (intr.x, intr.y, intr.z, intr.gs,
                                                                                        intr.trk, intr.vs))))
        self.icao.append(int(intr.icao))
        self.callsigns.append(str(intr.callsign))

    def _row(self, out) -> dict:
        """The step-log row of this step: :func:`daa_sil.onboard.step_columns`, fast-time's builder, at N = 1."""
        from daa_sil.onboard import step_columns  # lazy: start-up time
        from daa_sil.steplog import step_row  # lazy: start-up time

        return step_row(step_columns(out, self.delay_up_s, self.delay_down_s), 0)

    # -- outputs ------------------------------------------------------------------------------------

    def steplog_table(self, n_rows: "int | None" = None):
        """The first ``n_rows`` rows (all if None) as a step-log ``pyarrow.Table`` (schema of
        :mod:`daa_sil.steplog`)."""
        import pyarrow as pa  # lazy: start-up time

        from daa_sil.steplog import STEP_SCHEMA  # lazy: start-up time

        rows = self.rows if n_rows is None else self.rows[:n_rows]
        cols = {name: [r.get(name, math.nan) for r in rows] for name in STEP_SCHEMA.names}
        return pa.Table.from_pydict(cols, schema=STEP_SCHEMA)

    def write_steplog(self, path: "str | Path", meta: dict, n_rows: "int | None" = None) -> Path:
        """Write the first ``n_rows`` rows (all if None) atomically to ``path``; if its directory can no
        longer take it, to :func:`daa_sil.out_dir.rescue_path` (a warning says where). Returns where."""
        from daa_sil.out_dir import write_or_rescue  # lazy: start-up time
        from daa_sil.steplog import write_steplog  # lazy: start-up time

        table = self.steplog_table(n_rows)
        return write_or_rescue(path, lambda p: write_steplog(table, p, metadata=meta), "step log")
