"""Encounter model (paper Table 6): distributions, CPA placement, determinism, Parquet I/O."""

import numpy as np
import pytest
from scipy import stats

from daa_sil.models import encounter_files as EF
from daa_sil.models import encounter_geometry as EG
from daa_sil.models import encounters as E
from daa_sil.models.intruder_flight import INTRUDER_PERFORMANCE
from daa_sil.errors import FileFormatError, UsageError
from daa_sil.geometry.kinematics import advance
from daa_sil.geometry.units import DEG
from daa_sil.geometry.wellclear import t_cpa


@pytest.fixture(scope="module")
def sample():
    return E.sample_encounters(600, seed=11)


def _tn(mu, sd, lo, hi):
    return stats.truncnorm((lo - mu) / sd, (hi - mu) / sd, loc=mu, scale=sd)


def test_candidate_marginals_match_truncated_laws():
    # the raw Table-6 draws (before geometry checks), many of them, against scipy's truncated laws
    cfg = E.EncounterConfig()
    rng = [np.random.default_rng(5)]
    d = {"z": np.concatenate([E._draw_round(rng, 1)["z"] for _ in range(3000)]),
         "u": np.concatenate([E._draw_round(rng, 1)["u"] for _ in range(3000)])}
    p = E._candidates(d, cfg)
    for key, law in (("speed_mps", _tn(100, 30, 70, 400)), ("vs_mps", _tn(0, 10, -10, 10)),
                     ("hma_deg", _tn(0, 110, -110, 110)), ("advance", _tn(0.5, 0.5, 0.0, 0.8))):
        x = p[key].ravel()
        se = law.std() / np.sqrt(x.size)
        assert abs(x.mean() - law.mean()) < 4 * se, key
        assert abs(x.std() - law.std()) < 0.05 * law.std(), key
    ia = p["ia_deg"].ravel()
    head_on = np.mean(ia == 180.0)
    assert abs(head_on - 0.30) < 4 * np.sqrt(0.3 * 0.7 / ia.size)
    rest = ia[ia != 180.0]
    assert rest.min() >= 0 and rest.max() < 180 and abs(rest.mean() - 90) < 3
    assert abs(p["hmd_m"].mean() - 1375) < 40 and p["hmd_m"].max() <= 2750
    assert abs(p["vmd_m"].mean()) < 25 and np.abs(p["vmd_m"]).max() <= 915
    assert np.abs(p["turn_rate_dps"]).max() <= 5


def test_sampled_set_within_table6_bounds(sample):
    p = sample.params
    assert np.all((p["speed_mps"] >= 70) & (p["speed_mps"] <= 400))
    assert np.all(np.abs(p["vs_mps"]) <= 10) and np.all(np.abs(p["hma_deg"]) <= 110)
    assert np.all((p["advance"] >= 0) & (p["advance"] <= 0.8))
    # conditioned on the geometry checks the speed mean stays near the truncated-law mean (108.6 m/s)
    assert abs(p["speed_mps"].mean() - _tn(100, 30, 70, 400).mean()) < 4.0
    assert np.allclose(sample.intr.gs, p["speed_mps"]) and np.allclose(sample.own.gs, 55.0)
    assert np.allclose(sample.own.trk, 0.0)


def test_straight_intruders_realise_the_sampled_cpa(sample):
    # analytic CPA from the initial states for intruders that have not turned before the CPA
    straight = sample.seg_start_s[:, 0, 0] >= 121.0
    assert straight.sum() > 50
    es = sample.subset(np.flatnonzero(straight))
    s = es.own.position() - es.intr[:, 0].position()
    v = es.own.velocity() - es.intr[:, 0].velocity()
    tc = t_cpa(s, v)
    np.testing.assert_allclose(tc, 120.0, atol=1e-6)
    p = s + tc[:, None] * v
    np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1]), es.params["hmd_m"][:, 0], atol=1e-6)
    np.testing.assert_allclose(-p[:, 2], es.params["vmd_m"][:, 0], atol=1e-6)


def test_turning_intruders_pass_cpa_check_with_simulator_dynamics(sample):
    turning = sample.intruder_turns
    assert turning.sum() > 50
    es = sample.subset(np.flatnonzero(turning)[:80])
    own, intr = es.own, es.intr
    best = np.full(len(es), np.inf)
    t_best = np.zeros(len(es))
    for k in range(240):  # the fast-time loop: 1 s steps, controls from the schedule
        w, a, av = es.intruder_controls(float(k))
        for _ in range(10):  # 0.1 s sub-samples of the same exact arcs
            own = advance(own, dt=0.1)
            intr = advance(intr, w, a, av, 0.1, INTRUDER_PERFORMANCE)
            r = np.hypot(own.x - intr.x[:, 0], own.y - intr.y[:, 0])
            better = r < best
            best, t_best = np.where(better, r, best), np.where(better, k + 0.1 * (_ + 1), t_best)
    assert np.all(np.abs(t_best - 120.0) <= 1.0)
    np.testing.assert_allclose(best, es.params["hmd_m"][:, 0], atol=1.0, rtol=1e-3)


def test_no_start_inside_warning_volume(sample):
    from daa_sil.geometry.wellclear import time_to_violation

    s = sample.own.position() - sample.intr[:, 0].position()
    v = sample.own.velocity() - sample.intr[:, 0].velocity()
    assert not np.isfinite(time_to_violation(s, v, "do365", 25.0)).any()


def test_chunking_does_not_change_encounters():
    a = E.sample_encounters(100, seed=7)
    b = E.concat_encounters([E.sample_encounters(50, seed=7), E.sample_encounters(50, seed=7, start=50)])
    for f in ("x", "y", "z", "gs", "trk", "vs"):
        assert np.array_equal(getattr(a.intr, f), getattr(b.intr, f))
    assert np.array_equal(a.seg_start_s, b.seg_start_s) and np.array_equal(a.seed, b.seed)
    c = E.sample_encounters(100, seed=8)
    assert not np.array_equal(a.intr.x, c.intr.x)


def test_multi_intruder_and_controls():
    es = E.sample_encounters(5, seed=2, n_intruders=3)
    assert es.intr.shape == (5, 3) and es.params["hmd_m"].shape == (5, 3)
    w, a, av = es.intruder_controls(float(es.seg_start_s[0, 1, 0]) + 0.5)
    assert w.shape == (5, 3) and w[0, 1] == es.seg_turn_rate[0, 1, 0] and np.all(a == 0)
    assert np.abs(w).max() <= 5 * DEG + 1e-12


def test_parquet_round_trip_bit_exact(tmp_path):
    es = E.sample_encounters(7, seed=3, n_intruders=2)
    path = EF.save_encounters(es, tmp_path / "e.parquet")
    back = EF.load_encounters(path)
    for f in ("x", "y", "z", "gs", "trk", "vs"):
        assert np.array_equal(getattr(es.intr, f), getattr(back.intr, f))
        assert np.array_equal(getattr(es.own, f), getattr(back.own, f))
    for k in es.params:
        assert np.array_equal(es.params[k], back.params[k], equal_nan=True)
    assert np.array_equal(es.seg_end_s, back.seg_end_s) and back.root_seed == 3 and np.array_equal(es.seed, back.seed)
    sub = back.subset([1, 3])
    assert np.array_equal(sub.encounter_id, [1, 3])


def test_bad_files_give_one_line_errors(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    bad = tmp_path / "junk.parquet"
    bad.write_bytes(b"not parquet at all")
    other = tmp_path / "other.parquet"
    pq.write_table(pa.table({"a": [1]}), other)
    es = E.sample_encounters(2, seed=1)
    good = EF.save_encounters(es, tmp_path / "good.parquet")
    t = pq.read_table(good)
    broken = tmp_path / "broken.parquet"
    pq.write_table(t.drop(["intr_x"]), broken)
    for path, word in ((tmp_path / "missing.parquet", "no such"), (bad, "not a readable"),
                       (other, "not a daa-sil encounter"), (broken, "intr_x")):
        with pytest.raises(FileFormatError) as ei:
            EF.load_encounters(path)
        assert word in str(ei.value) and "\n" not in str(ei.value)
    with pytest.raises(UsageError):
        E.sample_encounters(3, seed=-1)


def test_geometry_constructor_head_on_by_hand():
    es = EG.encounter_from_geometry(EG.IntruderGeometry(angle_deg=180, hmd_m=500, t_cpa_s=60, gs_mps=100, vmd_m=50))
    # head-on, closing 155 m/s: start 60*155 = 9300 m ahead, 500 m to the right (east), 50 m above
    assert es.intr.x[0, 0] == pytest.approx(500.0)
    assert es.intr.y[0, 0] == pytest.approx(9300.0)
    assert es.intr.z[0, 0] - es.own.z[0] == pytest.approx(50.0)
    assert es.intr.trk[0, 0] == pytest.approx(np.pi)
    left = EG.encounter_from_geometry(EG.IntruderGeometry(angle_deg=180, hmd_m=-500, t_cpa_s=60, gs_mps=100))
    assert left.intr.x[0, 0] == pytest.approx(-500.0)


@pytest.mark.parametrize("reading", ["paper", "feet"])
def test_a_campaign_samples_its_encounters_in_pieces_without_changing_them(reading):
    """The campaign samples its encounter set one piece per worker; the pieces concatenated are the set
    sampled at once, field by field (two intruders, so every (N, M) array is checked), under a reading
    in metres and one in feet (other HMD / VMD ranges)."""
    import concurrent.futures as cf

    from daa_sil.study.campaign.run import MIN_SAMPLE_PART, CampaignConfig, sample_campaign_encounters

    cfg = CampaignConfig(groups=("B-1",), n_encounters=2 * MIN_SAMPLE_PART + 37, seed=5, n_intruders=2,
                         reading=reading)
    whole = sample_campaign_encounters(cfg)
    with cf.ThreadPoolExecutor(2) as ex:
        pieces = sample_campaign_encounters(cfg, ex, parts=3)  # 1,037 encounters: two pieces of >= 500
    assert len(pieces) == len(whole) == cfg.n_encounters
    for f in ("x", "y", "z", "gs", "trk", "vs"):
        assert np.array_equal(getattr(whole.intr, f), getattr(pieces.intr, f))
        assert np.array_equal(getattr(whole.own, f), getattr(pieces.own, f))
    for k in E.SEGMENT_FIELDS:
        assert np.array_equal(getattr(whole, k), getattr(pieces, k), equal_nan=True)
    assert whole.params.keys() == pieces.params.keys()
    for k in whole.params:
        assert np.array_equal(whole.params[k], pieces.params[k], equal_nan=True), k
    assert np.array_equal(whole.encounter_id, pieces.encounter_id) and np.array_equal(whole.seed, pieces.seed)
