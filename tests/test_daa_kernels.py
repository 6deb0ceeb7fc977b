"""The compiled DAA kernels (daa_sil.daa.kernels) give exactly the numbers of their numpy references.

Identical, not close: every float output equal (nan where the reference has nan), every code and
flag equal, on random inputs and on adversarial ones -- components drawn from boundary values of
the thresholds (on DTHR, ZTHR, tangent lines, zero discriminants), zero and tiny speeds, single-
instant windows, zero-length pieces, nan, +-inf and huge values.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest

#: the adversarial inputs overflow and make nan on purpose
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

from daa_sil.daa import certify, intervals
from daa_sil.geometry.thresholds import get_thresholds

THRESHOLDS = [get_thresholds("do365"), get_thresholds("paper"), get_thresholds("daidalus"),
              get_thresholds("do365").with_(name="tcoa", tcoa=20.0),
              get_thresholds("do365").with_(name="cylinder", tthr=0.0, tcoa=0.0)]


def _special(th) -> np.ndarray:
    """Values at or next to the boundaries of ``th`` and the numeric edge cases."""
    D, H = th.dthr, th.zthr
    base = [0.0, -0.0, 1e-13, -1e-13, 1e-12, -1e-12, 1e-300, 1e300, -1e300, np.inf, -np.inf, np.nan,
            D, -D, H, -H, D * D, 0.5 * th.tthr, th.tthr, 1.0, -1.0]
    near = [np.nextafter(x, s) for x in (D, -D, H, -H) for s in (np.inf, -np.inf)]
    return np.array(base + near)


def _draw(rng, n: int, th, scale: float, p_special: float = 0.25) -> np.ndarray:
    """Random values of magnitude ``scale``, a fraction ``p_special`` replaced by special values."""
    x = rng.normal(0.0, scale, n)
    x[rng.random(n) < 0.1] = rng.uniform(-2.0, 2.0, int(np.count_nonzero(rng.random(n) < 0.1)) or 1)[0]
    sp = _special(th)
    pick = rng.random(n) < p_special
    x[pick] = sp[rng.integers(0, sp.size, int(pick.sum()))]
    return x


def _tangent(rng, n: int, th):
    """Relative states whose straight line grazes the DTHR circle (cross product = DTHR |v|) or starts on
    it, with vertical speeds that make the vertical window a single instant."""
    D, H = th.dthr, th.zthr
    w = rng.uniform(1.0, 300.0, n)
    ang = rng.uniform(0, 2 * np.pi, n)
    ux, uy = np.sin(ang), np.cos(ang)
    back = rng.uniform(0.0, 5e4, n)
    sx, sy = D * uy - back * ux, -D * ux - back * uy  # offset D perpendicular to the motion
    vx, vy = w * ux, w * uy
    sz = np.where(rng.random(n) < 0.5, H, rng.uniform(-2 * H, 2 * H, n))
    vz = np.where(rng.random(n) < 0.3, 0.0, rng.uniform(-20, 20, n))
    return sx, sy, sz, vx, vy, vz


def _ref(fn, *args):
    """The numpy reference (its warnings for nan / inf inputs are expected here)."""
    with np.errstate(all="ignore"):
        return fn(*args)


def _same(a, b) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape
    if a.dtype.kind == "f":
        bad = ~((a == b) | (np.isnan(a) & np.isnan(b)))
    else:
        bad = a != b
    assert not bad.any(), f"{int(bad.sum())} of {a.size} differ, first at {np.flatnonzero(bad)[:5]}: " \
                          f"{a[bad][:5]} vs {b[bad][:5]}"


def _states(rng, n, th):
    if rng.random() < 0.5:
        return tuple(_draw(rng, n, th, s) for s in (8000.0, 8000.0, 300.0, 150.0, 150.0, 10.0))
    return _tangent(rng, n, th)


@pytest.mark.parametrize("th", THRESHOLDS, ids=lambda t: t.name)
@pytest.mark.parametrize("seed", range(6))
def test_interval_soa_identical(th, seed):
    rng = np.random.default_rng(seed)
    n = 40_000
    comp = _states(rng, n, th)
    length = np.abs(_draw(rng, n, th, 100.0, 0.1))
    length[rng.random(n) < 0.05] = 0.0
    _same_pair(intervals.interval_soa(*comp, length, th), _ref(intervals.interval_soa_reference, *comp, length, th))
    # with the caller's vertical window (a single instant in some rows)
    lo = np.abs(_draw(rng, n, th, 20.0, 0.1))
    hi = np.where(rng.random(n) < 0.2, lo, lo + np.abs(rng.normal(0, 30, n)))
    hi[rng.random(n) < 0.1] = -np.inf
    got = intervals.interval_soa(*comp, length, th, (lo, hi))
    _same_pair(got, _ref(intervals.interval_soa_reference, *comp, length, th, (lo, hi)))


def _same_pair(got, ref):
    for g, r in zip(got, ref):
        _same(g, r)


@pytest.mark.parametrize("th", THRESHOLDS, ids=lambda t: t.name)
@pytest.mark.parametrize("seed", range(6))
def test_wcv_soa_identical(th, seed):
    rng = np.random.default_rng(100 + seed)
    comp = _states(rng, 40_000, th)
    _same(intervals.wcv_soa(*comp, th), _ref(intervals.wcv_soa_reference, *comp, th))


def _compiled_and_reference(monkeypatch, module, name: str, s, v, *args):
    """``(compiled, reference)`` results of ``module.<name>`` on the relative states ``s``, ``v`` (n, 3) laid out
    as (n,), (n / 8, 8) and one row; the reference ``<name>_reference`` is made to raise while the compiled
    function runs, so the pair cannot be the numpy code twice."""
    n = s.shape[0]

    def not_here(*_a, **_k):
        raise AssertionError("the numpy reference ran: the compiled path was not taken")

    for shape in ((n,), (n // 8, 8), (1,)):
        k = int(np.prod(shape))
        ss, vv = s[:k].reshape(shape + (3,)), v[:k].reshape(shape + (3,))
        want = _ref(getattr(module, f"{name}_reference"), ss, vv, *args)
        with monkeypatch.context() as m:
            m.setattr(module, f"{name}_reference", not_here)
            got = getattr(module, name)(ss, vv, *args)
        yield got, want


@pytest.mark.parametrize("th", THRESHOLDS[:3], ids=lambda t: t.name)
@pytest.mark.parametrize("seed", range(4))
def test_nmac_interval_identical(th, seed, monkeypatch):
    """The step's NMAC test (wellclear.nmac_interval over one step, compiled) against its numpy reference:
    relative states drawn at the NMAC cylinder's edges (500 ft, 100 ft, +-1 ulp), zero and tiny relative
    speeds, signed zeros, nan and inf; steps of 0, 1 and 2.5 s, (N, M) arrays and one row."""
    from daa_sil.daa import kernels
    from daa_sil.geometry import wellclear as wc

    kernels.get()
    rng = np.random.default_rng(300 + seed)
    n = 40_000
    edge = np.array([th.nmac_h, -th.nmac_h, th.nmac_v, -th.nmac_v] +
                    [np.nextafter(x, d) for x in (th.nmac_h, th.nmac_v) for d in (0.0, np.inf)])
    comp = []
    for scale in (300.0, 300.0, 60.0, 150.0, 150.0, 10.0):
        a = _draw(rng, n, th, scale)
        pick = rng.random(n) < 0.15
        a[pick] = edge[rng.integers(0, edge.size, int(pick.sum()))]
        comp.append(a)
    s, v = np.stack(comp[:3], axis=-1), np.stack(comp[3:], axis=-1)
    v[rng.random(n) < 0.1] = 0.0
    for t_end in (1.0, 0.0, 2.5):
        for got, want in _compiled_and_reference(monkeypatch, wc, "nmac_interval", s, v, th, t_end):
            _same_pair(got, want)
    hits = np.isfinite(_ref(wc.nmac_interval_reference, s, v, th, 1.0)[0]).sum()
    assert 100 < hits < n - 100  # both outcomes occur: the equality above is not vacuous


@pytest.mark.parametrize("th", THRESHOLDS, ids=lambda t: t.name)
@pytest.mark.parametrize("seed", range(4))
def test_encounter_geometry_identical(th, seed, monkeypatch):
    """The step's geometry (range, HMD, height difference, tau_mod, WCV; wellclear.encounter_geometry,
    compiled) against the numpy functions bit for bit (signed zeros too): adversarial states (the
    thresholds +-1 ulp, tangents to the DTHR circle, zero, tiny, huge, nan and inf), lookaheads 0, 55 s
    and inf, (N,), (N, M) and one row; the numpy reference is made to raise while the compiled one runs."""
    from daa_sil.daa import kernels
    from daa_sil.geometry import wellclear as wc

    kernels.get()
    rng = np.random.default_rng(500 + seed)
    n = 40_000
    drawn = [_draw(rng, n // 2, th, sc) for sc in (8000.0, 8000.0, 300.0, 150.0, 150.0, 10.0)]
    comp = [np.concatenate([a, b]) for a, b in zip(drawn, _tangent(rng, n - n // 2, th))]
    s, v = np.stack(comp[:3], axis=-1), np.stack(comp[3:], axis=-1)
    v[rng.random(n) < 0.05] = 0.0
    for lookahead in (55.0, 0.0, np.inf):
        for got, want in _compiled_and_reference(monkeypatch, wc, "encounter_geometry", s, v, th, lookahead):
            assert list(got) == list(want)
            for name in want:
                _bits_same(got[name], want[name])
    ref = _ref(wc.encounter_geometry_reference, s, v, th, 55.0)
    assert 100 < ref["wcv"].sum() < n - 100  # both outcomes occur: the equality above is not vacuous
    tau = ref["tau_mod_s"]
    assert (tau == 0).sum() > 100 and np.isnan(tau).sum() > 100 and (np.isfinite(tau) & (tau > 0)).sum() > 100


def _pieces(rng, n, th):
    """Chord pieces: start / end relative positions (end = start + h v + a curvature offset), duration,
    error bounds (arrays or 0.0) and true end velocities."""
    x0, y0, z0, vx, vy, vz = _states(rng, n, th)
    h = np.abs(_draw(rng, n, th, 2.0, 0.1))
    h[rng.random(n) < 0.05] = 0.0
    bend = rng.normal(0, 3.0, (3, n))
    x1, y1, z1 = x0 + h * vx + bend[0], y0 + h * vy + bend[1], z0 + h * vz + bend[2]
    acc = np.abs(_draw(rng, n, th, 3.0, 0.1))
    e_p, e_v = acc * h * h * 0.125, acc * h * 0.5
    e_z = 0.0 if rng.random() < 0.5 else np.abs(_draw(rng, n, th, 0.5, 0.1))
    u0 = (vx + rng.normal(0, 2, n), vy + rng.normal(0, 2, n))
    u1 = (vx + rng.normal(0, 2, n), vy + rng.normal(0, 2, n))
    return (x0, y0, z0, x1, y1, z1), h, e_p, e_v, e_z, u0, u1


@pytest.mark.parametrize("th", THRESHOLDS, ids=lambda t: t.name)
@pytest.mark.parametrize("seed", range(6))
def test_classify_pieces_identical(th, seed):
    rng = np.random.default_rng(200 + seed)
    n = 40_000
    ends, h, e_p, e_v, e_z, _, _ = _pieces(rng, n, th)
    _same(certify.classify_pieces(*ends, h, th, e_p, e_v, e_z),
          _ref(certify.classify_pieces_reference, *ends, h, th, e_p, e_v, e_z))
    lo = np.abs(_draw(rng, n, th, 2.0, 0.1))
    hi = np.where(rng.random(n) < 0.2, lo, lo + np.abs(rng.normal(0, 2, n)))
    hi[rng.random(n) < 0.1] = -np.inf
    _same(certify.classify_pieces(*ends, h, th, e_p, e_v, e_z, (lo, hi)),
          _ref(certify.classify_pieces_reference, *ends, h, th, e_p, e_v, e_z, (lo, hi)))


@pytest.mark.parametrize("th", THRESHOLDS, ids=lambda t: t.name)
@pytest.mark.parametrize("seed", range(6))
def test_clear_second_order_identical(th, seed):
    rng = np.random.default_rng(300 + seed)
    ends, h, e_p, e_v, e_z, u0, u1 = _pieces(rng, 40_000, th)
    _same(certify.clear_second_order(*ends, *u0, *u1, h, th, e_p, e_v, e_z),
          _ref(certify.clear_second_order_reference, *ends, *u0, *u1, h, th, e_p, e_v, e_z))


def _flip_points(ref, p_lo, p_hi):
    """Adjacent floats ``(a, b)`` per row with ``ref(a) != ref(b)`` between ``p_lo`` and ``p_hi`` (> 0), by
    bisection on the float's bits: the exact place where the reference's decision flips, where a
    kernel that rounds any operation differently decides differently."""
    a, b = p_lo.view(np.int64).copy(), p_hi.view(np.int64).copy()
    at_a = ref(a.view(float))
    keep = at_a != ref(b.view(float))
    a, b, at_a = a[keep], b[keep], at_a[keep]
    for _ in range(70):
        gap = b - a > 1
        if not gap.any():
            break
        mid = np.where(gap, a + (b - a) // 2, a)
        same = ref(mid.view(float), keep) == at_a
        a, b = np.where(gap & same, mid, a), np.where(gap & ~same, mid, b)
    return keep, a.view(float), b.view(float)


@pytest.mark.parametrize("th", THRESHOLDS[:3] + THRESHOLDS[4:], ids=lambda t: t.name)
@pytest.mark.parametrize("knob", ["scale", "e_p", "e_v", "h"])
def test_certificates_identical_at_their_flip_points(th, knob):
    """At the float where the reference's verdict flips (moving one input), the kernel decides the same
    on both sides and on the neighbouring floats."""
    rng = np.random.default_rng(zlib.crc32(f"{th.name}/{knob}".encode()))
    n = 4000
    ends, h, e_p, e_v, e_z, u0, u1 = _pieces(rng, n, th)
    base = dict(ends=ends, h=h, e_p=e_p, e_v=e_v)

    def args(value, rows):
        d = {k: (tuple(c[rows] for c in v) if isinstance(v, tuple) else v[rows]) for k, v in base.items()}
        if knob == "scale":
            x0, y0, z0, x1, y1, z1 = d["ends"]
            d["ends"] = (x0 * value, y0 * value, z0, x1 * value, y1 * value, z1)
        else:
            d[knob] = value
        return d

    flips = {"classify": 0, "clear2": 0}
    for name, fn, ref_fn in (("classify", certify.classify_pieces, certify.classify_pieces_reference),
                             ("clear2", certify.clear_second_order, certify.clear_second_order_reference)):
        def call(f, value, rows=None):
            rows = np.arange(n) if rows is None else rows
            d = args(value, rows)
            ez = e_z if np.ndim(e_z) == 0 else e_z[rows]
            if name == "classify":
                return f(*d["ends"], d["h"], th, d["e_p"], d["e_v"], ez)
            return f(*d["ends"], *(c[rows] for c in u0 + u1), d["h"], th, d["e_p"], d["e_v"], ez)

        lo, hi = (np.full(n, 1e-3), np.full(n, 1e3)) if knob == "scale" else (np.full(n, 1e-9), np.full(n, 1e4))
        keep, a, b = _flip_points(lambda v, rows=None: _ref(call, ref_fn, v, rows), lo, hi)
        rows = np.flatnonzero(keep)
        if knob in ("scale", "e_p"):  # (the other knobs flip few rows, or none on some seeds)
            assert rows.size >= 100, f"{name}/{knob}: too few flips to test ({rows.size})"
        flips[name] += rows.size
        for k in range(-2, 3):
            v = np.nextafter(a, np.inf) if k > 0 else a
            for _ in range(abs(k) - (k > 0)):
                v = np.nextafter(v, np.inf if k > 0 else -np.inf)
            _same(call(fn, v, rows), _ref(call, ref_fn, v, rows))
        _same(call(fn, b, rows), _ref(call, ref_fn, b, rows))


def test_kernel_outcomes_are_not_trivial():
    """The inputs above reach every outcome (so the comparisons exercise each branch)."""
    th = THRESHOLDS[0]
    rng = np.random.default_rng(7)
    ends, h, e_p, e_v, e_z, u0, u1 = _pieces(rng, 40_000, th)
    codes = certify.classify_pieces(*ends, h, th, e_p, e_v, e_z)
    assert set(np.unique(codes)) == {certify.CLEAR, certify.INSIDE, certify.UNDECIDED}
    clear = certify.clear_second_order(*ends, *u0, *u1, h, th, e_p, e_v, e_z)
    assert clear.any() and not clear.all()
    comp = _states(np.random.default_rng(8), 40_000, th)
    t_in, t_out = intervals.interval_soa(*comp, np.full(40_000, 180.0), th)
    assert np.isfinite(t_in).any() and np.isinf(t_in).any() and (t_in == 0).any()
    flags = intervals.wcv_soa(*comp, th)
    assert flags.any() and not flags.all()


# --------------------------------------------------------------------------------------------------
# the evaluator's compiled passes against its numpy reference, on real maneuver paths
# --------------------------------------------------------------------------------------------------
from daa_sil.daa import DaaConfig  # noqa: E402
from daa_sil.daa.axis_paths import maneuver_paths, candidate_counts  # noqa: E402
from daa_sil.daa.config import AXIS_HORIZONTAL, AXIS_SPEED, AXIS_VERTICAL  # noqa: E402
from daa_sil.daa.kernels.unfused import command_rel_states_into, rel_states_into  # noqa: E402
from daa_sil.daa.safety import command_paths  # noqa: E402
from daa_sil.daa.trajectory import PathEvaluator  # noqa: E402
from daa_sil.geometry.kinematics import AircraftState, Command  # noqa: E402


def _encounters(rng, n: int, m: int, cfg):
    """Ownships at the axis limits or anywhere, intruders converging from 1-9 km, some level with the
    ownship, some ZTHR above or below it, some standing still, some with nan or huge states."""
    own = AircraftState(rng.normal(0, 100, n), rng.normal(0, 100, n), np.full(n, 1000.0),
                        rng.choice([cfg.min_gs, cfg.max_gs, 55.0, 30.0, 120.0], n), rng.uniform(0, 2 * np.pi, n),
                        rng.choice([0.0, cfg.max_vs, -cfg.max_vs, 3.0, -7.5], n))
    rng_m = rng.uniform(1000, 9000, (n, m))
    brg = rng.uniform(-np.pi, np.pi, (n, m))
    dz = rng.choice([0.0, cfg.th.zthr, -cfg.th.zthr, 50.0, -300.0, 600.0], (n, m)) + rng.normal(0, 1, (n, m)) * (
        rng.random((n, m)) < 0.5)
    gs = rng.choice([0.0, 40.0, 80.0, 150.0, 250.0], (n, m))
    intr = AircraftState(own.x[:, None] + rng_m * np.sin(brg), own.y[:, None] + rng_m * np.cos(brg),
                         1000.0 + dz, gs, brg + np.pi + rng.normal(0, 0.3, (n, m)), rng.choice([0.0, 5.0, -5.0], (n, m)))
    odd = rng.random(n) < 0.03
    intr.x[odd, 0] = np.nan
    intr.y[rng.random(n) < 0.02, 0] = 1e12
    return own, intr


def _same_conflicts(a, b):
    for name in ("seg_in", "seg_out", "tail_in", "tail_out"):
        _same(getattr(a, name), getattr(b, name))


@pytest.mark.parametrize("preset", ["do365", "paper", "daidalus"])
@pytest.mark.parametrize("axis", [AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_SPEED])
def test_band_paths_evaluate_identical(preset, axis):
    """Tails, certificates, undecided pieces (bisection on the compiled state) and candidates of every band
    axis, for the corrective volume, the preventive one and a recovery cylinder."""
    cfg = DaaConfig.for_preset(preset)
    rng = np.random.default_rng(zlib.crc32(f"{preset}/{axis}".encode()))
    own, intr = _encounters(rng, 400, 2, cfg)
    j_lo, j_hi = candidate_counts(own, axis, cfg)
    paths, _ = maneuver_paths(own, axis, cfg, max(j_lo, j_hi), with_values=False)
    cyl = cfg.th.with_(name="cylinder", dthr=1000.0, zthr=100.0, tthr=0.0, tcoa=0.0)
    for th in (cfg.th, cfg.th_preventive, cyl):
        got = PathEvaluator(paths, intr, cfg.lookahead_s).evaluate(th)
        ref = _ref(PathEvaluator(paths, intr, cfg.lookahead_s).evaluate_reference, th)
        _same_conflicts(got, ref)
        for g, r in zip(got.candidates(), _ref(ref.candidates_reference)):
            _same(g, r)
        assert np.isfinite(ref.seg_in).any() and np.isfinite(ref.tail_in).any()
    sub = np.flatnonzero(rng.random(own.shape[0]) < 0.5)  # a subset (the recovery search evaluates those)
    _same_conflicts(PathEvaluator(paths.subset(sub), intr[sub], 100.0).evaluate(cfg.th),
                    _ref(PathEvaluator(paths.subset(sub), intr[sub], 100.0).evaluate_reference, cfg.th))


@pytest.mark.parametrize("preset", ["do365", "daidalus"])
def test_command_paths_evaluate_identical(preset):
    """SM's paths (a command on up to three axes at once): last tails only, no exits."""
    cfg = DaaConfig.for_preset(preset)
    rng = np.random.default_rng(11)
    own, intr = _encounters(rng, 600, 2, cfg)
    n = own.shape[0]
    cmd = Command(own.trk + rng.choice([0.0, 0.3, -1.2, np.pi], n), rng.choice([0.0, 10.0, -20.0, np.nan], n),
                  rng.choice([40.0, 55.0, 90.0, np.nan], n))
    paths = command_paths(own, cmd, cfg)
    for exits in (False, True):
        got = PathEvaluator(paths, intr, 85.0, tails="last", exits=exits).evaluate(cfg.th)
        ref = _ref(PathEvaluator(paths, intr, 85.0, tails="last", exits=exits).evaluate_reference, cfg.th)
        _same_conflicts(got, ref)
        _same_pair(got.prefix(), ref.prefix())


@pytest.mark.parametrize("axis", [AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_SPEED])
def test_axis_state_kernel_identical(axis):
    """The compiled ownship state on a band path equals the paths' numpy ``state_at`` at any time
    (including before the start, at the speed limit and past it)."""
    for preset in ("do365", "daidalus"):
        cfg = DaaConfig.for_preset(preset)
        rng = np.random.default_rng(axis)
        own, _ = _encounters(rng, 2000, 1, cfg)
        paths, _ = maneuver_paths(own, axis, cfg, 10, with_values=False)
        n_idx, p_idx = rng.integers(0, 2000, 20_000), rng.integers(0, 2, 20_000)
        t = np.concatenate([rng.uniform(-5, 200, 19_000), rng.choice([0.0, 1e-9, 1e6, np.inf, np.nan], 1000)])
        ref = _ref(lambda: paths.state_at(n_idx, p_idx)(t))
        _, code, rate, kin = paths.kin
        out = np.empty((6, t.size))
        rel_states_into(code, rate, kin[n_idx, p_idx], np.zeros((t.size, 6)), t, out)
        with np.errstate(all="ignore"):  # relative to an intruder at rest at the origin, as the numpy mover does
            rel = [r - (0.0 + t * 0.0) for r in ref[:3]] + [r - 0.0 for r in ref[3:]]
        for g, r in zip(out, rel):
            _same(g, np.broadcast_to(r, t.shape).astype(float))


def test_command_state_kernel_identical():
    """The compiled ownship state flying a command (SM) equals the numpy one (``_CommandMotion.state``) at
    any time: during the turn and speed change, after either ends, after both, at the vertical target."""
    cfg = DaaConfig.for_preset("do365")
    rng = np.random.default_rng(21)
    own, _ = _encounters(rng, 3000, 1, cfg)
    n = own.shape[0]
    cmd = Command(own.trk + rng.choice([0.0, 0.3, -1.2, np.pi, -np.pi, 2.5], n), rng.choice([0.0, 10.0, -20.0, np.nan], n),
                  rng.choice([20.0, 40.0, 55.0, 90.0, 150.0, np.nan], n))
    paths = command_paths(own, cmd, cfg)
    assert paths.kin is not None
    idx = rng.integers(0, n, 30_000)
    t = np.concatenate([rng.uniform(0, 100, 29_000), rng.choice([0.0, 1e-9, 1e5, np.inf, np.nan, -1.0], 1000)])
    ref = _ref(lambda: paths.state_at(idx, np.zeros_like(idx))(t))
    _, phases, enc, *perf = paths.kin
    out = np.empty((6, t.size))
    command_rel_states_into(phases[idx], enc[idx], *perf, np.zeros((t.size, 6)), t, out)
    with np.errstate(all="ignore"):
        rel = [r - (0.0 + t * 0.0) for r in ref[:3]] + [r - 0.0 for r in ref[3:]]
    for g, r in zip(out, rel):
        _same(g, np.broadcast_to(r, t.shape).astype(float))


# --------------------------------------------------------------------------------------------------
# the undecided pieces' loop (kernels.resolve) against the numpy loop it replaces
# --------------------------------------------------------------------------------------------------
from daa_sil.daa import undecided  # noqa: E402
from daa_sil.daa.kernels import resolve_parts as resolve_kernel  # noqa: E402


def test_bisection_halvings_are_numpys_log2():
    """The kernel's count of halvings is ``int(np.ceil(np.log2(max(w, dt) / dt)))`` exactly, next to every
    power of two (where a log2 that rounded its last bit differently would give another count)."""
    thr = undecided.bisect_thresholds()
    rng = np.random.default_rng(5)
    widths = [0.0, -1.0, 0.04, 0.1, 1e-300, 300.0, 1e6]
    for dt in (undecided.BISECT_DT_IN, undecided.BISECT_DT_OUT, 0.01, 0.3):
        for n in range(0, 40):
            x = dt * 2.0 ** n
            widths += [x, np.nextafter(x, 0), np.nextafter(x, np.inf), np.nextafter(np.nextafter(x, np.inf), np.inf)]
        widths += list(rng.uniform(0, 500, 300)) + list(dt * 2.0 ** rng.uniform(0, 30, 300))
    for dt in (undecided.BISECT_DT_IN, undecided.BISECT_DT_OUT, 0.01, 0.3):
        for w in widths:
            ref = int(np.ceil(np.log2(max(np.max(np.array([w]), initial=0.0), dt) / dt)))
            assert resolve_kernel.halvings(np.max(np.array([w]), initial=0.0), dt, thr) == ref, (w, dt)


def _resolved_three_ways(paths, intr, th, t_end, **kw):
    """Conflicts with the fused kernel, with the numpy loop over compiled pieces, with the numpy reference."""
    out = []
    for compiled, fused in ((True, True), (True, False), (False, False)):
        ev = PathEvaluator(paths, intr, t_end, **kw)
        ev.fused = fused
        out.append(ev.evaluate(th) if compiled else _ref(ev.evaluate_reference, th))
    return out


def _small_volumes(cfg):
    """A well-clear volume, a small cylinder (short clips: sampled every CLIP_DT) and a tiny volume with
    a short TTHR, so that pieces are split to the last depth."""
    return (cfg.th, cfg.th.with_(name="small", dthr=60.0, zthr=15.0, tthr=0.0, tcoa=0.0),
            cfg.th.with_(name="tiny", dthr=152.0, zthr=30.0, tthr=3.0, tcoa=0.0))


@pytest.mark.parametrize("preset", ["do365", "daidalus"])
@pytest.mark.parametrize("axis", [AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_SPEED])
def test_resolve_kernel_identical_on_close_encounters(preset, axis):
    """Intruders 150-2500 m away, so that most of the undecided pieces are crossings, clips and splits:
    the fused kernel gives the numpy loop's intervals, which it changes in many segments."""
    cfg = DaaConfig.for_preset(preset)
    rng = np.random.default_rng(zlib.crc32(f"resolve/{preset}/{axis}".encode()))
    own, intr = _encounters(rng, 300, 2, cfg)
    d = rng.uniform(150, 2500, intr.shape) / np.hypot(intr.x - own.x[:, None], intr.y - own.y[:, None])
    with np.errstate(invalid="ignore"):
        intr = AircraftState(own.x[:, None] + (intr.x - own.x[:, None]) * d, own.y[:, None] + (intr.y - own.y[:, None]) * d,
                             intr.z, intr.gs, intr.trk, intr.vs)
    j_lo, j_hi = candidate_counts(own, axis, cfg)
    paths, _ = maneuver_paths(own, axis, cfg, max(j_lo, j_hi), with_values=False)
    resolved = 0
    for th in _small_volumes(cfg):
        fused, loop, ref = _resolved_three_ways(paths, intr, th, cfg.lookahead_s)
        _same_conflicts(fused, loop)
        _same_conflicts(fused, ref)
        ends = np.broadcast_to(paths.knot_times()[:, None, :, 1:], fused.seg_out.shape)
        resolved += int(np.count_nonzero(np.isfinite(fused.seg_out) & (fused.seg_out != ends)))
    assert resolved > 100  # the bisection placed that many exits inside a segment


@pytest.mark.parametrize("exits", [False, True])
def test_resolve_kernel_identical_on_command_paths(exits):
    """SM's paths (turn, speed and vertical change at once, with a kink) against close intruders."""
    cfg = DaaConfig.for_preset("do365")
    rng = np.random.default_rng(31 + exits)
    own, intr = _encounters(rng, 500, 2, cfg)
    d = rng.uniform(150, 2500, intr.shape) / np.hypot(intr.x - own.x[:, None], intr.y - own.y[:, None])
    with np.errstate(invalid="ignore"):
        intr = AircraftState(own.x[:, None] + (intr.x - own.x[:, None]) * d, own.y[:, None] + (intr.y - own.y[:, None]) * d,
                             intr.z, intr.gs, intr.trk, intr.vs)
    n = own.shape[0]
    cmd = Command(own.trk + rng.choice([0.0, 0.3, -1.2, np.pi], n), rng.choice([0.0, 10.0, -20.0, np.nan], n),
                  rng.choice([40.0, 55.0, 90.0, np.nan], n))
    paths = command_paths(own, cmd, cfg)
    assert paths.kin is not None
    for th in _small_volumes(cfg):
        fused, loop, ref = _resolved_three_ways(paths, intr, th, 85.0, tails="last", exits=exits)
        _same_conflicts(fused, loop)
        _same_conflicts(fused, ref)


# --------------------------------------------------------------------------------------------------
# straight-line alerting through the compiled interval, against wellclear.violation_interval
# --------------------------------------------------------------------------------------------------
from daa_sil.daa import alerting  # noqa: E402


@pytest.mark.parametrize("preset", ["do365", "paper", "daidalus"])
def test_alerting_identical_to_violation_interval(preset, monkeypatch):
    """Alert levels (with and without early alerting times), conflict lists and ProjL computed through
    :func:`intervals.interval_soa` equal those from ``wellclear.violation_interval``, on encounters near
    and far, with nan and huge states."""
    cfg = DaaConfig.for_preset(preset)
    rng = np.random.default_rng(zlib.crc32(f"alerting/{preset}".encode()))
    own, intr = _encounters(rng, 3000, 3, cfg)
    d = rng.uniform(0.02, 6.0, intr.shape)
    with np.errstate(invalid="ignore"):
        intr = AircraftState(own.x[:, None] + (intr.x - own.x[:, None]) * d, own.y[:, None] + (intr.y - own.y[:, None]) * d,
                             intr.z, intr.gs, intr.trk, intr.vs)
    prev = rng.integers(0, 4, intr.shape)

    def every():
        with np.errstate(all="ignore"):
            return (alerting.alert_levels(own, intr, cfg), alerting.alert_levels(own, intr, cfg, prev=prev),
                    *alerting.conflict_lists(own, intr, cfg, early_level=prev), alerting.proj_lowc(own, intr, cfg),
                    alerting.proj_lowc(own, intr, cfg, horizon_s=0.0))
    got = every()
    monkeypatch.setattr(alerting, "COMPILED", False)
    ref = every()
    for g, r in zip(got, ref):
        _same(g, r)
    assert set(np.unique(ref[0])) == {0, 1, 2, 3} and ref[2].any() and ref[4].any() and not ref[4].all()


@pytest.mark.parametrize("preset", ["do365", "daidalus"])
def test_relative_knots_identical(preset):
    """The evaluator's relative states at the knots (compiled) equal the numpy broadcast, on band paths
    of every axis, SM's command paths, and knot states with nan, inf and huge values."""
    cfg = DaaConfig.for_preset(preset)
    rng = np.random.default_rng(zlib.crc32(f"knots/{preset}".encode()))
    own, intr = _encounters(rng, 300, 3, cfg)
    ipos, ivel = intr.position(), intr.velocity()
    cases = []
    for axis in (AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_SPEED):
        paths, _ = maneuver_paths(own, axis, cfg, 12, with_values=False)
        cases.append(paths)
    cases.append(command_paths(own, Command(own.trk + 0.5, own.vs * 0 + 5.0, own.gs * 0 + 60.0), cfg))
    th = cfg.th
    for paths in cases:
        shape = (own.shape[0], intr.shape[1]) + paths.shape[1:]
        args = (*paths.knot_states(), paths.knot_times(), ipos, ivel, shape)
        for g, r in zip(intervals.relative_at_knots(*args), _ref(intervals.relative_at_knots_reference, *args)):
            for a, b in zip(g, r):
                _same(a, b)
        if paths.kin[0] == "axis":  # the evaluator's, from the band paths' motion without their knot states
            fresh = maneuver_paths(own, paths.kin[1], cfg, 12, with_values=False)[0]
            assert fresh.pos is None
            for g, r in zip(PathEvaluator(fresh, intr, 60.0).s + PathEvaluator(fresh, intr, 60.0).v,
                            _ref(intervals.relative_at_knots_reference, *args)[0] +
                            _ref(intervals.relative_at_knots_reference, *args)[1]):
                _same(g, r)
    n, m, p, k = 50, 2, 3, 7
    shape = (n, m, p, k)
    pos = [_draw(rng, n * p * k, th, 5000.0).reshape(n, p, k) for _ in range(3)]
    vel = [_draw(rng, n * p, th, 100.0).reshape(n, p, 1) for _ in range(3)]  # broadcast along the knots
    t = np.abs(_draw(rng, k, th, 50.0))
    ip, iv = _draw(rng, n * m * 3, th, 5000.0).reshape(n, m, 3), _draw(rng, n * m * 3, th, 100.0).reshape(n, m, 3)
    args = (pos, vel, t, ip, iv, shape)
    for g, r in zip(intervals.relative_at_knots(*args), _ref(intervals.relative_at_knots_reference, *args)):
        for a, b in zip(g, r):
            _same(a, b)


def _bits_same(a, b) -> None:
    """``a`` and ``b`` bit for bit (signed zeros included); two nans are equal whatever their sign."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape, (a.dtype, a.shape, b.dtype, b.shape)
    if a.dtype.kind != "f":
        assert np.array_equal(a, b)
        return
    bad = (a.view(np.uint64) != b.view(np.uint64)) & ~(np.isnan(a) & np.isnan(b))
    assert not bad.any(), f"{int(bad.sum())} of {a.size} differ, first at {np.flatnonzero(bad)[:5]}: " \
                          f"{a[bad][:5]} vs {b[bad][:5]}"


def _same_command_paths(got, ref) -> None:
    """Every field of two SM paths bit for bit: knot states and times, the acceleration, jerk and kink
    bounds, each path's last knot, whether its vertical speed is constant, and the motion handed to the
    kernels."""
    for g, r in zip(got.pos + got.vel, ref.pos + ref.vel):
        _bits_same(g, r)
    for name in ("t", "acc_h", "acc_v", "jerk_h", "kink_t"):
        _bits_same(getattr(got, name), getattr(ref, name))
    np.testing.assert_array_equal(got.vz_const, ref.vz_const)
    np.testing.assert_array_equal(got.n_seg, ref.n_seg)
    assert got.kin[0] == ref.kin[0] == "command" and got.kin[3:] == ref.kin[3:]
    _bits_same(got.kin[1], ref.kin[1])
    _bits_same(got.kin[2], ref.kin[2])


def _command_batch(rng, own, cfg):
    n = own.shape[0]
    return Command(own.trk + rng.choice([0.0, -0.0, 0.3, -1.2, np.pi, -np.pi, 2.5, 1e-7, 1e-12, np.nan], n),
                   rng.choice([0.0, 10.0, -20.0, 1e3, -1e3, cfg.max_vs, np.nan], n),
                   rng.choice([20.0, 40.0, 55.0, 90.0, 400.0, cfg.min_gs, cfg.max_gs, -5.0, np.nan], n))


@pytest.mark.parametrize("preset", ["do365", "daidalus"])
def test_command_paths_identical(preset, monkeypatch):
    """SM's paths: the compiled plan (``kernels.command_plan``) and knot states equal the numpy plan and
    ``_CommandMotion.state`` bit for bit (turns of up to 180 deg both ways, -0.0 and tiny track changes,
    speed and vertical changes beyond the limits, commands with nan axes, ownships at the limits, nan
    states), for batches and for N = 1 (the SIL). The numpy plan is made to raise while the compiled
    one runs, so the comparison cannot be the numpy code against itself."""
    from daa_sil.daa import safety

    cfg = DaaConfig.for_preset(preset)
    rng = np.random.default_rng(zlib.crc32(f"cmdknots/{preset}".encode()))
    own, _ = _encounters(rng, 2000, 1, cfg)
    own.trk[rng.random(2000) < 0.01] = np.nan
    own.gs[rng.random(2000) < 0.01] = np.nan
    cmd = _command_batch(rng, own, cfg)
    singles = [(own[i:i + 1], cmd[i:i + 1]) for i in rng.choice(2000, 40, replace=False)]

    def no_numpy(*a):
        raise AssertionError("the numpy plan ran")

    with monkeypatch.context() as m:
        m.setattr(safety, "command_paths_reference", no_numpy)
        got = command_paths(own, cmd, cfg)
        got_1 = [command_paths(o, c, cfg) for o, c in singles]
    assert got.kin is not None and got.pos[0].shape[-1] > 10
    _same_command_paths(got, _ref(safety.command_paths_reference, own, cmd, cfg))
    monkeypatch.setattr(safety, "COMPILED", False)  # the numpy plan and the numpy motion
    _same_command_paths(got, _ref(command_paths, own, cmd, cfg))
    for g, (o, c) in zip(got_1, singles):
        _same_command_paths(g, _ref(command_paths, o, c, cfg))


@pytest.mark.parametrize("preset", ["do365", "daidalus"])
@pytest.mark.parametrize("axis", [AXIS_HORIZONTAL, AXIS_VERTICAL, AXIS_SPEED])
def test_axis_knot_states_identical(preset, axis, monkeypatch):
    """The band paths' knot states from the compiled axis motion equal the numpy closed forms (the turn's
    two-sided form included), ownships at and beyond the axis limits, nan and huge states."""
    from daa_sil.daa import axis_paths

    cfg = DaaConfig.for_preset(preset)
    rng = np.random.default_rng(zlib.crc32(f"axisknots/{preset}/{axis}".encode()))
    own, _ = _encounters(rng, 1500, 1, cfg)
    own.gs[rng.random(1500) < 0.02] = np.nan
    own.vs[rng.random(1500) < 0.02] = 1e300
    j = 25  # (the counts of a batch with nan / huge speeds are not defined)
    got, _ = maneuver_paths(own, axis, cfg, j, with_values=False)
    monkeypatch.setattr(axis_paths, "COMPILED", False)
    ref, _ = _ref(maneuver_paths, own, axis, cfg, j, False)
    shape = got.shape
    for g, r in zip(sum(got.knot_states(), ()), ref.pos + ref.vel):
        _same(g, np.broadcast_to(r, shape).astype(float))
    assert shape[-1] > 5


# --------------------------------------------------------------------------------------------------
# an axis's regions, recovery and resolutions (band_regions) against axis_bands in numpy
# --------------------------------------------------------------------------------------------------
import dataclasses  # noqa: E402

from daa_sil.daa import bands as bands_mod  # noqa: E402


def _band_configs():
    """Every preset with the earliest-exit recovery: as they are, and DAIDALUS's grid and conflict
    lists with it (the compiled pass covers both; the cylinder recovery stays in numpy)."""
    out = [DaaConfig.for_preset(p) for p in ("do365", "paper")]
    out.append(dataclasses.replace(DaaConfig.for_preset("daidalus"), recovery="earliest_exit"))
    out.append(dataclasses.replace(DaaConfig.for_preset("do365"), daidalus_grid=True))
    out.append(dataclasses.replace(DaaConfig.for_preset("paper"), horizon_from_maneuver=True))
    return out


@pytest.mark.parametrize("case", range(5))
@pytest.mark.parametrize("m", [0, 1, 3])
def test_axis_regions_identical(case, m, monkeypatch):
    """Bands of every axis (values, regions, gap regions, recovery, resolutions, preferred sides) from the
    compiled tail equal axis_bands in numpy, on near and far intruders, with nan and huge states and
    with no intruder at all."""
    cfg = _band_configs()[case]
    rng = np.random.default_rng(zlib.crc32(f"regions/{case}/{m}".encode()))
    own, intr = _encounters(rng, 400, max(m, 1), cfg)
    d = rng.uniform(0.05, 2.0, intr.shape)
    with np.errstate(invalid="ignore"):
        intr = AircraftState(own.x[:, None] + (intr.x - own.x[:, None]) * d, own.y[:, None] + (intr.y - own.y[:, None]) * d,
                             intr.z, intr.gs, intr.trk, intr.vs)
    intr = intr[:, :m]
    # and exact head-on encounters (both sides of every axis equally good: the preferred side's tie rule)
    k = 60
    rng_h = rng.uniform(1500.0, 6000.0, k)
    own_h = AircraftState(np.zeros(k), np.zeros(k), np.full(k, 1000.0), np.full(k, 55.0), np.zeros(k), np.zeros(k))
    intr_h = AircraftState(np.zeros((k, m)), np.repeat(rng_h[:, None], m, 1), np.full((k, m), 1000.0),
                           np.full((k, m), 60.0), np.full((k, m), np.pi), np.zeros((k, m)))
    early = rng.integers(0, 4, intr.shape)
    batches = [(own, intr, alerting.conflict_lists(own, intr, cfg, early_level=early)),
               (own_h, intr_h, alerting.conflict_lists(own_h, intr_h, cfg))]

    def run():
        with np.errstate(all="ignore"):
            return [bands_mod.compute_bands(o, i, cfg, lists=li) for o, i, li in batches]
    got = run()
    monkeypatch.setattr(bands_mod, "COMPILED", False)
    ref = run()
    for gb, rb in zip(got, ref):
        _same_bands(gb, rb)
    if m:
        reg = np.concatenate([a.region.ravel() for a in ref[0].axes()])
        assert {0, 2, 3, 4} <= set(np.unique(reg))
        assert any(np.isfinite(a.res_lo).any() for a in ref[0].axes())
        assert any((a.preferred == 1).any() for a in ref[1].axes())


@pytest.mark.parametrize("preset", ["do365", "daidalus"])
def test_classify_command_identical(preset, monkeypatch):
    """Command classification (axis, direction) compiled equals numpy: held (nan) fields, track changes
    at +-pi and next to it, changes on and next to the deadbands, equal times on two axes (the first
    axis wins), no change at all."""
    from daa_sil.daa import resolution

    cfg = DaaConfig.for_preset(preset)
    rng = np.random.default_rng(zlib.crc32(f"classify/{preset}".encode()))
    n = 20_000
    own, _ = _encounters(rng, n, 1, cfg)
    db = resolution.CLASSIFY_DEADBAND
    dtrk = rng.choice([0.0, np.pi, -np.pi, np.nextafter(np.pi, 0), db["trk"], np.nextafter(db["trk"], 0), 1.0, -2.5,
                       7.0, cfg.turn_rate * 3.0], n)
    dvs = rng.choice([0.0, db["vs"], np.nextafter(db["vs"], 0), -db["vs"], cfg.vertical_accel * 3.0, 12.0, -30.0], n)
    dgs = rng.choice([0.0, db["gs"], np.nextafter(db["gs"], np.inf), cfg.horizontal_accel * 3.0, -20.0, 40.0], n)
    cmd = Command(np.where(rng.random(n) < 0.15, np.nan, own.trk + dtrk), np.where(rng.random(n) < 0.15, np.nan, own.vs + dvs),
                  np.where(rng.random(n) < 0.15, np.nan, own.gs + dgs))
    # exact ties: 4 s on the vertical and the speed axis from rest (the vertical axis, the first, wins)
    own.vs[:100], own.gs[:100] = 0.0, 0.0
    cmd.trk[:100], cmd.vs[:100], cmd.gs[:100] = own.trk[:100], 4.0 * cfg.vertical_accel, 4.0 * cfg.horizontal_accel
    got = resolution.classify_command(own, cmd, cfg)
    monkeypatch.setattr(resolution, "COMPILED", False)
    ref = resolution.classify_command(own, cmd, cfg)
    for g, r in zip(got, ref):
        _same(g, r)
    assert set(np.unique(ref[0])) == {0, 1, 2, 3} and set(np.unique(ref[1])) == set(range(7))
    assert (ref[0][:100] == AXIS_VERTICAL).all()


@pytest.mark.parametrize("case", range(5))
@pytest.mark.parametrize("m", [0, 1, 3])
def test_fused_axis_pass_identical(case, m, monkeypatch):
    """The conflicts of a band axis in one pass per path (``band_regions.axis_conflict_regions``: no arrays
    of relative states or of candidates' conflicts, undecided segments resolved on their knots' states alone)
    give every field of the bands exactly as ``PathEvaluator`` then ``axis_regions`` do, on far, near and
    very close intruders (crossings, clips and splits), with nan and huge states and with no intruder."""
    cfg = _band_configs()[case]
    rng = np.random.default_rng(zlib.crc32(f"fused/{case}/{m}".encode()))
    own, intr = _encounters(rng, 500, max(m, 1), cfg)
    d = rng.choice([0.03, 0.1, 0.3, 1.0], intr.shape) * rng.uniform(0.5, 1.5, intr.shape)
    with np.errstate(invalid="ignore"):
        intr = AircraftState(own.x[:, None] + (intr.x - own.x[:, None]) * d, own.y[:, None] + (intr.y - own.y[:, None]) * d,
                             intr.z, intr.gs, intr.trk, intr.vs)
    intr = intr[:, :m]
    lists = alerting.conflict_lists(own, intr, cfg, early_level=rng.integers(0, 4, intr.shape))

    def run():
        with np.errstate(all="ignore"):
            return bands_mod.compute_bands(own, intr, cfg, lists=lists)
    got = run()
    monkeypatch.setattr(bands_mod, "FUSED", False)
    ref = run()
    _same_bands(got, ref)
    if m:
        assert any(np.isfinite(a.t_out).any() for a in ref.axes())
        assert {0, 2, 3} <= set(np.unique(np.concatenate([a.region.ravel() for a in ref.axes()])))


# --------------------------------------------------------------------------------------------------
# the choice of a candidate (Algorithm 2) against search_maneuver in numpy
# --------------------------------------------------------------------------------------------------
from daa_sil.daa import resolution  # noqa: E402


def _same_bands(got, ref) -> None:
    """Every field of every axis of two Bands is the same (arrays bit for bit, nan where nan)."""
    for g, r in zip(got.axes(), ref.axes()):
        for f in dataclasses.fields(r):
            a, b = getattr(g, f.name), getattr(r, f.name)
            if b is None or np.ndim(b) == 0:
                assert a == b, f.name
            else:
                _same(a, b)


def _closing_encounters(preset: str, tag: str, nearest: float):
    """(cfg, rng, own, intr, bands, n): 600 encounters x 2 intruders of ``preset``, each intruder moved to a
    random fraction in [nearest, 1] of its distance, and their bands."""
    cfg = DaaConfig.for_preset(preset)
    rng = np.random.default_rng(zlib.crc32(f"{tag}/{preset}".encode()))
    own, intr = _encounters(rng, 600, 2, cfg)
    d = rng.uniform(nearest, 1.0, intr.shape)
    with np.errstate(invalid="ignore"):
        intr = AircraftState(own.x[:, None] + (intr.x - own.x[:, None]) * d, own.y[:, None] + (intr.y - own.y[:, None]) * d,
                             intr.z, intr.gs, intr.trk, intr.vs)
        bands = bands_mod.compute_bands(own, intr, cfg)
    return cfg, rng, own, intr, bands, own.shape[0]


@pytest.mark.parametrize("preset", ["do365", "paper", "daidalus"])
def test_search_maneuver_identical(preset, monkeypatch):
    """``kernels.select.search_into`` (the bands read in place, through row views of row views) chooses the
    candidate and rule numpy does, with every rule taken, with and without a reference command, nan states
    included."""
    cfg, rng, own, intr, bands, n = _closing_encounters(preset, "search", 0.05)
    ax, dr = rng.integers(0, 4, n), rng.integers(0, 7, n)
    ref = Command(own.trk + rng.normal(0, 0.5, n), rng.choice([0.0, 5.0, np.nan], n), rng.choice([40.0, 60.0, np.nan], n))
    sub = np.flatnonzero(rng.random(n) < 0.6)
    half = np.arange(sub.size) % 2 == 0
    cases = [(bands, own, intr, ax, dr, ref), (bands[sub], own[sub], intr[sub], ax[sub], dr[sub], ref[sub]),
             (bands[sub][half], own[sub][half], intr[sub][half], ax[sub][half], dr[sub][half], ref[sub][half])]
    rules = set()
    for b, o, i, a, dd, rf in cases:
        for h in (cfg.sm_horizon_s, 5.0, 300.0):
            for r in (rf, None):
                def run():
                    with np.errstate(all="ignore"):
                        return resolution.search_maneuver(o, i, a, dd, cfg, ref=r, horizon_s=h, bands=b, return_t_in=True)
                got = run()
                monkeypatch.setattr(resolution, "COMPILED", False)
                want = run()
                monkeypatch.setattr(resolution, "COMPILED", True)
                for g, w in zip((got[0].trk, got[0].vs, got[0].gs, got[1], got[2]),
                                (want[0].trk, want[0].vs, want[0].gs, want[1], want[2])):
                    _same(g, w)
                rules |= set(np.unique(want[1]).tolist())
    assert rules == {1, 2, 3, 4}


@pytest.mark.parametrize("preset", ["do365", "paper", "daidalus"])
def test_resolve_identical(preset, monkeypatch):
    """``kernels.select.resolution_into`` (persistence, axes in priority order with the previous one last, NONE
    then RECOVERY, best effort) chooses the resolution numpy does, with and without a previous resolution,
    on whole bands and on nested row views."""
    cfg, rng, own, intr, bands, n = _closing_encounters(preset, "resolve", 0.02)
    prev = (rng.integers(0, 4, n).astype(np.int8), rng.integers(0, 7, n).astype(np.int8))
    sub = np.flatnonzero(rng.random(n) < 0.6)
    half = np.arange(sub.size) % 2 == 0
    cases = [(bands, own, intr, prev), (bands[sub], own[sub], intr[sub], (prev[0][sub], prev[1][sub])),
             (bands[sub][half], own[sub][half], intr[sub][half], (prev[0][sub][half], prev[1][sub][half]))]
    cfgs = [cfg, dataclasses.replace(cfg, resolution_axes=("speed", "horizontal"))]
    axes_seen = set()
    for b, o, i, p in cases:
        for c in cfgs:
            for pv in (p, None):
                def run():
                    with np.errstate(all="ignore"):
                        return resolution.resolve(o, i, c, pv, b, return_t_in=True)
                got = run()
                monkeypatch.setattr(resolution, "COMPILED", False)
                want = run()
                monkeypatch.setattr(resolution, "COMPILED", True)
                for g, w in zip((got[0].trk, got[0].vs, got[0].gs, got[1], got[2], got[3]),
                                (want[0].trk, want[0].vs, want[0].gs, want[1], want[2], want[3])):
                    _same(g, w)
                axes_seen |= set(np.unique(want[1]).tolist())
    assert axes_seen == {0, 1, 2, 3}
