"""Wait-map grid, transitions and rewards against hand-worked numbers and invariants."""

import numpy as np
import pytest

from daa_sil.errors import UsageError
from daa_sil.waitmap import MdpParams, fine_grid, paper_grid, resolve_grid
from daa_sil.waitmap.grid import Axis, Grid, _linear_axis, _theta_axis
from daa_sil.waitmap.transitions import (LOWC, OUT, assemble, build_transitions, kinematic_matrix,
                                         reward_of, spatial_matrix)

SMALL = "paper,dx=6,dy=6,dh=3,vi=3,vh=3,theta=4"


def test_grid_presets_sizes_and_custom():
    assert paper_grid().shape == (12, 12, 4, 5, 5, 5) and paper_grid().size == 72_000
    assert fine_grid().size >= 1_000_000
    g = resolve_grid("paper,dx=24,theta=8,dh=-300:300:7")
    assert g.shape == (24, 12, 7, 5, 5, 8)
    assert g.axis("dh").lo == -300 and g.axis("dh").hi == 300
    dy = paper_grid().axis("dy").values
    assert np.array_equal(dy, -dy[::-1])  # exactly symmetric: needed by the mirror oracle


def test_grid_from_yaml(tmp_path):
    f = tmp_path / "g.yaml"
    f.write_text("base: paper\ndx: {min: -1000, max: 1000, n: 5}\nvi: {points: [70, 155, 300]}\ntheta: {n: 6}\n")
    g = resolve_grid(str(f))
    assert g.axis("dx").points == (-1000.0, -500.0, 0.0, 500.0, 1000.0)
    assert g.axis("vi").points == (70.0, 155.0, 300.0)
    assert g.axis("theta").n == 6 and g.axis("theta").periodic


@pytest.mark.parametrize("spec", ["paper,dx=1", "paper,foo=3", "paper,dx=a", "nonsense", "paper,dh=5:1:3"])
def test_bad_grid_specs_raise_usage_error(spec):
    with pytest.raises(UsageError):
        resolve_grid(spec)


def _line_grid(vi_pts=(55.0, 195.0)):
    """dx nodes every 500 m; one-node-ish other axes (two nodes each, as required)."""
    return Grid((Axis("dx", (-1000.0, -500.0, 0.0, 500.0, 1000.0)), _linear_axis("dy", -500, 500, 3),
                 _linear_axis("dh", -200, 200, 3), Axis("vi", vi_pts), _linear_axis("vh", -5, 5, 3),
                 _theta_axis(2)))


def test_spatial_step_hand_worked():
    g = _line_grid()
    p = MdpParams(v_own=55.0)
    spm = spatial_matrix(g, p).toarray()
    idx = lambda *i: np.ravel_multi_index(i, g.shape)  # noqa: E731
    # vi = 55 heading 0 (same as ownship): no relative motion -> stays exactly on its node
    s = idx(2, 1, 1, 0, 1, 0)
    assert spm[s, s] == pytest.approx(1.0)
    # vi = 195 heading 180 deg: closes 250 m in 1 s -> half way between dx nodes 0 and -500
    s = idx(2, 1, 1, 1, 1, 1)
    assert spm[s, idx(2, 1, 1, 1, 1, 1)] == pytest.approx(0.5)
    assert spm[s, idx(1, 1, 1, 1, 1, 1)] == pytest.approx(0.5)
    # at the back edge the same motion leaves the box: the whole row goes to EXIT
    s = idx(0, 1, 1, 1, 1, 1)
    assert spm[s].sum() == 0.0
    # climbing intruder: dh 0 -> +5 m, i.e. 5/200 of the way to the +200 node
    s = idx(2, 1, 1, 0, 2, 0)
    assert spm[s, idx(2, 1, 2, 0, 2, 0)] == pytest.approx(5 / 200)


def test_kinematic_matrix_rows_and_means():
    g = resolve_grid("paper,vi=60:300:25,theta=72")  # fine kinematic axes: interior nodes see no clamping
    p = MdpParams()
    K = kinematic_matrix(g, p, 5.0)
    assert np.allclose(np.asarray(K.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    nvi, nvh, nth = 25, 5, 72
    vi = g.axis("vi").values
    th = g.axis("theta").values
    k = np.ravel_multi_index((12, 2, 10), (nvi, nvh, nth))
    row = K.getrow(k)
    ivi, ivh, ith = np.unravel_index(row.indices, (nvi, nvh, nth))
    # Table 1 speed changes have mean 0 -> E[vi'] = vi (linear interpolation keeps the mean)
    assert row.data @ vi[ivi] == pytest.approx(vi[12], abs=1e-9)
    # turn: horizontal half the time, then 0.8 * 5 deg/s + 0.2 * 0 (Table 1 mean) -> +2 deg per step
    dth = np.angle(np.exp(1j * (th[ith] - th[10])))
    assert np.degrees(row.data @ dth) == pytest.approx(0.5 * 0.8 * 5.0, abs=1e-9)


def test_reward_hand_worked():
    p = MdpParams()
    # head-on, dead ahead: HMD = 0 floored at 1 m -> C1/HMD = 1220; d_h = 61 m -> C2/d_h = 2 -> R = 1 - 2
    assert reward_of(1000.0, 0.0, 61.0, 100.0, np.pi, p) == pytest.approx(-1.0)
    # intruder behind flying away (diverging): HMD = current range 2440 m -> 1220/2440 = 0.5 < 122/1
    assert reward_of(-2440.0, 0.0, 0.0, 100.0, np.pi, p) == pytest.approx(0.5)
    # co-located: both separations floored, the division never produces inf/nan
    assert np.isfinite(reward_of(0.0, 0.0, 0.0, 55.0, 0.0, p))


def test_assembled_rows_are_stochastic_and_special_states_absorb():
    g = resolve_grid(SMALL)
    tr = build_transitions(g, MdpParams(), 2.5)
    Pw, Pe = assemble(tr)
    S = g.size
    assert Pw.shape == (S + 3, S + 3)
    assert np.allclose(np.asarray(Pw.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert np.allclose(np.asarray(Pe.sum(axis=1)).ravel(), 1.0, atol=0)
    assert Pw.data.min() >= 0
    # no mass ever lands on a LoWC node: it is redirected to LOWC
    assert Pw[:, np.flatnonzero(tr.lowc)].nnz == 0
    for j in range(3):
        assert Pw[S + j, S + j] == 1.0
    assert np.all(Pe[:S].tocoo().col == S + OUT)
    assert np.all(Pw[np.flatnonzero(tr.lowc)].tocoo().col == S + LOWC)
