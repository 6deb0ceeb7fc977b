"""The paper's inconsistencies, recomputed from its tables, and the signatures' paper side: each
expected number is typed from the paper's tables and worked by hand here, not taken from the code."""

import numpy as np
import pytest

from daa_sil.study.report import paper_checks as C
from daa_sil.study.analysis.study import Study
from daa_sil.study.report.signatures import SIGNATURES, paper_cell, signature_section


def test_reception_table_against_its_own_counts():
    rows = {r["group"]: r for r in C.reception_rows()}
    assert rows["IC-1"]["computed"] == pytest.approx(100 * (924574 / 793529 - 1)) == pytest.approx(16.514, abs=1e-3)
    assert rows["IC-1"]["printed"] == 16.19 and not rows["IC-1"]["agrees"]
    # the others agree once truncated to two decimals, as the paper prints: 15.106 -> 15.10, 16.189 -> 16.18
    assert rows["ID-1"]["agrees"] and rows["ID-2"]["agrees"]


def test_the_averages_are_pooled_against_both_baselines():
    a = C.averages()
    rec_int = (924574 + 913403 + 921993) / 3
    rec_base = (795163 + 793529) / 2
    assert a["reception"]["pooled"] == pytest.approx(100 * (rec_int / rec_base - 1)) == pytest.approx(15.817, abs=1e-3)
    assert a["reception"]["rows"] == pytest.approx(100 * (rec_int / 793529 - 1)) == pytest.approx(15.94, abs=0.01)
    nw_int = (10229 + 21078 + 10278) / 3
    assert a["reduction"]["pooled"] == pytest.approx(100 * (1 - nw_int / ((78842 + 87153) / 2)))
    assert a["reduction"]["pooled"] == pytest.approx(83.30, abs=0.01) and a["reduction"]["printed"] == 83.29
    assert a["reduction"]["rows"] == pytest.approx(100 * (1 - nw_int / 87153)) == pytest.approx(84.10, abs=0.01)


def test_received_counted_alike_and_lowc_time():
    c = C.counted_alike()
    assert c["b2"] == 793529 + 7564 and c["id2"] == 853974 + 68019
    assert c["pct"] == pytest.approx(15.09, abs=0.01)
    lt = {r["group"]: r for r in C.lowc_time()}
    # ID-2: 2.81e-7 / h x 666.67 h = 1.87e-4 of the time; x 3600 s = 0.674 s per flight hour; / 240 s >= 2.8e-3
    assert lt["ID-2"]["share"] == pytest.approx(2.81e-7 * 2000 / 3, rel=1e-3)
    assert lt["ID-2"]["s_per_hr"] == pytest.approx(0.6744, abs=1e-3)
    assert lt["ID-2"]["events_per_hr_min"] == pytest.approx(0.6744 / 240, rel=1e-3)
    assert lt["ID-2"]["events_per_hr_min"] > 1e-3  # at least the FAA's "Frequent"


def test_signatures_paper_side_shows_the_arithmetic():
    s = {x.key: x for x in SIGNATURES}
    assert paper_cell(s["unsafe"], "B-2") == "0.94 % = (7,564 + 0) / (793,529 + 7,564 + 0)"
    assert s["unsafe"].paper("ID-2")[0] == pytest.approx(68019 / 921993)
    assert paper_cell(s["daa_per_received"], "B-2") == "0.110 = 87,153 / 793,529"
    assert paper_cell(s["received"], "B-2") == "79.4 = 793,529 / 10,000"
    assert paper_cell(s["active"], "B-2") == "not given"


def _study():
    n = 400
    rng = np.random.default_rng(3)

    def g(name, lowc, dur):
        cols = {"group": np.array([name] * n), "encounter_id": np.arange(n), "duration_s": np.full(n, 240.0),
                "lowc": lowc, "nmac": np.zeros(n, bool), "lowc_duration_s": np.where(lowc, dur, 0.0),
                "pi": np.zeros(n), "dev_h_m": np.zeros(n), "dev_v_m": np.zeros(n), "n_active_steps": lowc * 30}
        for c in ("n_wait", "n_no_wait", "n_pilot_received", "n_pilot_exec", "n_blend", "n_blend_exact",
                  "n_blend_axis", "n_daa_override"):
            cols[c] = rng.poisson(2, n)
        return cols

    lo_b2 = np.arange(n) < 40
    lo_id2 = np.arange(n) < 30  # fewer LoWC encounters ...
    b2, id2 = g("B-2", lo_b2, 4.0), g("ID-2", lo_id2, 8.0)  # ... lasting twice as long
    return Study({k: np.concatenate([b2[k], id2[k]]) for k in b2}, replicates=300, seed=2)


def test_report_sections_render_the_reconciliation_on_our_runs():
    st = _study()
    assert st.estimate("ID-2", "lowc_duration_mean").value == pytest.approx(8.0)
    assert st.estimate("B-2", "lowc_s_per_hr").value == pytest.approx(40 * 4.0 / (400 * 240) * 3600)
    text = "\n".join(C.inconsistency_section({"r": st}))
    assert "30 / 40" in text and "16.51 %" in text and "15.09 %" in text and "Frequent" in text
    assert "+100.0 %" in text  # ID-2's LoWCs last twice as long: both statements can hold
    sig = "\n".join(signature_section({"r": st}))
    assert "0.94 % = (7,564 + 0)" in sig and "**ID-2**" in sig
