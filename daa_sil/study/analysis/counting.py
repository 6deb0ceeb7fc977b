"""How a campaign's tables are counted.

The counting settings of a reading (which pilot commands count as received, over which window),
the per-encounter columns each counted quantity sums (:data:`COUNT_SOURCES`), and the normalised
per-decision table.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from daa_sil.errors import UsageError
from daa_sil.study.analysis.metrics import paper_results

# ==================================================================================================
# The encounter-level study
# ==================================================================================================
#: counting settings of a reading (``campaign.json`` ``config.readings`` keys) and their defaults
COUNTING_DEFAULTS = {"received": "arrived", "window": "active", "blends": "all", "superseded": "dropped"}


#: allowed values of each counting setting, as documented for readers of a report
COUNTING_HELP = {
    "received": {"arrived": "every fresh pilot command that arrived during the window (incl. those the DAA overrode)",
                 "pilot+blend": "executed as sent + blended (the paper's Table 5 arithmetic: received = pilot + blend)",
                 "executed": "executed as sent only"},
    "window": {"active": "steps where the agent decides (corrective alert, a wait or blend in progress, DAA holding)",
               "whole": "the whole encounter (commands arrive outside the agent's active phase too)"},
    "blends": {"all": "every blend", "maneuvers": "blends of a command carrying a maneuver intent only (a blended "
                                                  "'hold' counts in no column)"},
    "superseded": {"dropped": "one command per step: a command the link released with a newer one is not counted",
                   "fate": "every command the link released; one released with a newer one (a FIFO burst) is "
                           "counted with the newest: executed as sent, blended or overridden with it"},
}

#: the per-encounter columns of the commands superseded within their step (``n_superseded*`` of
#: :mod:`daa_sil.study.simulation.fasttime_results`), by window / decision, added under ``superseded = fate``
_SUP_ARRIVED = {"active": "n_superseded", "whole": "n_superseded_whole"}
_SUP_EXEC = {"active": "n_superseded_exec", "whole": "n_superseded_exec_whole"}
_SUP_BLEND = {"all": "n_superseded_blend", "maneuvers": "n_superseded_blend_intent"}


#: counted quantity -> (the counting settings it depends on, {their values: per-encounter columns summed})
#: decisions happen only in the active phase, so their whole-encounter count is the active one;
#: commands also arrive outside it (``n_*_whole`` columns of :mod:`daa_sil.study.simulation.fasttime`)
def _decisions(col: str) -> tuple:
    return (("window",), {("active",): (col,), ("whole",): (col,)})


def _received() -> tuple:
    """received = every arrival, pilot (executed as sent) + blend, or executed only, per window, blend
    counting (which matters only to ``pilot+blend``) and superseded commands."""
    exec_col = {"active": "n_pilot_exec", "whole": "n_pilot_exec_whole"}
    arrived = {"active": "n_pilot_received", "whole": "n_pilot_received_whole"}
    blend_col = {"all": "n_blend", "maneuvers": "n_blend_intent"}
    table = {}
    for w in ("active", "whole"):
        for b in ("all", "maneuvers"):
            for sup in ("dropped", "fate"):
                fate = sup == "fate"
                table[("arrived", w, b, sup)] = (arrived[w],) + ((_SUP_ARRIVED[w],) if fate else ())
                table[("pilot+blend", w, b, sup)] = (exec_col[w], blend_col[b]) + (
                    (_SUP_EXEC[w], _SUP_BLEND[b]) if fate else ())
                table[("executed", w, b, sup)] = (exec_col[w],) + ((_SUP_EXEC[w],) if fate else ())
    return (("received", "window", "blends", "superseded"), table)


def _with_superseded(keys: tuple, table: dict, extra) -> tuple:
    """A quantity's entry with the ``superseded`` setting added: ``dropped`` as before, ``fate`` adds
    ``extra(values)`` (the columns of the superseded commands with that fate)."""
    out = {}
    for opt, cols in table.items():
        out[opt + ("dropped",)] = cols
        out[opt + ("fate",)] = cols + (extra(dict(zip(keys, opt))),)
    return (keys + ("superseded",), out)


COUNT_SOURCES: dict[str, tuple[tuple[str, ...], dict[tuple[str, ...], tuple[str, ...]]]] = {
    "wait": _decisions("n_wait"),
    "no_wait": _decisions("n_no_wait"),
    "received": _received(),
    "pilot_exec": _with_superseded(("window",), {("active",): ("n_pilot_exec",), ("whole",): ("n_pilot_exec_whole",)},
                                   lambda o: _SUP_EXEC[o["window"]]),
    "blend": _with_superseded(("blends",), {("all",): ("n_blend",), ("maneuvers",): ("n_blend_intent",)},
                              lambda o: _SUP_BLEND[o["blends"]]),
    "daa_override": _with_superseded(*_decisions("n_daa_override"), lambda o: "n_superseded_override"),
    "blend_intent": _decisions("n_blend_intent"),
    "blend_exact": _decisions("n_blend_exact"),
    "blend_axis": _decisions("n_blend_axis"),
    "stale": _decisions("n_stale"),
    "link_lost": _decisions("n_link_lost"),
}


def counting_options() -> dict[str, list[str]]:
    """The values each counting setting can take: every value some entry of :data:`COUNT_SOURCES`
    uses (so a new table entry is a new allowed value; :data:`COUNTING_HELP` only describes them)."""
    out: dict[str, list[str]] = {k: [] for k in COUNTING_DEFAULTS}
    for keys, table in COUNT_SOURCES.values():
        for opt in table:
            for k, v in zip(keys, opt):
                if v not in out.setdefault(k, []):
                    out[k].append(v)
    return out


#: quantities a report can do without (older result tables lack their columns)
OPTIONAL_QUANTITIES = ("blend_intent", "stale", "link_lost")


@dataclass(frozen=True)
class CountingRules:
    """How one named reading of the paper counts (not :class:`daa_sil.config.readings.Reading`, the
    reading's full bundle of settings, which also drives the simulation): its ``name``, its ``settings`` (``config.readings``; the
    counting keys of :data:`COUNTING_DEFAULTS` are used here, the rest is recorded) and where its
    results come from (``source``)."""

    name: str = "default"
    settings: Mapping = field(default_factory=dict)
    source: str = ""

    def counting(self) -> dict:
        """The counting settings in force: defaults overridden by the reading's."""
        out = dict(COUNTING_DEFAULTS)
        for k in COUNTING_DEFAULTS:
            if k in self.settings and self.settings[k] is not None:
                out[k] = str(self.settings[k])
        return out

    def columns_for(self, quantity: str) -> tuple[str, ...]:
        """Per-encounter columns summed for ``quantity`` under this reading."""
        direct = self.settings.get("columns") if isinstance(self.settings, Mapping) else None
        if isinstance(direct, Mapping) and quantity in direct:
            cols = direct[quantity]
            return (cols,) if isinstance(cols, str) else tuple(str(c) for c in cols)
        if quantity not in COUNT_SOURCES:
            raise UsageError(f"unknown counted quantity {quantity!r}; known: {', '.join(COUNT_SOURCES)}")
        keys, table = COUNT_SOURCES[quantity]
        cnt = self.counting()
        opt = tuple(cnt[k] for k in keys)
        if opt not in table:
            allowed = "; ".join(", ".join(f"{k}={v}" for k, v in zip(keys, o)) for o in table)
            raise UsageError(f"reading {self.name!r}: {quantity!r} cannot be counted with "
                             f"{', '.join(f'{k}={v}' for k, v in zip(keys, opt))}; allowed: {allowed}")
        return table[opt]

    def describe(self) -> str:
        """The reading's counting and other settings as recorded; the description (documentation, not a
        setting) is the current one of a reading of ``daa_sil/config/readings.py`` of the same name."""
        from daa_sil.config.readings import READINGS  # lazy: start-up time

        c = self.counting()
        rest = {k: v for k, v in self.settings.items() if k not in COUNTING_DEFAULTS and k != "columns"}
        if "description" in rest and self.name in READINGS and READINGS[self.name].description:
            rest["description"] = READINGS[self.name].description
        txt = ", ".join(f"{k}={v}" for k, v in c.items())
        if rest:
            txt += "; " + ", ".join(f"{k}={v}" for k, v in sorted(rest.items()))
        return txt


def paper_setup(group: str) -> "str | None":
    """``baseline`` / ``integrated`` for the paper's five groups (Table 2), None for others."""
    g = paper_results().get("groups", {}).get(group)
    return g.get("setup") if isinstance(g, dict) else None


#: decision-table columns the study reads (provenance needs ``decided_by`` and/or ``in_box``)
DECISION_COLUMNS = ("group", "encounter_id", "t", "decision", "decided_by", "in_box", "wait_in_box")
#: the authority each recorded decision gives (steps without a decision: the pilot's)
AUTHORITY_OF = {"wait": 2, "pilot": 0, "none": 0}  # 0 pilot, 1 DAA (every other decision), 2 waiting


def normalise_decisions(dec) -> "dict | None":
    """The decision table (Table or dict) as numpy columns for :class:`Study`: ``decided_by`` as
    str with ``""`` for none, ``in_box`` as int8 (1 inside the map's box, 0 outside, -1 no lookup).
    None when the table has neither provenance column."""
    if dec is None:
        return None
    names = dec.column_names if hasattr(dec, "column_names") else list(dec)
    if "in_box" not in names and "wait_in_box" in names:  # the simulator's name (daa_sil.study.simulation.fasttime)
        if hasattr(dec, "rename_columns"):
            dec = dec.rename_columns(["in_box" if c == "wait_in_box" else c for c in names])
        else:
            dec = {("in_box" if k == "wait_in_box" else k): v for k, v in dec.items()}
        names = dec.column_names if hasattr(dec, "column_names") else list(dec)
    if not any(c in names for c in ("decided_by", "in_box")):
        return None
    out = {}
    if hasattr(dec, "column_names"):
        import pyarrow as pa  # lazy: start-up time
        import pyarrow.compute as pc  # lazy: start-up time

        def arr(c):
            return dec.column(c)

        out["group"] = np.asarray(arr("group").to_numpy(zero_copy_only=False)).astype(str)
        out["encounter_id"] = np.asarray(arr("encounter_id").to_numpy(zero_copy_only=False), np.int64)
        if "decision" in names:
            out["decision"] = np.asarray(arr("decision").to_numpy(zero_copy_only=False)).astype(str)
        if "t" in names:
            out["t"] = np.asarray(arr("t").to_numpy(zero_copy_only=False), float)
        if "decided_by" in names:
            col = pc.cast(arr("decided_by"), pa.string())
            out["decided_by"] = np.asarray(pc.fill_null(col, "").to_numpy(zero_copy_only=False)).astype(str)
        if "in_box" in names:  # bool (or 0/1 numbers); null or nan = no lookup
            col = arr("in_box")
            valid = np.asarray(pc.is_valid(col).to_numpy(zero_copy_only=False), bool)
            vals = np.asarray(pc.fill_null(pc.cast(col, pa.float64()), 0.0).to_numpy(zero_copy_only=False), float)
            valid &= np.isfinite(vals)
            out["in_box"] = np.where(valid, (vals != 0).astype(np.int8), np.int8(-1)).astype(np.int8)
        return out
    out["group"] = np.asarray(dec["group"]).astype(str)
    out["encounter_id"] = np.asarray(dec["encounter_id"], np.int64)
    if "decision" in dec:
        out["decision"] = np.asarray(dec["decision"]).astype(str)
    if "t" in dec:
        out["t"] = np.asarray(dec["t"], float)
    if "decided_by" in dec:
        out["decided_by"] = np.array(["" if (b is None or b != b) else str(b) for b in dec["decided_by"]], dtype=str)
    if "in_box" in dec:
        out["in_box"] = np.array([-1 if (b is None or b != b) else int(bool(b)) for b in dec["in_box"]], np.int8)
    return out


def provenance_columns(dec: "dict | None", group: str, ids: np.ndarray) -> "dict | None":
    """Per-encounter provenance counts of ``group`` from a normalised decision table (or None):
    wait/no-wait decisions with a ``decided_by``, those decided by the map, by both and by ProjL;
    map lookups (``in_box`` given) and those inside the box."""
    if dec is None:
        return None
    m = dec["group"] == group
    eid = dec["encounter_id"][m]
    pos = np.searchsorted(ids, eid)
    ok = (pos < ids.size) & (ids[np.minimum(pos, ids.size - 1)] == eid)
    n = ids.size
    out = {}

    def count(mask):
        sel = mask & ok
        return np.bincount(pos[sel], minlength=n).astype(float)

    if "decided_by" in dec:
        by = dec["decided_by"][m]
        has = by != ""
        if "decision" in dec:
            has &= np.isin(dec["decision"][m], ("wait", "no_wait"))
        out["n_dec"] = count(has)
        out["n_dec_map"] = count(has & (by == "map"))
        out["n_dec_both"] = count(has & (by == "both"))
        out["n_dec_projl"] = count(has & (by == "projl"))
    if "in_box" in dec:
        ib = dec["in_box"][m]
        out["n_lookup"] = count(ib >= 0)
        out["n_in_box"] = count(ib == 1)
    if "t" in dec and "decision" in dec:
        out["n_switches"] = authority_switches(pos[ok], dec["t"][m][ok], dec["decision"][m][ok], n)
    return out


def authority_switches(pos: np.ndarray, t: np.ndarray, decision: np.ndarray, n: int) -> np.ndarray:
    """Changes of authority per encounter ``(n,)``: the decisions of encounter ``pos[i]`` at step ``t[i]``
    (s, 1 s steps) give the authority of those steps (:data:`AUTHORITY_OF`: a wait -> waiting, a pilot
    command flown -> the pilot, any other decision -> the DAA); steps without a decision are the
    pilot's. Each change between two consecutive steps counts one."""
    if pos.size == 0:
        return np.zeros(n)
    k = np.rint(t).astype(np.int64)
    steps = int(k.max()) + 2
    code = np.array([AUTHORITY_OF.get(d, 1) for d in np.unique(decision)], np.int8)
    dense = np.zeros((n, steps), np.int8)
    dense[pos, k] = code[np.searchsorted(np.unique(decision), decision)]
    return np.count_nonzero(dense[:, 1:] != dense[:, :-1], axis=1).astype(float)
