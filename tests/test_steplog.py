"""Step-log schema, columnar builder and Parquet round trip with schema checks."""

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from daa_sil import steplog as sl
from daa_sil.errors import FileFormatError, UsageError


def _step_cols(k: int, n: int, m: int) -> dict:
    """Columns of step k whose values encode (step, encounter, intruder) so ordering is checkable."""
    enc = np.arange(n)
    cols = {name: np.full(n, np.nan) for name, typ in zip(sl.STEP_SCHEMA.names, sl.STEP_SCHEMA.types)
            if typ == pa.float64()}
    cols.update(step=np.full(n, k, np.int32), t=np.full(n, float(k)), own_x=100.0 * enc + k,
                decision=np.full(n, sl.DECISIONS.index("wait") if k == 1 else 0),
                rule=np.zeros(n, int), authority=np.array(["pilot"] * n),
                projl=np.zeros(n, bool), decided_by=np.zeros(n, int), wait_in_box=np.zeros(n, bool),
                pilot_cmd_received=enc % 2 == 0,
                pilot_axis=np.zeros(n, int), pilot_dir=np.zeros(n, int), exec_axis=np.full(n, 1),
                exec_dir=np.full(n, 2), lowc=np.full(n, k == 2), nmac=np.zeros(n, bool))
    for name, typ in sl.INTRUDER_COLUMNS.items():
        vals = 1000.0 * k + 10.0 * enc[:, None] + np.arange(m)[None, :]
        cols[name] = vals.astype(typ.to_pandas_dtype()) if typ != pa.bool_() else vals % 2 == 0
    cols["alert_level"] = np.full((n, m), k, np.int8)
    # encounter e has e bands at this step (variable length lists)
    width = n
    cols["bands_count"] = enc.copy()
    cols["bands_trk_lo_deg"] = np.tile(np.arange(width, dtype=float), (n, 1)) + 0.5 * k
    cols["bands_trk_hi_deg"] = cols["bands_trk_lo_deg"] + 1.0
    cols["bands_trk_region"] = np.tile(np.arange(width) % len(sl.REGIONS), (n, 1))
    return cols


def _build(n=3, m=2, k=3):
    b = sl.StepLogBuilder(np.array([7, 8, 9][:n]), m)
    for step in range(k):
        b.append(_step_cols(step, n, m))
    return b.finish()


def test_builder_orders_rows_by_encounter_then_step():
    tab = _build()
    assert tab.schema.equals(sl.STEP_SCHEMA, check_metadata=False)
    assert tab.num_rows == 9
    assert tab["encounter_id"].to_pylist() == [7, 7, 7, 8, 8, 8, 9, 9, 9]
    assert tab["step"].to_pylist() == [0, 1, 2] * 3
    # own_x = 100 * encounter_index + step
    assert tab["own_x"].to_pylist() == [0, 1, 2, 100, 101, 102, 200, 201, 202]
    # row (encounter 1, step 2): intr_x = [2000 + 10 + 0, 2000 + 10 + 1]
    assert tab["intr_x"][5].as_py() == [2010.0, 2011.0]
    assert tab["alert_level"].type == pa.list_(pa.int8())
    assert tab["decision"].to_pylist()[:3] == ["none", "wait", "none"]
    assert set(tab["exec_axis"].to_pylist()) == {"horizontal"} and set(tab["exec_dir"].to_pylist()) == {"right"}
    assert tab["lowc"].to_pylist() == [False, False, True] * 3
    assert np.isnan(tab["sm_pilot"].to_numpy()).all()


def test_band_lists_are_variable_length_and_decoded():
    tab = _build()
    lo = tab["bands_trk_lo_deg"].to_pylist()
    assert [len(x) for x in lo] == [0, 0, 0, 1, 1, 1, 2, 2, 2]
    assert lo[8] == [1.0, 2.0]  # encounter 2, step 2: arange(2) + 1.0
    assert tab["bands_trk_region"].to_pylist()[7] == ["none", "far"]
    assert tab["bands_trk_hi_deg"].to_pylist()[7] == [1.5, 2.5]


def test_round_trip_and_metadata(tmp_path):
    tab = _build()
    path = sl.write_steplog(tab, tmp_path / "steps.parquet", metadata={"preset": "paper"})
    back = sl.read_steplog(path)
    assert back.schema.equals(tab.schema, check_metadata=False)
    for name in tab.column_names:
        a, b = back[name], tab[name]
        if pa.types.is_floating(a.type):  # nan-aware
            np.testing.assert_array_equal(a.to_numpy(), b.to_numpy())
        else:
            assert a.to_pylist() == b.to_pylist(), name
    meta = sl.steplog_metadata(path)
    assert meta["preset"] == "paper" and meta["daa_sil.steplog"] == sl.STEPLOG_VERSION
    assert not list(tmp_path.glob(".*tmp"))  # atomic write left no temp file


def test_missing_column_and_bad_shapes_are_usage_errors():
    b = sl.StepLogBuilder(np.arange(2), 1)
    cols = _step_cols(0, 2, 1)
    del cols["lowc"]
    with pytest.raises(UsageError, match="'lowc' is missing"):
        b.append(cols)
    cols = _step_cols(0, 2, 1)
    cols["range_m"] = np.zeros((2, 3))
    with pytest.raises(UsageError, match="range_m.*expected \\(2, 1\\)"):
        b.append(cols)
    cols = _step_cols(0, 2, 1)
    cols["decision"] = np.full(2, 99)
    b.append(cols)
    with pytest.raises(UsageError, match="out of range"):
        b.finish()


def test_reader_rejects_other_tables(tmp_path):
    other = tmp_path / "other.parquet"
    pq.write_table(pa.table({"encounter_id": [1], "step": pa.array([0], pa.int32())}), other)
    with pytest.raises(FileFormatError, match="column 't' is missing"):
        sl.read_steplog(other)
    garbage = tmp_path / "garbage.parquet"
    garbage.write_bytes(b"PAR1 this is not parquet")
    with pytest.raises(FileFormatError, match="not a readable Parquet file"):
        sl.read_steplog(garbage)
    with pytest.raises(FileFormatError, match="does not exist"):
        sl.read_steplog(tmp_path / "nope.parquet")
    # right columns, wrong type
    tab = _build().set_column(2, "t", pa.array(np.zeros(9, np.float32)))
    bad = tmp_path / "badtype.parquet"
    pq.write_table(tab.replace_schema_metadata(sl.STEP_SCHEMA.metadata), bad)
    with pytest.raises(FileFormatError, match="column 't' has type float"):
        sl.read_steplog(bad)


def test_reader_rejects_other_versions(tmp_path):
    tab = _build().replace_schema_metadata({"daa_sil.steplog": "999"})
    p = tmp_path / "v999.parquet"
    pq.write_table(tab, p)
    with pytest.raises(FileFormatError, match="version 999"):
        sl.read_steplog(p)


def test_empty_builder_gives_empty_table():
    tab = sl.StepLogBuilder(np.arange(4), 2).finish()
    assert tab.num_rows == 0 and tab.schema.equals(sl.STEP_SCHEMA, check_metadata=False)


def test_cells_equal_treats_nan_as_equal_and_compares_lists_elementwise():
    from daa_sil.steplog import cells_equal

    nan = float("nan")
    assert cells_equal(nan, nan) and cells_equal([1.0, nan], [1.0, nan]) and cells_equal("wait", "wait")
    assert not cells_equal(nan, 0.0) and not cells_equal([1.0], [1.0, 2.0]) and not cells_equal([1.0, 2.0], [1.0, 2.5])
    assert not cells_equal(1.0, 1.0 + 1e-12)  # exact: parity means identical logs


def test_step_row_is_the_builders_row():
    """The SIL vehicle's row of a step (``step_row``) is the row fast-time's builder writes for it: every
    cell, named codes, bands cut to their count, plain Python types (the live feed sends them as JSON)."""
    n, m, k = 3, 2, 3
    ids = np.array([7, 8, 9])
    tab = _build(n, m, k)
    by_key = {(r["encounter_id"], r["step"]): r for r in tab.to_pylist()}
    rows = []
    for step in range(k):
        cols = _step_cols(step, n, m)
        for i in range(n):
            row = sl.step_row(cols, i, encounter_id=int(ids[i]))
            assert list(row) == list(sl.STEP_COLUMNS)
            want = by_key[(int(ids[i]), step)]
            assert all(sl.cells_equal(row[c], want[c]) for c in sl.STEP_COLUMNS), \
                [c for c in sl.STEP_COLUMNS if not sl.cells_equal(row[c], want[c])]
            assert row["bands_trk_region"] == [sl.REGIONS[j % len(sl.REGIONS)] for j in range(i)]
            assert type(row["step"]) is int and type(row["own_x"]) is float and type(row["lowc"]) is bool
            assert all(type(v) is int for v in row["alert_level"]) and type(row["decision"]) is str
            rows.append(row)
    # the vehicle's table of rows is the builder's table, rows in the same order
    order = sorted(range(len(rows)), key=lambda j: (rows[j]["encounter_id"], rows[j]["step"]))
    again = pa.Table.from_pylist([rows[j] for j in order], schema=sl.STEP_SCHEMA)
    assert again.num_rows == tab.num_rows
    assert all(sl.cells_equal(a[c], b[c]) for a, b in zip(again.to_pylist(), tab.to_pylist()) for c in sl.STEP_COLUMNS)


def test_step_row_fills_missing_floats_and_refuses_other_missing_columns():
    cols = _step_cols(0, 2, 1)
    del cols["sm_pilot"]
    assert np.isnan(sl.step_row(cols, 1)["sm_pilot"])
    del cols["decision"]
    with pytest.raises(UsageError, match="decision"):
        sl.step_row(cols, 0)
