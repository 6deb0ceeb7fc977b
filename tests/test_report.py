"""Report rendering from a small synthetic campaign directory."""

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from daa_sil.errors import FileFormatError
from daa_sil.report import FIGURES, write_report

COLS = ("n_wait", "n_no_wait", "n_pilot_received", "n_pilot_exec", "n_blend", "n_blend_exact", "n_blend_axis",
        "n_daa_override")


def _group_table(group, n, rng, wait, nmac=False):
    c = {"group": [group] * n, "encounter_id": np.arange(n), "duration_s": np.full(n, 240.0),
         "lowc": np.arange(n) == 0, "nmac": (np.arange(n) == 1) & nmac, "lowc_duration_s": np.r_[3.0, np.zeros(n - 1)],
         "pi": np.r_[0.7, np.zeros(n - 1)], "dev_h_m": rng.normal(1700, 100, n), "dev_v_m": rng.normal(180, 10, n)}
    c["n_wait"] = np.full(n, 8 if wait else 0)
    c["n_no_wait"] = np.full(n, 1 if wait else 9)
    c["n_pilot_received"] = np.full(n, 92 if wait else 80)
    c["n_blend"] = np.full(n, 7 if wait else 0)
    c["n_blend_exact"] = np.full(n, 6 if wait else 0)
    c["n_blend_axis"] = c["n_blend"] - c["n_blend_exact"]
    c["n_daa_override"] = np.full(n, 0 if wait else 1)
    c["n_pilot_exec"] = c["n_pilot_received"] - c["n_blend"] - c["n_daa_override"]
    return pa.table(c)


@pytest.fixture
def results_dir(tmp_path):
    rng = np.random.default_rng(0)
    d = tmp_path / "camp"
    for g, wait in (("B-1", False), ("B-2", False), ("ID-2", True)):
        (d / g).mkdir(parents=True)
        pq.write_table(_group_table(g, 30, rng, wait, nmac=(g == "B-1")), d / g / "encounters-00000.parquet")
    return d


def test_report_renders_with_paper_columns(results_dir, tmp_path):
    out = write_report(results_dir, tmp_path / "rep")
    text = out.read_text()
    for f in FIGURES:
        assert (tmp_path / "rep" / f).stat().st_size > 1000
        assert f in text
    for title in ("Table 3", "Table 4", "Table 5", "Table 7", "Table 8", "Exact match"):
        assert title in text
    assert "87,153" in text and "921,993" in text and "2.81e-07" in text and "1,689" in text  # paper values
    # ID-2: no-wait 30 vs 270 in B-2 -> reduction 88.89 %; reception 2760 vs 2400 -> +15.00 %
    assert "88.89 %" in text and "15.00 %" in text
    assert "**DOES NOT HOLD**: 0 NMAC" in text  # we planted one NMAC in B-1
    assert "**HOLDS**: 0 DAA overrides" in text


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
