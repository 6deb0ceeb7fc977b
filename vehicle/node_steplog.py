"""The vehicle node's step log: the Parquet log of the steps flown, with the run's metadata
(scenario, clock, counters, settings events and the full configuration)."""

from __future__ import annotations

from pathlib import Path


class StepLogWriter:
    """Part of :class:`vehicle.node.VehicleNode` (a mixin: it uses the node's attributes)."""

    def _config_record(self) -> dict:
        """The full configuration the vehicle flew: the run configuration (if any) with the scenario's
        threshold preset, the DAA configuration and the agent's policy actually used."""
        from dataclasses import asdict

        from daa_sil.config.run_config import preset

        rc = self.opts.config if self.opts.config is not None else preset("paper")
        rec = rc.with_(thresholds=self.sc.thresholds).to_dict(full=True)
        rec["given"] = self.opts.config is not None
        rec["resolved"]["policy"] = asdict(self.core.core.policy)
        rec["resolved"]["daa"] = {k: v for k, v in asdict(self.core.core.daa_cfg).items() if k != "thresholds"}
        rec["waitmap"]["source"] = self.opts.waitmap or rc.waitmap["source"]
        return rec

    def write_steplog(self) -> "Path | None":
        """Write the step log so far (atomic Parquet); returns its path or None."""
        if self.opts.steplog is None or self.stats.steps == 0:
            return None
        import json

        if self._lates:
            import numpy as np

            self.stats.late_p99_ms = round(float(np.percentile(self._lates, 99)), 3)
        meta = {"scenario": self.sc.name, "seed": str(self.sc.seed), "preset": self.sc.thresholds,
                "clock": self.opts.clock, "complete": str(self.stats.steps >= self.core.n_steps).lower(),
                "signed": str(self.codec.signed).lower(),
                "gate": json.dumps(self.gate.counters.__dict__, sort_keys=True),
                "link": json.dumps(self.ep.stats() if self.ep else {}, sort_keys=True),
                "vehicle": json.dumps({k: v for k, v in self.stats.__dict__.items() if k != "extra"}, sort_keys=True)}
        if self.live is not None:
            meta["live"] = json.dumps(self.live.stats.__dict__, sort_keys=True)
        if self._lates:  # realtime: per-step lateness (ms) and the wall origin, for timing analyses
            meta["realtime_timing"] = json.dumps({"t0_monotonic": round(self._wall0, 6), "speed": self.opts.speed,
                                                  "late_ms": [round(x, 2) for x in self._lates],
                                                  "ready_ms": [round(x, 2) for x in self._ready],
                                                  **self.stats.extra})
        # parameter / mode writes: kind, name, old, new, status, link, source, t_received, t_applied, t_sent
        meta["settings"] = json.dumps([e.as_dict() for e in self.services.events], sort_keys=True)
        meta["config"] = json.dumps(self._config_record(), sort_keys=True, default=str)
        if self.core.waitmap_record is not None:  # what `daa-sil run` records, without loading the maps again
            meta["waitmap"] = json.dumps(self.core.waitmap_record, sort_keys=True)
        # only the steps flown: a step computed but stopped before it was published is not in the log
        return self.core.write_steplog(self.opts.steplog, meta, n_rows=self.stats.steps)
