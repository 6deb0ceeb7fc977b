"""The experiments behind the attribution table: paired comparisons across runs of one seed, the
authority-switch count by hand, the replay of an encounter, the page."""

import numpy as np
import pytest

from daa_sil.errors import UsageError
from daa_sil.study.analysis.counting import authority_switches
from daa_sil.study.analysis.experiment_analysis import compare, diff, value
from daa_sil.study.report.experiment_page import experiments_page
from daa_sil.study.campaign.experiments import RUNS, run_experiments


def test_authority_switches_by_hand():
    # encounter 0: wait, no_wait, pilot, (no decision: the pilot's), no_wait, then the pilot's again
    pos = np.array([0, 0, 0, 0, 1])
    t = np.array([0.0, 1.0, 2.0, 4.0, 3.0])
    dec = np.array(["wait", "no_wait", "pilot", "no_wait", "blend"])
    got = authority_switches(pos, t, dec, 3)
    # 0: steps 0..5 waiting, DAA, pilot, pilot, DAA, pilot = 4 changes between steps
    # 1: pilot until t = 3, DAA at 3, pilot after = 2; 2: no decision at all = 0
    assert list(got) == [4.0, 2.0, 0.0]


def test_an_experiment_run_compares_paired_on_the_same_encounters(tmp_path):
    with pytest.raises(UsageError, match="unknown experiment 'nope'"):
        run_experiments(tmp_path, 5, 6, 6, only=("nope",), log=lambda m: None)
    dirs = run_experiments(tmp_path, 5, 6, 6, 1, only=("blend-no-wait",), log=lambda m: None)
    d = dirs["blend-no-wait"]
    assert d.name == "exp-blend-no-wait-6" and (d / "campaign.json").is_file()
    res = compare([("ID-2", d, "ID-2"), ("no wait", d, "ID-2-no-wait")], ("wait", "no_wait", "received"),
                  replicates=200)
    assert res["n"] == 6
    assert value(res, "no wait", "wait") == 0.0  # w = 0: it never waits
    # the same encounters: a difference is the mean of the per-encounter differences
    assert diff(res, "no wait", "wait") == pytest.approx(-value(res, "ID-2", "wait"))
    page = experiments_page({"meta": {"seed": 5, "n_small": 6, "n_large": 6, "command": "x"},
                             "experiments": {"blend_waiting": {"title": "T", "why": "w", "runs": ["r"], **res}}})
    assert "## T" in page and "no wait − ID-2" in page
    assert max(line.count("|") - 1 for line in page.splitlines() if line.startswith("|")) <= 12


def test_every_run_names_what_it_tests():
    assert len({r.name for r in RUNS}) == len(RUNS)
    for r in RUNS:
        assert r.why and r.size in ("small", "large") and r.group_specs()


def test_what_is_flown_instead_of_the_command_by_hand(tmp_path):
    """The axes of the commands flown instead of the pilot's, counted from a hand-written decision table:
    a blend of a maneuver and of a 'hold' told apart by the pilot's intent, overrides and allocations on
    their own, the pilot's own executions left out."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from daa_sil.study.campaign.experiment_replays import executed_axes

    (tmp_path / "IC-1").mkdir()
    rows = [("pilot", "none", "none"), ("blend", "vertical", "vertical"), ("blend", "horizontal", "vertical"),
            ("blend", "none", "none"), ("blend", "none", "none"), ("blend", "none", "horizontal"),
            ("daa_override", "none", "horizontal"), ("no_wait", "none", "none")]
    dec, pax, eax = (list(c) for c in zip(*rows))
    sm = [5.0, 3.0, -1.0, 30.0, float("nan"), 2.0, 0.0, 30.0]  # SM of the command flown
    pq.write_table(pa.table({"group": ["IC-1"] * len(rows), "decision": dec, "pilot_axis": pax, "exec_axis": eax,
                             "sm_exec": sm}), tmp_path / "IC-1" / "decisions-00000.parquet")
    got = executed_axes(tmp_path, ["IC-1"])["IC-1"]
    assert got == {"blend of a maneuver": {"n": 2, "axes": {"vertical": 2}, "unsafe": 1},
                   "blend of a 'hold'": {"n": 3, "axes": {"none": 2, "horizontal": 1}, "unsafe": 1},
                   "DAA override": {"n": 1, "axes": {"horizontal": 1}, "unsafe": 1},
                   "DAA allocation": {"n": 1, "axes": {"none": 1}, "unsafe": 0}}
    page = experiments_page({"meta": {}, "experiments": {"exec_axes": {"title": "X", "why": "w", "runs": ["paper"],
                                                                       "groups": {"IC-1": got}}}})
    assert "| IC-1 | blend of a 'hold' | 3 | 67 % | 33 % | 0 % | 0 % | 33.3 % |" in page
