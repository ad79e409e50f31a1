"""The results table: schema round trip, version refusal, collecting cells, summaries from totals."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from harness import metrics as M
from harness import results as R


def _cell(cell_id, pipeline, offset, *, frames=2, seed=1):
    rows = []
    for f in range(frames):
        true = np.zeros((4, 5, 2), np.float32)
        est = true + np.float32(offset * (f + 1))
        rows += M.flow_rows(est, true, np.ones((4, 5), bool), frame=f)
    return R.rows_to_frame(rows, cell_id=cell_id, scene="tiny", scene_hash="h", seed=seed, pipeline=pipeline,
                           config_hash="cfg", git_commit="abc", machine="m")


def test_round_trip_keeps_values_and_dtypes(tmp_path):
    df = _cell("c1", "lk", 0.5)
    R.write_table(df, tmp_path / "results.parquet")
    back = R.read_results(tmp_path)
    pd.testing.assert_frame_equal(back, df)
    assert list(back.columns) == list(R.COLUMNS)
    assert back["frame"].dtype == "Int64" and back["higher_is_better"].dtype == bool
    assert not list(tmp_path.glob(".*tmp"))  # no temporary file left behind


def test_histograms_round_trip_compactly(tmp_path):
    rng = np.random.default_rng(5)
    epe = np.abs(rng.standard_t(2, 300_000)) * 0.5  # heavy tail: bins up to the overflow
    h = M.epe_histogram(epe)
    packed = M.encode_hist(h)
    assert isinstance(packed, bytes) and len(packed) < len(" ".join(f"{b}:{c}" for b, c in zip(*np.nonzero(h), h[h > 0]))) / 3
    rows = [{"metric": "epe_median", "region": "all", "motion": "total", "frame": 0, "value": 1.0, "sum": np.nan,
             "count": float(h.sum()), "hist": packed}, {"metric": "epe_mean", "value": 1.0, "sum": 1.0, "count": 1.0}]
    df = R.rows_to_frame(rows, cell_id="c1", scene="s", pipeline="lk")
    R.write_table(df, tmp_path / "results.parquet")
    back = R.read_results(tmp_path)
    assert back["hist"].tolist() == [packed, b""]
    np.testing.assert_array_equal(M.decode_hist(back["hist"][0]), h)


def test_a_histogram_that_is_not_encode_hist_bytes_is_refused():
    with pytest.raises(R.SchemaError, match="column 'hist' cannot be bytes: expected bytes from "
                                            "harness.metrics.encode_hist, got str '3:100'"):
        R.rows_to_frame([{"metric": "epe_median", "value": 0.0, "hist": "3:100"}])
    with pytest.raises(ValueError, match="hist: not an encoded histogram"):
        M.decode_hist(b"\x01\x04garbage-bytes")


def test_older_or_foreign_tables_are_refused(tmp_path):
    df = _cell("c1", "lk", 0.5)
    pq.write_table(pa.Table.from_pandas(df, preserve_index=False), tmp_path / "results.parquet")
    with pytest.raises(R.SchemaError, match="no aerobench schema version"):
        R.read_results(tmp_path)
    old = df.drop(columns=["kind"])
    t = pa.Table.from_pandas(old, preserve_index=False)
    t = t.replace_schema_metadata({b"aerobench.schema_version": b"0"})
    pq.write_table(t, tmp_path / "old.parquet")
    with pytest.raises(R.SchemaError, match="schema v0, this aerobench reads v2"):
        R.read_results(tmp_path / "old.parquet")
    with pytest.raises(R.SchemaError, match=r"missing column\(s\) \['kind'\]"):
        R.write_table(old, tmp_path / "x.parquet")
    with pytest.raises(FileNotFoundError, match="no such results table"):
        R.read_results(tmp_path / "nowhere")


def test_rows_to_frame_rejects_unknown_cell_columns():
    with pytest.raises(ValueError, match=r"unknown column\(s\) \['colour'\]"):
        R.rows_to_frame([], colour="red")


def test_collect_cells_is_independent_of_finishing_order(tmp_path):
    cells = {"c2": _cell("c2", "hs", 1.0), "c1": _cell("c1", "lk", 0.5), "c3": _cell("c3", "lk", 0.25, seed=2)}
    for run, order in (("a", ["c1", "c2", "c3"]), ("b", ["c3", "c2", "c1"])):
        for c in order:
            R.write_table(cells[c], tmp_path / run / "cells" / c / R.ROWS_FILE)
    (tmp_path / "b" / "cells" / ".tmp-c4").mkdir()  # a cell still being written is not collected
    a, b = R.collect_cells(tmp_path / "a"), R.collect_cells(tmp_path / "b")
    pd.testing.assert_frame_equal(a, b)
    assert (tmp_path / "a" / R.RESULTS_FILE).read_bytes() == (tmp_path / "b" / R.RESULTS_FILE).read_bytes()
    summary = pd.read_csv(tmp_path / "a" / R.SUMMARY_FILE)
    lk = summary[(summary["pipeline"] == "lk") & (summary["metric"] == "epe_mean") & (summary["region"] == "all")]
    # lk cells: EPE sqrt(2)*0.5*(1, 2) and sqrt(2)*0.25*(1, 2) over 20 px each: pooled mean of the four frames
    assert lk["value"].item() == pytest.approx(np.sqrt(2) * (0.5 * 1.5 + 0.25 * 1.5) / 2)
    assert lk["n_cells"].item() == 2


def test_summarize_recomputes_from_totals_not_averages():
    a = R.rows_to_frame(M.flow_rows(np.ones((1, 1, 2), np.float32) * 3, np.zeros((1, 1, 2), np.float32),
                                    np.ones((1, 1), bool)), cell_id="a", pipeline="p", scene="s")
    b = R.rows_to_frame(M.flow_rows(np.zeros((1, 9, 2), np.float32), np.zeros((1, 9, 2), np.float32),
                                    np.ones((1, 9), bool)), cell_id="b", pipeline="p", scene="s")
    s = R.summarize(pd.concat([a, b])).set_index(["metric", "region"])
    assert s.loc[("epe_mean", "all"), "value"] == pytest.approx(3 * np.sqrt(2) / 10)  # not (3 sqrt2 + 0) / 2


def test_run_json_round_trip_and_refusals(tmp_path):
    data = {"suite": "ci", "config_hash": "x", "n": np.int64(3), "provenance": {"machine": "m"}}
    R.write_run_json(tmp_path, data)
    assert R.read_run_json(tmp_path) == {"suite": "ci", "config_hash": "x", "n": 3, "provenance": {"machine": "m"}}
    with pytest.raises(ValueError, match="Out of range float"):
        R.write_run_json(tmp_path, {"x": float("nan")})
    with pytest.raises(FileNotFoundError, match="no run.json"):
        R.read_run_json(tmp_path / "elsewhere")


def test_cells_read_during_the_run_give_the_same_bytes_and_a_rewritten_cell_is_read_again(tmp_path):
    """collect_cells with a CellRowsReader writes the file collect_cells alone writes (cells shuffled, re-written)."""
    import hashlib
    import os

    def make(run):
        for k, cid in enumerate(["c2", "c1", "c3"]):
            rows = _cell(cid, "lk", 0.25 * (k + 1), frames=3).sample(frac=1.0, random_state=k)  # rows out of order
            (run / "cells" / cid).mkdir(parents=True)
            R.write_table(rows, run / "cells" / cid / R.ROWS_FILE)

    alone, during = tmp_path / "alone", tmp_path / "during"
    make(alone)
    make(during)
    reader = R.CellRowsReader(during)
    for cid in ("c3", "c1", "c2", "missing"):
        reader.add(cid)
    # c1 re-written after it was read (a retried task): the reader's copy is stale and must not be used
    new = _cell("c1", "lk", 9.0, frames=3)
    for run in (alone, during):
        R.write_table(new, run / "cells" / "c1" / R.ROWS_FILE)
        os.utime(run / "cells" / "c1" / R.ROWS_FILE, ns=(1, 1))
    a = R.collect_cells(alone)
    b = R.collect_cells(during, read=reader)
    pd.testing.assert_frame_equal(a, b)
    for name in (R.RESULTS_FILE, R.SUMMARY_FILE):
        assert hashlib.sha256((alone / name).read_bytes()).digest() == hashlib.sha256((during / name).read_bytes()).digest()
    assert list(dict.fromkeys(a["cell_id"])) == ["c1", "c2", "c3"]
    assert (a[a["cell_id"] == "c1"]["value"].max()) > 8  # the re-written rows, not the first ones
    assert reader.cells_table() is None  # c1's rows were re-written after they were read: not at hand
    reader.add("c1")
    cells = reader.cells_table()
    pd.testing.assert_frame_equal(cells, R.cell_table(a), check_exact=True)
    assert cells["cell_id"].tolist() == ["c1", "c2", "c3"] and list(cells.columns) == list(R.CELL_COLUMNS)
    order = a[a["cell_id"] == "c2"][list(R.ROW_ORDER)].astype(str).values.tolist()
    assert order == sorted(order, key=lambda r: r[:3])  # metric, region, motion ascending within a cell


def test_the_collected_table_is_what_results_parquet_reads_back(tmp_path):
    """The report takes the table collect_cells returns instead of reading the file: it must be the same frame."""
    for k, cid in enumerate(["c2", "c1", "c3"]):
        rows = _cell(cid, "lk" if k else "hs", 0.25 * (k + 1), frames=3, seed=k)
        rows.loc[rows.index[0], "frame"] = pd.NA  # a nullable integer with a gap
        R.write_table(rows, tmp_path / "cells" / cid / R.ROWS_FILE)
    collected = R.collect_cells(tmp_path)
    read = R.read_results(tmp_path)
    pd.testing.assert_frame_equal(collected, read, check_exact=True, check_index_type=True,
                                  check_column_type=True)
    assert list(collected.dtypes) == list(read.dtypes) and collected.equals(read)
    assert isinstance(collected.index, pd.RangeIndex) and isinstance(read.index, pd.RangeIndex)
    assert collected["hist"].map(type).tolist() == read["hist"].map(type).tolist()
