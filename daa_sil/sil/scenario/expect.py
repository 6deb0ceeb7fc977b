"""The expectation checker: does a run's result meet the scenario's ``expect`` section?"""

from __future__ import annotations

from .schema import Expectation


def check_expectation(exp: Expectation, result: dict) -> list[str]:
    """Violations of ``exp`` by a run ``result`` (keys ``lowc``, ``nmac``, ``min_range_m``,
    ``decision_counts``, ``first_link_lost_s``); empty list = all expectations hold."""
    bad: list[str] = []
    if exp.lowc is not None and bool(result["lowc"]) != exp.lowc:
        bad.append(f"expected lowc={str(exp.lowc).lower()}, got {str(bool(result['lowc'])).lower()}")
    if exp.nmac is not None and bool(result["nmac"]) != exp.nmac:
        bad.append(f"expected nmac={str(exp.nmac).lower()}, got {str(bool(result['nmac'])).lower()}")
    counts = result.get("decision_counts", {})
    for d in exp.decisions_include:
        if counts.get(d, 0) <= 0:
            bad.append(f"expected decision '{d}' to appear, it did not")
    for d in exp.decisions_exclude:
        if counts.get(d, 0) > 0:
            bad.append(f"expected no '{d}' decision, got {counts[d]}")
    if exp.min_range_at_least_m is not None:
        mr = result.get("min_range_m")
        if mr is None or not mr >= exp.min_range_at_least_m:
            bad.append(f"expected min range >= {exp.min_range_at_least_m:g} m, got {mr}")
    if exp.link_lost_by_s is not None:
        t = result.get("first_link_lost_s")
        if t is None or t > exp.link_lost_by_s:
            bad.append(f"expected link_lost by t = {exp.link_lost_by_s:g} s, got {t}")
    return bad
