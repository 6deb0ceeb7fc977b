"""Report rendering from small synthetic campaign directories: sections, readings, ablation,
provenance, errors."""

import json
import zlib

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from daa_sil.errors import FileFormatError, UsageError
from daa_sil.study.report.pages import APPENDICES, ablation_rows, write_report
from daa_sil.study.report.figures import FIGURES
from daa_sil.study.analysis.report_input import build_blocks, parse_recount
from daa_sil.study.analysis.study import Study
from daa_sil.study.analysis.findings import load_findings

COLS = ("n_wait", "n_no_wait", "n_pilot_received", "n_pilot_exec", "n_blend", "n_blend_exact", "n_blend_axis",
        "n_daa_override")


def _group_table(group, n, rng, wait, nmac=False, no_wait_scale=1.0):
    active = rng.random(n) < 0.3
    c = {"group": [group] * n, "encounter_id": np.arange(n), "duration_s": np.full(n, 240.0),
         "lowc": np.arange(n) < 3, "nmac": (np.arange(n) == 1) & nmac,
         "lowc_duration_s": np.r_[3.0, 2.0, 1.0, np.zeros(n - 3)],
         "pi": np.r_[0.7, 0.4, 0.2, np.zeros(n - 3)], "pi_paper": np.r_[0.8, 0.5, 0.25, np.zeros(n - 3)],
         "dev_h_m": rng.normal(1700, 100, n), "dev_v_m": rng.normal(180, 10, n),
         "intruder_turns": np.arange(n) % 2 == 0}
    k = rng.poisson(9, n) * active
    c["n_wait"] = k * 8 // 9 if wait else np.zeros(n, int)
    c["n_no_wait"] = np.rint((k // 9 if wait else k) * no_wait_scale).astype(int)
    c["n_blend"] = k * 7 // 9 if wait else np.zeros(n, int)
    c["n_blend_intent"] = c["n_blend"]
    c["n_blend_exact"] = c["n_blend"] * 6 // 7
    c["n_blend_axis"] = c["n_blend"] - c["n_blend_exact"]
    c["n_daa_override"] = np.zeros(n, int) if wait else k // 9
    c["n_pilot_exec"] = k // 3
    c["n_pilot_received"] = c["n_pilot_exec"] + c["n_blend"] + c["n_daa_override"]
    return pa.table(c)


def _campaign(d, groups, n=60, reading=None, settings=None, seed=0, decisions=None):
    rng = np.random.default_rng(seed)
    for g, wait, kw in groups:
        (d / g).mkdir(parents=True)
        pq.write_table(_group_table(g, n, rng, wait, **kw), d / g / "encounters-00000.parquet")
        if decisions is not None:
            pq.write_table(decisions(g, n), d / g / "decisions-00000.parquet")
    cfg = {"groups": [g for g, _, _ in groups], "n_encounters": n, "seed": seed, "preset": "paper"}
    if reading:
        cfg["reading"] = reading
    if settings:
        cfg["readings"] = settings
    (d / "campaign.json").write_text(json.dumps({"format": 1, "config": cfg}))
    return d


def _pages(main) -> str:
    """The main page and its appendices, as one text."""
    return "\n".join([main.read_text()] + [(main.parent / a).read_text() for a in APPENDICES])


def _widest(text: str) -> int:
    return max((line.count("|") - 1 for line in text.splitlines() if line.startswith("|")), default=0)


PAPER5 = [("B-1", False, {"nmac": True}), ("B-2", False, {}), ("IC-1", True, {}), ("ID-1", True, {}),
          ("ID-2", True, {})]


def test_report_renders_findings_tables_and_figures(tmp_path):
    d = _campaign(tmp_path / "camp", PAPER5)
    out = write_report(d, tmp_path / "rep", replicates=500)
    main = out.read_text()
    text = _pages(out)
    for f in FIGURES:
        assert (tmp_path / "rep" / f).stat().st_size > 1000 and f in main
    # the main page: the reading against the paper
    for title in ("## Headline tally", "## Every finding of the paper", "## Where the misses come from",
                  "## Signatures", "## Verdict words and rules", "consistent (not shown)", "uninformative"):
        assert title in main, title
    # the appendices: readings, ablations, provenance
    for title in ("Table 3", "Table 4", "Table 5", "Table 7", "Table 8", "Penetration integral", "Paired comparisons",
                  "Ablation", "Decision provenance", "Methods", "## Where the paper contradicts itself", "16.51 %"):
        assert title in text, title
    assert all(f"]({a})" in main for a in APPENDICES)
    assert "bootstrap seed 14" in text and "500 replicates" in text
    # a reader's page: no table wider than 12 columns; the main page short
    assert _widest(text) <= 12 and len(main.splitlines()) <= 800
    data = json.loads((tmp_path / "rep" / "findings.json").read_text())
    assert data["bootstrap"] == {"replicates": 500, "seed": 14, "conf": 0.95}
    by = {(f["id"], f["group"]): f["outcomes"]["default"] for f in data["findings"]}
    assert by[("nmac", "B-1")]["verdict"] == "not reproduced"  # we planted one NMAC in B-1
    assert by[("nmac", "B-2")]["verdict"] == "reproduced"
    assert by[("override-integrated", "ID-2")]["verdict"] == "by construction"  # counted apart
    # the paper's no-wait count in ID-2 (10,278 in 10,000) is shown per encounter
    assert "1.03" in main
    # no decision provenance columns: skipped with a note, not an error
    assert "skipped — the decision tables carry no" in text or "skipped" in text


def _headers(text: str) -> list:
    """The header cells of every Markdown table of ``text``."""
    lines = text.splitlines()
    return [[c.strip() for c in a.strip().strip("|").split("|")] for a, b in zip(lines, lines[1:])
            if a.startswith("|") and b.startswith("|---")]


def _rows(text: str) -> list:
    """(header cells, row cells) of every body row of every Markdown table of ``text``."""
    out, hdr, lines = [], None, text.splitlines()
    for i, line in enumerate(lines):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not line.startswith("|"):
            hdr = None
        elif i + 1 < len(lines) and lines[i + 1].startswith("|---"):
            hdr = cells
        elif hdr is not None and not line.startswith("|---"):
            out.append((hdr, cells))
    return out


def test_main_page_opens_with_a_summary_and_names_no_machine_path(tmp_path):
    """The page a reader meets: what is reproduced and what is missed (with the cause) before the tables;
    no header named twice (the signatures side by side); campaign directories under the runs directory
    shown as RUNS/..., not as this machine's path."""
    runs = tmp_path / "runs"
    d = _campaign(runs / "paper", PAPER5, reading="paper")
    out = write_report([d], tmp_path / "rep", replicates=300, runs_root=runs)
    main, text = out.read_text(), _pages(out)
    assert main.index("## In short") < main.index("## Headline tally") < main.index("## Every finding")
    short = main[main.index("## In short"):main.index("## Headline tally")]
    assert "**Reproduced:** " in short and "no NMAC (B-2, IC-1, ID-1, ID-2)" in short  # B-1 had one planted
    assert "**Missed: LoWC and NMAC" in short and "Cause: " in short
    assert "`RUNS/paper`" in text and str(runs) not in text
    for h in _headers(main):
        assert len(h) == len(set(h)) and len(h) <= 12, h
    sig = next(h for h in _headers(main) if h[0] == "group" and any("Tabassum & Bai" in c for c in h))
    assert "received / enc.: Tabassum & Bai" in sig and "received / enc.: ours [95 % CI]" in sig
    assert main.startswith("# Tabassum & Bai's findings against the `paper` reading")
    # one set of findings on every page: the summary's total is each tally row's, and each row adds up to it
    n = len(load_findings())
    assert f"The paper states {n} findings about its results" in short
    tallies = [row for page in sorted(out.parent.glob("*.md")) for hdr, row in _rows(page.read_text())
               if hdr[:3] == ["reading", "findings", "empirical"]]
    assert tallies
    for row in tallies:
        assert int(row[1]) == n and sum(int(c) for c in row[3:]) == n == int(row[2]) + sum(int(c) for c in row[7:]), row


def test_two_readings_side_by_side_and_a_recount(tmp_path):
    a = _campaign(tmp_path / "lit", PAPER5, reading="literal", settings={"units": "m"}, seed=1)
    b = _campaign(tmp_path / "ft", PAPER5, reading="feet", settings={"units": "ft", "received": "pilot+blend"}, seed=2)
    out = write_report([a, b], tmp_path / "rep", replicates=300, recount=["exec:received=executed"])
    text = (tmp_path / "rep" / "appendix-readings.md").read_text()
    header = next(line for line in text.splitlines() if line.startswith("| # | finding"))
    assert "| Tabassum & Bai |" in header  # the published value: never a column named like a reading
    for lab in ("literal", "feet", "literal+exec", "feet+exec"):
        assert f"| `{lab}` |" in header + " |" or f"| `{lab}`" in header
    assert _widest(_pages(out)) <= 12
    data = json.loads((tmp_path / "rep" / "findings.json").read_text())
    rec = next(f for f in data["findings"] if f["id"] == "received" and f["group"] == "ID-2")["outcomes"]
    # received counted three ways from the same columns: arrived > pilot + blend > executed as sent
    assert rec["literal"]["value"] > rec["literal+exec"]["value"]
    assert rec["feet"]["value"] > rec["feet+exec"]["value"]
    assert (tmp_path / "rep" / "fig9_allocation-feet.png").is_file()
    # a recount the source already counts by adds no column; another keeps its own description
    labels = [blk.label for blk in build_blocks([a, b], ["pb:received=pilot+blend"])]
    assert labels == ["literal", "feet", "literal+pb"]
    assert "recounted with received=pilot+blend" in build_blocks([a], ["pb:received=pilot+blend"])[1].reading.settings["description"]


def test_seeds_of_one_reading_are_compared(tmp_path):
    a = _campaign(tmp_path / "s0", PAPER5, reading="literal", seed=0)
    b = _campaign(tmp_path / "s7", PAPER5, reading="literal", seed=7)
    text = _pages(write_report([a, b], tmp_path / "rep", replicates=300))
    assert "literal (seed 0)" in text and "literal (seed 7)" in text
    assert "## Agreement between campaign seeds" in text and "findings compared agree within the CI" in text


def test_a_smaller_run_of_the_same_seed_is_not_compared_as_another_seed(tmp_path):
    """Its encounters are the first of the larger run's: not an independent sample."""
    big = _campaign(tmp_path / "big", PAPER5, n=60, reading="literal", seed=0)
    small = _campaign(tmp_path / "small", PAPER5, n=30, reading="literal", seed=0)
    other = _campaign(tmp_path / "other", PAPER5, n=30, reading="literal", seed=7)
    text = _pages(write_report([big, small, other], tmp_path / "rep", replicates=200))
    heads = [line for line in text.splitlines() if line.startswith("### literal") and " vs " in line]
    assert "literal (seed 0, 60 enc.)" in text and "literal (seed 0, 30 enc.)" in text
    assert heads == ["### literal (seed 0, 60 enc.) vs literal (seed 7)"], heads


def _decisions(map_share):
    def make(g, n):
        rng = np.random.default_rng(zlib.crc32(g.encode()))
        k = 40 * n
        by = rng.choice(["map", "projl", "both", "neither"], k, p=[map_share, 0.3, 0.1, 0.6 - map_share])
        return pa.table({"group": [g] * k, "encounter_id": np.repeat(np.arange(n), 40),
                         "decision": rng.choice(["wait", "no_wait"], k), "decided_by": by,
                         "in_box": pa.array(np.where(rng.random(k) < 0.1, None, rng.random(k) < 0.25).tolist(),
                                            pa.bool_())})
    return make


def test_ablation_and_provenance_sections(tmp_path):
    groups = [("B-2", False, {}), ("ID-2", True, {}), ("ID-2-projl", True, {"no_wait_scale": 1.0}),
              ("ID-2-map", True, {"no_wait_scale": 3.0}), ("my-group", True, {})]
    d = _campaign(tmp_path / "abl", groups, n=200, decisions=_decisions(0.2))
    text = _pages(write_report(d, tmp_path / "rep", replicates=500))
    assert "### default: what the map adds to ProjL (ID-2 minus ID-2-projl)" in text
    assert "what ProjL adds to the map (ID-2 minus ID-2-map)" in text
    assert "my-group" in text  # an unknown group is shown, not a crash
    # each ablation opens with one summary row per reading, the per-reading tables collapsed below it
    abl = (tmp_path / "rep" / "appendix-ablations.md").read_text()
    head = abl.index("### What ProjL adds to the map (ID-2 minus ID-2-map)")
    summary = next(row for hdr, row in _rows(abl[head:]) if hdr[0] == "reading")
    assert summary[0] == "`default`" and summary[1].startswith("**-")  # ID-2-map's 3x allocations: measurable
    assert abl.index("<details>", head) < abl.index("#### default: what ProjL adds to the map", head)
    blocks = build_blocks(d)
    st = Study(blocks[0].enc, blocks[0].reading, dec=blocks[0].dec, replicates=500)
    rows = {r["metric"]: r for r in ablation_rows(st, "ID-2", "ID-2-map")}
    # ID-2-map allocates 3x as often in the same encounters: clearly measurable, negative difference
    assert rows["no_wait"]["measurable"] and rows["no_wait"]["diff"].hi < 0
    # provenance: about 20 % decided by the map, about 25/90 of lookups inside the box
    e = st.estimate("ID-2", "map_decided_share")
    assert e.lo < 0.2 < e.hi and e.hi - e.lo < 0.05
    e = st.estimate("ID-2", "in_box_share")
    assert e.lo < 0.25 < e.hi
    assert "decided by the wait function (map)" in text and "Only the ID groups read a map" in text


def test_identical_ablation_says_the_map_adds_nothing(tmp_path):
    """ID-2-projl with the same table as ID-2: every paired difference is exactly 0."""
    d = tmp_path / "same"
    _campaign(d, [("B-2", False, {}), ("ID-2", True, {})], n=100)
    t = pq.read_table(d / "ID-2" / "encounters-00000.parquet")
    (d / "ID-2-projl").mkdir()
    t = t.set_column(0, "group", pa.array(["ID-2-projl"] * t.num_rows))
    pq.write_table(t, d / "ID-2-projl" / "encounters-00000.parquet")
    text = _pages(write_report(d, tmp_path / "rep", replicates=300))
    assert "The map adds nothing measurable to ProjL here." in text


def test_report_errors(tmp_path):
    with pytest.raises(FileFormatError, match="no such"):
        write_report(tmp_path / "nope", tmp_path / "o")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileFormatError, match="holds no"):
        write_report(tmp_path / "empty", tmp_path / "o")
    (tmp_path / "bad" / "B-1").mkdir(parents=True)
    (tmp_path / "bad" / "B-1" / "encounters-00000.parquet").write_bytes(b"garbage")
    with pytest.raises(FileFormatError, match="not a readable Parquet") as ei:
        write_report(tmp_path / "bad", tmp_path / "o")
    assert "\n" not in str(ei.value)
    assert not (tmp_path / "o" / "report.md").exists()
    # a reading that names a counting the table does not know
    d = _campaign(tmp_path / "r", PAPER5[:2], reading="x", settings={"window": "season"})
    with pytest.raises(UsageError, match="allowed: window=active"):
        write_report(d, tmp_path / "o2")
    assert not (tmp_path / "o2" / "report.md").exists()
    for bad, msg in (("noname", "NAME:key=value"), ("a:colour=red", "allowed keys"), ("a:received=some", "one of")):
        with pytest.raises(UsageError, match=msg):
            parse_recount(bad)


def test_findings_json_rounds_floats_and_stores_each_basis_row_once():
    from daa_sil.study.report.verdict_words import basis_changes, rounded

    assert rounded({"a": [0.0018427397934059897, 795163.0, 1 / 3], "b": "x"}) == {"a": [0.00184274, 795163.0, 0.333333],
                                                                                 "b": "x"}
    ref = [{"setting": "H", "value": 40}, {"setting": "outside", "value": "approach"}]
    mine = [{"setting": "H", "value": 40}, {"setting": "outside", "value": "clamp"}]
    assert basis_changes(mine, ref) == [{"setting": "outside", "value": "clamp"}]
    assert basis_changes(ref, ref) == [] and basis_changes(None, ref) is None
