"""The report on a real small campaign (``daa-sil campaign run``, 3 groups x 80 encounters): every
row of the findings table has its value with a CI (or an exact bound) and a verdict, and a planted
DAA override turns a verdict into "not reproduced"."""

import hashlib
import json
import re
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from daa_sil.cli import main
from daa_sil.study.analysis.findings import BY_CONSTRUCTION, NOT_TESTABLE, VERDICTS, load_findings

N = 80
GROUPS = ("B-2", "IC-1", "ID-2")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("camp") / "c"
    rc = main(["campaign", "run", "--groups", ",".join(GROUPS), "--encounters", str(N), "--seed", "3",
               "--out", str(d), "--no-progress"])
    assert rc == 0
    return d


def _enc(d, group):
    return pq.read_table(sorted((d / group).glob("encounters-*.parquet")))


def _table_rows(text):
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| # | finding"))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip("|").split("|")])
    return lines[start], rows


def test_every_row_has_a_ci_and_a_verdict(campaign, tmp_path, capsys):
    rc = main(["campaign", "report", str(campaign), "--out", str(tmp_path / "rep"), "--replicates", "400", "--json"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["bootstrap"]["replicates"] == 400 and summary["bootstrap"]["seed"] == 14
    text = (tmp_path / "rep" / "report.md").read_text()
    header, rows = _table_rows(text)
    findings = load_findings()
    assert len(rows) == len(findings) > 60
    data = json.loads((tmp_path / "rep" / "findings.json").read_text())
    lowc = {g: int(pc.sum(_enc(campaign, g)["lowc"]).as_py() or 0) for g in GROUPS}
    intent = {g: int(pc.sum(_enc(campaign, g)["n_blend_intent"]).as_py()) for g in GROUPS}
    tested = 0
    for row, f in zip(rows, data["findings"]):
        ours, verdict = row[5], row[6].strip("*")
        o = f["outcomes"]["paper"]  # the default reading
        assert o["verdict"] in VERDICTS + (NOT_TESTABLE,) and verdict.startswith(o["verdict"]), (row, o)
        assert ours, row
        if o["verdict"] == NOT_TESTABLE:
            reason = o["evidence"]
            ran = all(g in GROUPS for g in _groups_of(f))
            if ran:  # only an undefined statistic may excuse a group that was run
                g = f["group"]
                assert (f["metric"] in ("pi_mean", "pi_paper_mean") and lowc[g] == 0) or \
                       (f["metric"] in ("exact_match", "axis_match") and g and intent[g] == 0), (f, reason)
            else:
                assert "not in this reading" in reason, (f, reason)
            continue
        tested += 1
        if f["kind"] in ("value", "change", "equivalence", "bound", "category"):
            assert o["lo"] is not None and o["hi"] is not None and o["lo"] <= o["value"] <= o["hi"], (f["id"], o)
            assert re.search(r"\[.+, .+\]", ours), row
        elif f["kind"] == "zero":
            assert ("≤" in ours) if o["verdict"] in ("reproduced", BY_CONSTRUCTION) else ("[" in ours), row
        else:
            assert "vs " in ours and ("McNemar" in ours or "per enc." in ours), row
    assert tested >= 40  # the three groups run give most findings a verdict
    # one value by hand from the Parquet tables: ID-2's no-wait decisions per encounter
    no_wait = pc.sum(_enc(campaign, "ID-2")["n_no_wait"]).as_py() / N
    f = next(x for x in data["findings"] if x["id"] == "no-wait" and x["group"] == "ID-2")["outcomes"]["paper"]
    assert f["value"] == pytest.approx(no_wait) and f["lo"] <= no_wait <= f["hi"]
    # a LoWC of positive duration always has a positive PI with the constants of the volume it violated
    # (the preset's, integrated on the LoWC segment); with the paper's Eq. constants (4000 ft = 1219.2 m,
    # not the preset's 1220 m) a LoWC that stays just outside that smaller disc may have none (seed 3:
    # ID-2 encounter 52, 1 s of LoWC, closest 1220.5 m, PI 4e-4 s), never a negative one
    for g in GROUPS:
        t = _enc(campaign, g)
        lo = np.asarray(t["lowc"]) & (np.asarray(t["lowc_duration_s"]) > 0)
        assert lo.any() and np.all(np.asarray(t["pi"])[lo] > 0) and np.all(np.asarray(t["pi_paper"])[lo] >= 0)


def _groups_of(f):
    if f["group"]:
        return [f["group"]] + (["B-2"] if f["kind"] == "change" else [])
    m = re.findall(r"\(([^)]*)\)", f["claim"])
    return [g.strip() for part in m for g in part.split(",")] or ["B-1", "B-2", "IC-1", "ID-1", "ID-2"]


def test_a_planted_override_is_not_reproduced(campaign, tmp_path):
    """Copy the campaign, give one ID-2 encounter a DAA override, name the copy's reading
    'planted', and report both side by side: "no DAA override with the allocation agent — ID-2"
    holds by construction on the real results and is not reproduced (a defect) on the planted ones."""
    planted = tmp_path / "planted"
    shutil.copytree(campaign, planted, ignore=shutil.ignore_patterns("report"))
    meta = json.loads((planted / "campaign.json").read_text())
    meta["config"]["reading"] = "planted"
    (planted / "campaign.json").write_text(json.dumps(meta))
    f0 = sorted((planted / "ID-2").glob("encounters-*.parquet"))[0]
    t = pq.read_table(f0)
    col = np.asarray(t["n_daa_override"]).copy()
    col[0] = 2
    t = t.set_column(t.schema.get_field_index("n_daa_override"), "n_daa_override", pa.array(col))
    pq.write_table(t, f0)
    # a tool that rewrites a chunk must give it new checksums, or the report refuses it as damaged
    sums = f0.with_name(f0.name.replace("encounters-", "chunk-").replace(".parquet", ".sha256"))
    sums.write_text("".join(f"{hashlib.sha256((f0.parent / name).read_bytes()).hexdigest()}  {name}\n"
                            for name in (line.split()[1] for line in sums.read_text().splitlines())))
    rc = main(["campaign", "report", str(campaign), str(planted), "--out", str(tmp_path / "rep"),
               "--replicates", "300"])
    assert rc == 0
    data = json.loads((tmp_path / "rep" / "findings.json").read_text())
    assert [r["label"] for r in data["readings"]] == ["paper", "planted"]
    o = next(x for x in data["findings"] if x["id"] == "override-integrated" and x["group"] == "ID-2")["outcomes"]
    assert o["paper"]["verdict"] == "by construction"
    assert o["planted"]["verdict"] == "not reproduced" and "2 in 1 of 80" in o["planted"]["text"]
    assert "a defect" in o["planted"]["evidence"]
    header, _ = _table_rows((tmp_path / "rep" / "appendix-readings.md").read_text())
    assert "| `paper` |" in header and "| `planted` |" in header + " |" and "Tabassum & Bai" in header


def test_report_labels_tell_apart_one_reading_on_two_sizes_of_one_seed():
    from daa_sil.study.analysis.report_input import Block, CountingRules, unique_labels

    def block(seed, n):
        return Block("paper", CountingRules("paper", {}, ""), {}, meta={"seed": seed, "n_encounters": n})

    got = [b.label for b in unique_labels([block(20261201, 10000), block(20261201, 2000), block(99991, 2000),
                                          Block("extended", CountingRules("extended", {}, ""), {}, meta={"seed": 1})])]
    assert got == ["paper (seed 20261201, 10,000 enc.)", "paper (seed 20261201, 2,000 enc.)", "paper (seed 99991)",
                   "extended"]
