"""The vehicle node's step-log metadata (scenario, clock, counters, settings events, the full
configuration) as a pure function of what the node hands it, and the realtime step timing it records."""

from __future__ import annotations

import json
from dataclasses import asdict


class StepTiming:
    """Realtime: per step, how late its telemetry went out after its deadline and when its computation
    was done (ms after the deadline); keeps the running mean and max in the node's stats."""

    def __init__(self) -> None:
        self.late_ms: list[float] = []
        self.ready_ms: list[float] = []
        self._late_sum_ms = 0.0

    def ready(self, ms: float) -> None:
        """Step computed ``ms`` after its deadline (negative: ahead of it)."""
        self.ready_ms.append(ms)

    def published(self, ms: float, stats) -> None:
        """Step published ``ms`` after its deadline; updates ``stats.late_max_ms`` / ``late_mean_ms``."""
        stats.late_max_ms = round(max(stats.late_max_ms, ms), 3)
        self._late_sum_ms += ms
        self.late_ms.append(ms)
        stats.late_mean_ms = round(self._late_sum_ms / len(self.late_ms), 3)

    def p99_ms(self) -> float:
        """99th percentile of the lateness (ms); only when steps were published in realtime."""
        import numpy as np  # lazy: start-up time

        return round(float(np.percentile(self.late_ms, 99)), 3)


def config_record(sc, opts, core) -> dict:
    """The full configuration the vehicle flew: the run configuration (if any) with the scenario's
    threshold preset, the DAA configuration and the agent's policy actually used (``core``: the
    :class:`vehicle.core.VehicleCore`)."""
    from daa_sil.config.run_config import preset  # lazy: start-up time

    rc = opts.config if opts.config is not None else preset("paper")
    rec = rc.with_(thresholds=sc.thresholds).to_dict(full=True)
    rec["given"] = opts.config is not None
    rec["resolved"]["policy"] = asdict(core.core.policy)
    rec["resolved"]["daa"] = {k: v for k, v in asdict(core.core.daa_cfg).items() if k != "thresholds"}
    rec["waitmap"]["source"] = opts.waitmap or rc.waitmap["source"]
    return rec


def steplog_meta(sc, opts, core, stats, *, signed: bool, gate: dict, link: dict, live: "dict | None",
                 timing: StepTiming, wall0: float, events: list) -> "dict[str, str]":
    """Step-log metadata of a vehicle run: ``sc`` the scenario, ``opts`` / ``stats`` the node's options
    and counters, ``core`` its :class:`vehicle.core.VehicleCore`; ``gate`` the command gate's counters,
    ``link`` the main endpoint's stats, ``live`` the live feed's (None without one), ``timing`` the
    realtime step timing with ``wall0`` (loop s of step 0's deadline), ``events`` the settings writes."""
    meta = {"scenario": sc.name, "seed": str(sc.seed), "preset": sc.thresholds,
            "clock": opts.clock, "complete": str(stats.steps >= core.n_steps).lower(),
            "signed": str(signed).lower(),
            "gate": json.dumps(gate, sort_keys=True),
            "link": json.dumps(link, sort_keys=True),
            "vehicle": json.dumps({k: v for k, v in stats.__dict__.items() if k != "extra"}, sort_keys=True)}
    if live is not None:
        meta["live"] = json.dumps(live, sort_keys=True)
    if timing.late_ms:  # realtime: per-step lateness (ms) and the wall origin, for timing analyses
        meta["realtime_timing"] = json.dumps({"t0_monotonic": round(wall0, 6), "speed": opts.speed,
                                              "late_ms": [round(x, 2) for x in timing.late_ms],
                                              "ready_ms": [round(x, 2) for x in timing.ready_ms],
                                              **stats.extra})
    # parameter / mode writes: kind, name, old, new, status, link, source, t_received, t_applied, t_sent
    meta["settings"] = json.dumps([e.as_dict() for e in events], sort_keys=True)
    # every intruder flown, by step-log index (the scenario's, then injected ones): viewers label them so
    meta["intruders"] = json.dumps([{"icao": i, "callsign": c} for i, c in zip(core.icao, core.callsigns)])
    meta["config"] = json.dumps(config_record(sc, opts, core), sort_keys=True, default=str)
    if core.waitmap_record is not None:  # what `daa-sil run` records, without loading the maps again
        meta["waitmap"] = json.dumps(core.waitmap_record, sort_keys=True)
    return meta
