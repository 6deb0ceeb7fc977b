"""Wait-map files (round trip, corruption, version), lookup semantics and the cached family API."""

import json
import zipfile

import numpy as np
import pytest

from daa_sil import waitmap
from daa_sil.errors import FileFormatError
from daa_sil.waitmap import MdpParams, build_family, build_map, resolve_grid
from daa_sil.waitmap.store import ARRAYS

SMALL = "paper,dx=6,dy=6,dh=3,vi=3,vh=3,theta=4"


@pytest.fixture(scope="module")
def wm():
    return build_map(resolve_grid(SMALL), MdpParams(), 5.0)


def test_round_trip_is_bit_exact(wm, tmp_path):
    path = waitmap.save(wm, tmp_path / "m.npz")
    back = waitmap.load(path)
    for n in ARRAYS:
        a, b = getattr(wm, n), getattr(back, n)
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
    assert back.grid == wm.grid and back.params == wm.params and back.turn_rate_deg == 5.0
    assert back.content_hash == wm.content_hash and len(back.content_hash) == 64
    assert back.stats["iterations"] == wm.stats["iterations"]


def test_fields_are_the_float32_cast_of_the_arrays_given(wm):
    """The interleaved float32 fields hold exactly ``astype(float32)`` of each float64 array (bit for bit),
    and fields of different shapes are refused instead of broadcast."""
    from dataclasses import replace

    from daa_sil.waitmap.lookup import FIELDS

    rng = np.random.default_rng(7)
    raw = {n: rng.normal(0.0, 30.0, wm.grid.shape) for n in FIELDS}
    raw["p_lowc"][0, 0, 0, 0, 0, 0] = 1.0 + 1e-9  # rounds to 1.0f
    raw["q_wait"].flat[1] = -0.0
    m = replace(wm, **raw)
    for n in FIELDS:
        got = getattr(m, n)
        assert got.dtype == np.float32 and got.tobytes() == raw[n].astype(np.float32).tobytes()
    with pytest.raises(ValueError, match="one shape"):
        replace(wm, wait_s=raw["wait_s"][..., :1])


def test_a_loaded_maps_fields_are_read_into_one_array_as_np_load_reads_them(wm, tmp_path):
    """``read_arrays`` gives every array bit for bit as ``np.load`` does; the four interpolated fields
    come as views of one (..., 4) float32 array, which the map keeps as its fields without a copy."""
    from daa_sil.waitmap.lookup import FIELDS
    from daa_sil.waitmap.store import read_arrays

    path = waitmap.save(wm, tmp_path / "m.npz")
    got, extrema = read_arrays(path)
    with np.load(path) as z:
        want = {k: z[k] for k in z.files}
    assert set(got) == set(want)
    for k, a in want.items():
        assert got[k].dtype == a.dtype and got[k].shape == a.shape and got[k].tobytes() == a.tobytes(), k
    base = got[FIELDS[0]].base
    assert base.shape == wm.grid.shape + (len(FIELDS),)
    for i, n in enumerate(FIELDS):
        assert got[n].base is base and np.array_equal(base[..., i], want[n])
        assert extrema[n] == (want[n].min(), want[n].max())
    back = waitmap.load(path)
    assert all(getattr(back, n).base is back.p_lowc.base for n in FIELDS)


@pytest.mark.parametrize("name, value, ok", [
    ("p_lowc", np.nextafter(np.float32(1.0), np.float32(2.0)), False),  # the next float32 above 1
    ("p_lowc", 1.0 + 1e-9, True),  # rounds to 1.0f: within [0, 1], as before
    ("wait_s", -0.5, False),
    ("t_lowc", np.nan, False),
    ("q_wait", np.inf, False),
    ("q_wait", -1e30, True),
])
def test_the_value_checks_of_a_map_read_side_by_side_are_the_old_rule(wm, tmp_path, name, value, ok):
    """The range checks take the fields' extrema from the read (no pass of their own); a value one
    float32 step outside its range, a NaN or an inf is still refused, naming the array."""
    from dataclasses import replace

    arr = getattr(wm, name).astype(np.float64)
    arr.flat[arr.size // 2] = value
    path = waitmap.save(replace(wm, **{name: arr}), tmp_path / "m.npz")
    if ok:
        assert float(getattr(waitmap.load(path), name).flat[arr.size // 2]) == float(np.float32(value))
    else:
        with pytest.raises(FileFormatError, match=name):
            waitmap.load(path)


def test_a_map_with_float64_fields_loads_as_their_float32_cast(wm, tmp_path):
    """Fields not stored as float32 are read by numpy as they stand and cast as before."""
    path = waitmap.save(wm, tmp_path / "m.npz")
    with np.load(path) as z:
        data = {k: z[k] for k in z.files}
    wide = {k: (v.astype(np.float64) if v.dtype == np.float32 else v) for k, v in data.items()}
    other = tmp_path / "wide.npz"
    with open(other, "wb") as fh:
        np.savez(fh, **wide)
    back = waitmap.load(other, expected_hash=wm.content_hash)
    for n in ("wait_s", "p_lowc", "t_lowc", "q_wait"):
        assert getattr(back, n).dtype == np.float32 and getattr(back, n).tobytes() == data[n].tobytes()


def test_refuses_to_overwrite(wm, tmp_path):
    from daa_sil.errors import OutputError

    waitmap.save(wm, tmp_path / "m.npz")
    with pytest.raises(OutputError):
        waitmap.save(wm, tmp_path / "m.npz")


def _one_line(exc):
    msg = str(exc.value)
    assert "\n" not in msg and msg
    return msg


def test_truncated_and_corrupt_files_fail_cleanly(wm, tmp_path):
    good = waitmap.save(wm, tmp_path / "m.npz").read_bytes()
    trunc = tmp_path / "trunc.npz"
    trunc.write_bytes(good[: len(good) // 2])
    with pytest.raises(FileFormatError) as e:
        waitmap.load(trunc)
    assert "trunc.npz" in _one_line(e)
    # flip bytes inside the stored wait-time array (uncompressed npz: data sits in the file)
    bad = bytearray(good)
    i = bytes(good).find(wm.wait_s.tobytes()[:64])
    assert i > 0
    bad[i + 8: i + 16] = b"\x00\x01\x02\x03\x04\x05\x06\x07"
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(bytes(bad))
    with pytest.raises(FileFormatError) as e:
        waitmap.load(corrupt)
    _one_line(e)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip at all")
    with pytest.raises(FileFormatError):
        waitmap.load(junk)


@pytest.mark.parametrize("member", ["p_lowc", "wait_s", "lowc"])
def test_a_forged_array_header_is_one_line_before_anything_is_allocated(wm, tmp_path, member):
    """A member whose header claims far more data than it holds (10^12 elements: terabytes) is refused in
    one line from its size, before its array is allocated (np.load allocates the header's shape first)."""
    import io

    path = waitmap.save(wm, tmp_path / "m.npz")
    with zipfile.ZipFile(path) as zf:
        items = [(i.filename, zf.read(i)) for i in zf.infolist()]
    forged = tmp_path / "forged.npz"
    with zipfile.ZipFile(forged, "w") as zf:
        for name, raw in items:
            if name == f"{member}.npy":
                arr = np.lib.format.read_array(io.BytesIO(raw))
                buf = io.BytesIO()
                np.lib.format.write_array_header_1_0(buf, {"descr": np.lib.format.dtype_to_descr(arr.dtype),
                                                           "fortran_order": False, "shape": (10**12,)})
                raw = buf.getvalue() + arr.tobytes()
            zf.writestr(name, raw)
    for expected_hash in (None, wm.content_hash):
        with pytest.raises(FileFormatError) as e:
            waitmap.load(forged, expected_hash=expected_hash)
        assert f"{member}.npy" in _one_line(e) and "more than it holds" in _one_line(e)


def test_wrong_version_fails(wm, tmp_path):
    path = waitmap.save(wm, tmp_path / "m.npz")
    with np.load(path) as z:
        data = {k: z[k] for k in z.files}
    meta = json.loads(str(data["meta_json"]))
    meta["format"] = "daa-sil-waitmap/999"
    data["meta_json"] = np.array(json.dumps(meta))
    other = tmp_path / "v999.npz"
    with open(other, "wb") as fh:
        np.savez(fh, **data)
    with pytest.raises(FileFormatError) as e:
        waitmap.load(other)
    assert "daa-sil-waitmap/999" in _one_line(e)
    assert zipfile.is_zipfile(other)


def test_lookup_at_nodes_and_periodic_heading(wm):
    nodes = wm.grid.nodes().reshape(-1, 6)
    r = wm.lookup(nodes)
    assert np.allclose(r.wait_s, wm.wait_s.ravel(), atol=1e-4)
    assert np.array_equal(r.evade, wm.evade.ravel())
    assert r.in_grid.all() and r.in_box.all()
    shifted = nodes.copy()
    shifted[:, 5] += 2 * np.pi
    assert np.allclose(wm.lookup(shifted).wait_s, r.wait_s, atol=1e-4)


def _neighbours(wm, pred):
    """A node i and its +dx neighbour j, both wait-optimal, with pred(i, j) true."""
    g = wm.grid
    ok = ~wm.evade[:-1] & ~wm.evade[1:] & pred(wm, slice(None, -1), slice(1, None))
    i = tuple(np.argwhere(ok)[0])
    j = (i[0] + 1,) + i[1:]
    nodes = g.nodes()
    return i, j, nodes[i], nodes[j]


def test_paper_wait_interpolates_p_and_t_separately(wm):
    """Between two threatening nodes W = (sum w_k t_k) / (sum w_k p_k), the p-weighted mean of the
    corner waits, not the plain blend of W (hand formula from the node arrays)."""
    pm = wm.params.p_min
    i, j, a, b = _neighbours(wm, lambda m, x, y: (m.p_lowc[x] > pm) & (m.p_lowc[y] > pm)
                             & (np.abs(m.wait_s[x] - m.wait_s[y]) > 1) & (np.abs(m.p_lowc[x] - m.p_lowc[y]) > 0.05))
    mid = wm.lookup(0.25 * a + 0.75 * b)
    p = 0.25 * float(wm.p_lowc[i]) + 0.75 * float(wm.p_lowc[j])
    t = 0.25 * float(wm.t_lowc[i]) + 0.75 * float(wm.t_lowc[j])
    assert not mid.evade
    assert float(mid.wait_s) == pytest.approx(t / p, rel=1e-5)
    plain = 0.25 * float(wm.wait_s[i]) + 0.75 * float(wm.wait_s[j])
    assert abs(float(mid.wait_s) - plain) > 1e-3  # the two rules differ here
    assert float(mid.p_lowc) == pytest.approx(p, rel=1e-5)


def test_p_min_floor_at_the_edge_of_the_threat_region(wm):
    """Next to a node with p = 0 (W = H) the lookup is the threatening node's wait (its t/p), not a
    blend with H; where the interpolated p falls below p_min the wait is H."""
    pm, H = wm.params.p_min, wm.params.horizon
    i, j, a, b = _neighbours(wm, lambda m, x, y: (m.p_lowc[x] > 10 * pm) & (m.p_lowc[y] == 0))
    assert wm.wait_s[j] == H and 1.0 <= wm.wait_s[i] < H
    near = wm.lookup(0.5 * a + 0.5 * b)
    assert float(near.wait_s) == pytest.approx(float(wm.wait_s[i]), rel=1e-5)
    frac = 1.0 - 0.5 * pm / float(wm.p_lowc[i])  # interpolated p = 0.5 p_min
    far = wm.lookup((1 - frac) * a + frac * b)
    assert float(far.p_lowc) < pm and float(far.wait_s) == H


def test_until_evade_definition_interpolates_w():
    wmb = build_map(resolve_grid(SMALL), MdpParams(wait_definition="until_evade"), 5.0)
    i, j, a, b = _neighbours(wmb, lambda m, x, y: np.abs(m.wait_s[x] - m.wait_s[y]) > 1)
    mid = wmb.lookup(0.25 * a + 0.75 * b)
    assert float(mid.wait_s) == pytest.approx(0.25 * float(wmb.wait_s[i]) + 0.75 * float(wmb.wait_s[j]), rel=1e-5)


def test_outside_the_box_reads_the_nearest_point_of_the_box(wm):
    g = wm.grid
    lo, hi = g.axis("dx").lo, g.axis("dx").hi
    # 5 km behind, flying away: the map at the box's rear edge
    far = wm.lookup(np.array([-5000.0, 300.0, 150.0, 100.0, 0.0, np.pi]))
    edge = wm.lookup(np.array([lo, 300.0, 150.0, 100.0, 0.0, np.pi]))
    assert not far.in_box and not far.in_grid and edge.in_box
    assert far.wait_s == edge.wait_s and far.p_lowc == edge.p_lowc and far.evade == edge.evade
    # in LoWC now (head-on, 300 m/s, co-altitude, just outside the box): 0 whatever the map says
    inside = wm.lookup(np.array([hi + 100.0, 0.0, 0.0, 300.0, 0.0, np.pi]))
    assert inside.wait_s == 0.0 and inside.evade and not inside.in_box and inside.p_lowc == 1.0
    # speeds outside the grid are clamped and flagged, positions still in the box
    fast = wm.lookup(np.array([-1400.0, 1400.0, 200.0, 400.0, 0.0, np.pi]))
    assert fast.in_box and not fast.in_grid and 0 <= fast.wait_s <= wm.params.horizon


def test_family_picks_nearest_condition_and_batches():
    g = resolve_grid(SMALL)
    fam = build_family(g, MdpParams(), (-5.0, 0.0, 5.0))
    rng = np.random.default_rng(3)
    st = np.column_stack([rng.uniform(-1500, 1500, (50, 2)), rng.uniform(-200, 200, 50), rng.uniform(70, 300, 50),
                          rng.uniform(-5, 5, 50), rng.uniform(0, 2 * np.pi, 50)]).reshape(5, 10, 6)
    tr = np.deg2rad(rng.choice([-4.0, -1.0, 0.5, 3.0], size=(5, 10)))
    res = fam.lookup(st, tr)
    assert res.wait_s.shape == (5, 10)
    want = {-4.0: -5.0, -1.0: 0.0, 0.5: 0.0, 3.0: 5.0}
    for k in np.ndindex(5, 10):
        m = fam.map_for(want[round(float(np.rad2deg(tr[k])), 1)])
        assert res.wait_s[k] == m.lookup(st[k]).wait_s


def test_default_family_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DAA_SIL_CACHE", str(tmp_path))
    kw = dict(grid="paper,dx=4,dy=4,dh=2,vi=2,vh=2,theta=4", turn_rates=(-5.0, 5.0))
    first = waitmap.default_family("paper", **kw)
    entries = list((tmp_path / "waitmaps").iterdir())
    assert len(entries) == 1 and (entries[0] / "family.json").is_file()
    again = waitmap.default_family("paper", **kw)
    for a, b in zip(first.maps, again.maps):
        assert a.wait_s.tobytes() == b.wait_s.tobytes() and a.content_hash == b.content_hash
    other = waitmap.default_family("do365", **kw)  # different parameters -> a different cache key
    assert len(list((tmp_path / "waitmaps").iterdir())) == 2 and other.maps[0].params.preset == "do365"
