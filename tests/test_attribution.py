"""The attribution table: every finding of the paper that is not true by construction lies in exactly
one cluster with a named cause, so no miss is left without a row; a miss outside every cluster is
listed as unattributed."""

from dataclasses import replace

import pytest

from daa_sil.study.attribution import CAUSES, CLUSTERS, attribution_rows
from daa_sil.study.findings import NOT_REPRODUCED, REPRODUCED, load_findings
from daa_sil.study.outcome import Outcome


def test_every_empirical_finding_is_in_exactly_one_cluster():
    ids = {f.id for f in load_findings() if not f.by_construction}
    held = [i for c in CLUSTERS for i in c.findings]
    assert sorted(held) == sorted(set(held))  # none in two clusters
    assert set(held) == ids  # none left out, none unknown
    for c in CLUSTERS:
        assert c.causes and set(c.causes) <= set(CAUSES) and c.experiments and c.because
    with pytest.raises(ValueError, match="unknown cause"):
        replace(CLUSTERS[0], causes=("bad luck",))


def test_rows_list_the_misses_and_flag_an_unattributed_one():
    found = load_findings()
    rows = [(f, {"r": Outcome(NOT_REPRODUCED if f.id in ("dev-h", "exact-match") else REPRODUCED, "x")})
            for f in found]
    out = attribution_rows(rows, "r", None)
    by = {r["key"]: r for r in out}
    assert len(by["deviation"]["misses"]) == 5 and all(m.startswith("dev-h — ") for m in by["deviation"]["misses"])
    assert by["blend-match"]["misses"] == ["exact-match (not reproduced)"]
    assert by["allocation"]["misses"] == [] and "not run" in by["allocation"]["showed"]
    assert "unattributed" not in by
    # a finding no cluster holds (a new one in paper_findings.yaml) shows up, not silently dropped
    stray = replace(found[3], id="a-new-finding")
    out = attribution_rows(rows + [(stray, {"r": Outcome(NOT_REPRODUCED, "x")})], "r", None)
    assert out[-1]["key"] == "unattributed" and "a-new-finding" in out[-1]["misses"][0]
