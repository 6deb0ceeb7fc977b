"""One encounter, one answer: every output of the DAA (bands, SM, the display's guidance) and of the
allocation agent for an encounter is bit for bit the same alone, inside a batch, and inside any
permutation or subset of that batch (docs/architecture.md, "Fast-time batches").

The batches are random (hypothesis) and are made to reach the batch-wide choices the DAA makes: several
intruders, intruders inside well clear, ownships at the speed limits (a speed axis with no candidate on
one side), exact head-ons, commands that change one, two or three axes, and the three presets
(``daidalus`` with its hysteresis carried over three agent steps). An encounter's bands are compared on
its own candidates: the columns of a batch's speed axis past an encounter's own candidates are not its
candidates. Checked to fail on main before batch invariance (3e5dc69): see the test docstrings.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from daa_sil.agent.memory import AgentMemory, PilotInput
from daa_sil.agent.wait_function import WaitValue
from daa_sil.agent.step import agent_step
from daa_sil.config.groups import policy_for_group
from daa_sil.daa import DaaConfig, compute_bands, safety_metric
from daa_sil.daa.bands import AxisBands
from daa_sil.geometry.kinematics import AircraftState, Command
from daa_sil.models.pilot_display import display_bands, guidance_values

PRESETS = ("do365", "paper", "daidalus")
#: the kinds of intruder an encounter is given (an exact head-on, one inside well clear, ...)
KINDS = ("head_on", "inside", "converging", "far")


def _encounters(seed: int, n: int, m: int, cfg: DaaConfig) -> tuple[AircraftState, AircraftState, Command]:
    """Ownships (N,) at or between the speed limits, intruders (N, M) of every kind, and a command each."""
    rng = np.random.default_rng(seed)
    gs = rng.choice([cfg.min_gs, cfg.max_gs, 55.0, np.nan], n)
    gs = np.where(np.isnan(gs), rng.uniform(cfg.min_gs, cfg.max_gs, n), gs)
    vs = rng.choice([cfg.max_vs, -cfg.max_vs, 0.0, np.nan], n)
    vs = np.where(np.isnan(vs), rng.uniform(-cfg.max_vs, cfg.max_vs, n), vs)
    trk = rng.choice([0.0, np.pi / 2, np.nan], n)
    trk = np.where(np.isnan(trk), rng.uniform(0, 2 * np.pi, n), trk)
    own = AircraftState(rng.normal(0, 200, n), rng.normal(0, 200, n), np.full(n, 1500.0), gs, trk, vs)
    kind = rng.choice(len(KINDS), (n, m))
    rng_m = np.select([kind == 0, kind == 1, kind == 2], [rng.uniform(1500, 7000, (n, m)), rng.uniform(50, 900, (n, m)),
                                                          rng.uniform(800, 6000, (n, m))], rng.uniform(9000, 20000, (n, m)))
    brg = np.where(kind == 0, trk[:, None], rng.uniform(0, 2 * np.pi, (n, m)))
    dz = np.where(kind == 0, 0.0, np.where(kind == 1, rng.uniform(-100, 100, (n, m)), rng.uniform(-400, 400, (n, m))))
    i_trk = np.where(kind == 0, trk[:, None] + np.pi, brg + np.pi + rng.normal(0, 0.25, (n, m)))
    i_vs = np.where(kind == 0, 0.0, rng.choice([0.0, 4.0, -4.0], (n, m)))
    intr = AircraftState(own.x[:, None] + rng_m * np.sin(brg), own.y[:, None] + rng_m * np.cos(brg),
                         1500.0 + dz, rng.choice([0.0, 30.0, 60.0, 90.0], (n, m)), np.mod(i_trk, 2 * np.pi), i_vs)
    cmd = Command(np.mod(trk + rng.choice([0.0, 0.4, -1.1, np.pi], n), 2 * np.pi),
                  rng.choice([0.0, 5.0, -12.0, cfg.max_vs, np.nan], n), rng.choice([cfg.min_gs, 55.0, 80.0, np.nan], n))
    return own, intr, cmd


def _same(a, b) -> bool:
    """Bit for bit (nan equal to nan, the sign of a zero counts)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.kind == "f":
        return bool(np.all((a == b) & (np.signbit(a) == np.signbit(b)) | (np.isnan(a) & np.isnan(b))))
    return bool(np.array_equal(a, b))


def _own_columns(batch: AxisBands, alone: AxisBands) -> slice:
    """The columns of a batch's axis that are the encounter's own candidates (aligned on the current value)."""
    start = batch.k0 - alone.k0
    return slice(start, start + alone.values.shape[1])


def _assert_same_axis(a: AxisBands, b: AxisBands, skip: tuple = ("axis",), *where) -> None:
    """Every field of two axes' bands bit for bit (fields in ``skip`` aside; both None counts as equal)."""
    for f in fields(AxisBands):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name in skip or (x is None and y is None):
            continue
        assert _same(np.asarray(x), np.asarray(y)), (*where, a.name, f.name)


def _assert_axis_row(alone: AxisBands, batch: AxisBands, i: int, what: str) -> None:
    cols = _own_columns(batch, alone)
    for f in fields(AxisBands):
        if f.name in ("axis", "side", "own_lo", "own_hi"):
            continue
        a = getattr(alone, f.name)
        if a is None:
            continue
        b = np.asarray(getattr(batch, f.name))[i]
        a = np.asarray(a)[0]
        if a.ndim:
            b = b[cols.start:cols.start + a.shape[0]]
        assert _same(a, b), f"{what}: {batch.name} {f.name} of row {i}: alone {a}, batch {b}"
    if getattr(batch, "own_lo", None) is not None:  # the batch says which columns are the row's own
        assert (batch.own_lo[i], batch.own_hi[i]) == (cols.start, cols.stop - 1), what


def _batches(n: int, rng) -> list:
    """(name, rows) of the batches an encounter is checked in: the batch, a permutation, a subset."""
    perm = rng.permutation(n)
    sub = np.sort(rng.choice(n, size=max(1, n // 2), replace=False))
    return [("batch", np.arange(n)), ("permutation", perm), ("subset", sub)]


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 31), preset=st.sampled_from(PRESETS), n=st.integers(2, 6), m=st.integers(1, 3))
def test_bands_sm_and_guidance_of_an_encounter_do_not_depend_on_its_batch(seed, preset, n, m):
    """compute_bands (every axis, every field), SM(u) and the display's guidance. On 3e5dc69 this fails at
    once: a speed axis has the batch's number of candidates, SM flies every command on the batch's knot
    grid and the undecided pieces are bisected to the batch's depth."""
    cfg = DaaConfig.for_preset(preset)
    own, intr, cmd = _encounters(seed, n, m, cfg)
    alone = [compute_bands(own[i:i + 1], intr[i:i + 1], cfg) for i in range(n)]
    sm_alone = [safety_metric(own[i:i + 1], intr[i:i + 1], cmd[i:i + 1], cfg) for i in range(n)]
    gd_alone = [guidance_values(display_bands(own[i:i + 1], intr[i:i + 1], cfg)) for i in range(n)]
    for what, rows in _batches(n, np.random.default_rng(seed + 1)):
        bands = compute_bands(own[rows], intr[rows], cfg)
        sm = safety_metric(own[rows], intr[rows], cmd[rows], cfg)
        gd = guidance_values(display_bands(own[rows], intr[rows], cfg))
        for pos, i in enumerate(rows):
            for ab_a, ab_b in zip(alone[i].axes(), bands.axes()):
                _assert_axis_row(ab_a, ab_b, pos, f"{preset} {what}")
            assert _same(sm_alone[i], sm[pos:pos + 1]), f"{preset} {what}: SM of row {i}"
            for key, val in gd_alone[i].items():
                assert _same(val, gd[key][pos:pos + 1]), f"{preset} {what}: guidance {key} of row {i}"


def _wait(w: float):
    return lambda own, intr, turn: WaitValue.constant(own.shape[0], w)


def _step_inputs(n: int, k: int, cmd: Command, own: AircraftState) -> PilotInput:
    """Step ``k``'s pilot input: a fresh command at steps 0 and 2 (the drawn one, then a hold), none at 1."""
    if k == 1:
        return PilotInput.nothing(n, link_alive_t=float(k))
    c = cmd if k == 0 else Command(own.trk.copy(), own.vs.copy(), own.gs.copy())
    t = float(k)
    return PilotInput(np.ones(n, bool), c, np.full(n, t - 1.0), np.full(n, t), np.full(n, t))


def _advance(state: AircraftState, dt: float) -> AircraftState:
    """Straight flight for ``dt`` s (the agent's inputs need not be a physical trajectory)."""
    v = state.velocity()
    return AircraftState(state.x + v[..., 0] * dt, state.y + v[..., 1] * dt, state.z + v[..., 2] * dt, state.gs,
                         state.trk, state.vs)


def _agent_run(own, intr, cmd, policy, cfg, w):
    """Three agent steps; returns per step (command flown, decision record, memory)."""
    n = own.shape[0]
    mem = AgentMemory.initial(n, own)
    out = []
    for k in range(3):
        c, dec, mem = agent_step(float(k), own, intr, _step_inputs(n, k, cmd, own), mem, policy, cfg, _wait(w))
        out.append((c, dec, mem))
        own, intr = _advance(own, 1.0), _advance(intr, 1.0)
    return out


def _assert_agent_row(alone, batch, pos: int, what: str) -> None:
    for k, ((ca, da, ma), (cb, db, mb)) in enumerate(zip(alone, batch)):
        for name in ("trk", "vs", "gs"):
            assert _same(getattr(ca, name), getattr(cb, name)[pos:pos + 1]), f"{what} step {k}: command {name}"
        for key in da:
            a, b = da[key], db[key]
            if a is None:
                assert b is None, f"{what} step {k}: {key}"
                continue
            assert _same(np.asarray(a), np.asarray(b)[pos:pos + 1]), f"{what} step {k}: {key}"
        for f in fields(AgentMemory):
            a, b = getattr(ma, f.name), getattr(mb, f.name)
            if f.name == "daa_state" or a is None:
                continue
            assert _same(a, np.asarray(b)[pos:pos + 1]), f"{what} step {k}: memory {f.name}"


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 31), preset=st.sampled_from(PRESETS), n=st.integers(2, 5), m=st.integers(1, 3),
       group=st.sampled_from(["B-1", "IC-1", "ID-2"]), w=st.sampled_from([0.0, 10.0]))
def test_agent_steps_of_an_encounter_do_not_depend_on_its_batch(seed, preset, n, m, group, w):
    """agent_step over three steps (a fresh command, none, a hold): the command flown, every field of the
    decision record (bands record, SM of the pilot's and the executed command, the blend's rule) and the
    memory. On 3e5dc69 this fails (SM(u) and the blend's candidate move with the batch)."""
    cfg = DaaConfig.for_preset(preset)
    own, intr, cmd = _encounters(seed, n, m, cfg)
    policy = policy_for_group(group)
    alone = [_agent_run(own[i:i + 1], intr[i:i + 1], cmd[i:i + 1], policy, cfg, w) for i in range(n)]
    for what, rows in _batches(n, np.random.default_rng(seed + 2)):
        batch = _agent_run(own[rows], intr[rows], cmd[rows], policy, cfg, w)
        for pos, i in enumerate(rows):
            _assert_agent_row(alone[i], batch, pos, f"{preset} {group} {what} row {i}")


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2 ** 31), preset=st.sampled_from(PRESETS), n=st.integers(1, 6), m=st.integers(1, 2),
       group=st.sampled_from(["B-1", "IC-1", "ID-2"]))
def test_sm_reused_within_a_step_equals_sm_computed_again(seed, preset, n, m, group, monkeypatch):
    """SM(u) is computed once per row, state and command in a step (the revert check's, the pilot's, the
    executed command's): every output equals that of an agent that computes each of them afresh."""
    import daa_sil.agent.step as agent_mod

    cfg = DaaConfig.for_preset(preset)
    own, intr, cmd = _encounters(seed, n, m, cfg)
    policy = policy_for_group(group)
    reused = _agent_run(own, intr, cmd, policy, cfg, 10.0)
    monkeypatch.setattr(agent_mod, "REUSE_SM", False)
    again = _agent_run(own, intr, cmd, policy, cfg, 10.0)
    for pos in range(n):
        _assert_agent_row([(c[pos:pos + 1], d, mm) for c, d, mm in _rows(again, pos)], reused, pos, f"{preset} {group}")


def _rows(run, pos):
    """One row's (command, decision record, memory) of each step of ``run``, as a run of that row alone."""
    out = []
    for c, d, mm in run:
        rec = {k: (None if v is None else np.asarray(v)[pos:pos + 1]) for k, v in d.items()}
        mem = AgentMemory(*(None if getattr(mm, f.name) is None or f.name == "daa_state" else
                            np.asarray(getattr(mm, f.name))[pos:pos + 1] for f in fields(AgentMemory)))
        out.append((c, rec, mem))
    return out


def test_cylinder_bands_on_the_one_pass_path_equal_the_evaluators(monkeypatch):
    """The ``daidalus`` preset (cylinder recovery): every row banded by the one-pass kernels, the saturated
    ones again on the evaluator's path, equals every row on the evaluator's path (``bands.FUSED = False``)."""
    import daa_sil.daa.bands as bands_mod

    cfg = DaaConfig.for_preset("daidalus")
    checked = 0
    for seed in (3, 4, 5):
        own, intr, _ = _encounters(seed, 24, 2, cfg)
        fused = compute_bands(own, intr, cfg)
        monkeypatch.setattr(bands_mod, "FUSED", False)
        ref = compute_bands(own, intr, cfg)
        monkeypatch.setattr(bands_mod, "FUSED", True)
        for a, b in zip(fused.axes(), ref.axes()):
            _assert_same_axis(a, b, ("axis", "own_lo", "own_hi"), seed)
            checked += int(np.sum(np.isfinite(np.asarray(a.recovery_time))))
    assert checked > 0  # (some rows did search a recovery)


def test_cylinder_recovery_search_compiled_equals_numpy(monkeypatch):
    """The bisection of the cylinder recovery time (``kernels.recovery.pivot_search_into``) against its numpy
    reference (``recovery.COMPILED = False``): every field of the daidalus preset's bands, on batches where
    rows do recover (and the conformance set's saturated encounters, below)."""
    import daa_sil.daa.recovery as recovery_mod
    from daa_sil.daa.conformance import read_records, states
    from pathlib import Path

    cfg = DaaConfig.for_preset("daidalus")
    recs = read_records(Path(__file__).resolve().parent / "data" / "daidalus_do365b.jsonl.xz")
    pick = [i for i, r in enumerate(recs) if r["track_recovery"]["recovery_bands_computed"]][:40]
    own_c, intr_c = states([recs[i] for i in pick])
    batches = [_encounters(seed, 24, 2, cfg)[:2] for seed in (3, 4)] + [(own_c, intr_c)]
    recovered = 0
    for own, intr in batches:
        got = compute_bands(own, intr, cfg)
        monkeypatch.setattr(recovery_mod, "COMPILED", False)
        ref = compute_bands(own, intr, cfg)
        monkeypatch.setattr(recovery_mod, "COMPILED", True)
        for a, b in zip(got.axes(), ref.axes()):
            _assert_same_axis(a, b)
            recovered += int(np.sum(np.isfinite(np.asarray(a.recovery_time))))
    assert recovered > 40


def test_cylinder_rows_compiled_equal_the_evaluators(monkeypatch):
    """The cylinder recovery's saturated rows made by the compiled search from their one-pass conflicts
    (``recovery.recover_rows``) against the same rows made again on the evaluator's path
    (``bands.CYLINDER_COMPILED = False``): every field, on the conformance set's encounters with a recovery
    band (batched and one at a time, as the SIL calls it) and on random batches, for the ``daidalus`` preset and
    its variants without the conflict lists' horizons, without shrinking below the first cylinder, and off the
    DAIDALUS grid."""
    import dataclasses

    import daa_sil.daa.bands as bands_mod
    from daa_sil.daa.conformance import read_records, states
    from pathlib import Path

    cfg = DaaConfig.for_preset("daidalus")
    recs = read_records(Path(__file__).resolve().parent / "data" / "daidalus_do365b.jsonl.xz")
    pick = [i for i, r in enumerate(recs) if r["track_recovery"]["recovery_bands_computed"]][:30]
    own_c, intr_c = states([recs[i] for i in pick])
    cases = [(cfg, own_c, intr_c)] + [(cfg, own_c[k:k + 1], intr_c[k:k + 1]) for k in range(0, len(pick), 3)]
    for seed, variant in ((3, {}), (4, {}), (5, {"horizon_from_maneuver": False}), (6, {"ca_bands": False}),
                          (7, {"daidalus_grid": False})):
        c = dataclasses.replace(cfg, **variant)
        cases.append((c, *_encounters(seed, 24, 1 + seed % 3, c)[:2]))
    recovered = 0
    for c, own, intr in cases:
        got = compute_bands(own, intr, c)
        monkeypatch.setattr(bands_mod, "CYLINDER_COMPILED", False)
        ref = compute_bands(own, intr, c)
        monkeypatch.setattr(bands_mod, "CYLINDER_COMPILED", True)
        for a, b in zip(got.axes(), ref.axes()):
            _assert_same_axis(a, b, ("axis",), own.shape)
            recovered += int(np.sum(np.asarray(a.recovery_nfactor) >= 0))
    assert recovered > 40  # (rows did search a recovery on the compiled path)


def test_sm_equals_the_first_entries_of_command_conflicts():
    """SM(u) reads only the first entries of the command's conflicts (``safety._command_first_entry``): the
    same numbers as ``command_conflicts(..., exits=False)``'s ``t_in`` (its general path, which also computes
    the exits), bit for bit, for every preset, several intruders, commands that change one, two or three
    axes or none, batched and one at a time."""
    from daa_sil.daa.safety import command_conflicts, sm_from_tin

    for preset in PRESETS:
        cfg = DaaConfig.for_preset(preset)
        for seed, m in ((11, 1), (12, 3)):
            own, intr, cmd = _encounters(seed, 30, m, cfg)
            horizon = cfg.sm_horizon_s
            t_in, _ = command_conflicts(own, intr, cmd, cfg, horizon + cfg.sm_margin_s, exits=False)
            want = sm_from_tin(t_in.min(axis=-1), horizon, cfg)
            assert _same(safety_metric(own, intr, cmd, cfg), want), (preset, seed)
            for k in range(0, 30, 7):
                assert _same(safety_metric(own[k:k + 1], intr[k:k + 1], cmd[k:k + 1], cfg), want[k:k + 1])
