"""Streaming readers: every bad CSV row is a reject with its 1-based file line, wherever it is in the file.

Oracle for line numbers: the test writes the file record by record and counts the newlines it wrote itself.
"""

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from hpe_cli.errors import HpeError
from hpe_cli.io.readers import LINE_COL, open_table, read_table


def build(path, records, header=b"pitch,yaw,roll,image\n"):
    """Write ``records`` (bytes, each with its own newline(s)); return the first line of each record."""
    lines, line = [], 2
    with open(path, "wb") as f:
        f.write(header)
        for rec in records:
            f.write(rec)
            lines.append(line)
            line += rec.count(b"\n")
    return lines


def collect(path, **kw):
    src = open_table(path, with_lines=True, **kw)
    got, rej = [], []
    for batch, rejects in src.batches_with_rejects():
        got.append(batch)
        rej += rejects
    table = pa.Table.from_batches(got, schema=src.schema) if got else None
    return table, rej


BAD = {
    "text": (b"1,abc,3,x.jpg\n", "non-numeric value in yaw"),
    "few": (b"1,2\n", "expected 4 fields, got 2"),
    "many": (b"1,2,3,a.jpg,9\n", "expected 4 fields, got 5"),
    "latin1": (b"1,2,3,caf\xe9.jpg\n", "undecodable bytes in image (not UTF-8)"),
    "unclosed": (b'1,2,3,"open.jpg\n', "unclosed quote"),
}


@pytest.mark.parametrize("block", [64, 256, 1 << 24])
@pytest.mark.parametrize("where", ["early", "late"])
def test_bad_rows_anywhere_are_rejects_with_lines(tmp_path, block, where):
    rng = np.random.default_rng(0)
    good = [f"{a:.3f},{b:.3f},{c:.3f},img{i}.jpg\n".encode() for i, (a, b, c) in enumerate(rng.normal(size=(300, 3)))]
    good[5] = b'1.5,2.5,3.5,"with, comma"\n'
    good[7] = b'1.5,2.5,3.5,"two\nlines"\n'
    good[9] = b"\n"  # blank line: counted, not a row
    recs = list(good)
    pos = {k: (i * 13 + 20 if where == "early" else 200 + i * 17) for i, k in enumerate(BAD)}
    for k, i in sorted(pos.items(), key=lambda kv: -kv[1]):
        recs.insert(i, BAD[k][0])
    path = tmp_path / "t.csv"
    lines = build(path, recs)
    table, rej = collect(path, block_size=block)
    want_rej = sorted((lines[recs.index(BAD[k][0])], BAD[k][1]) for k in BAD)
    assert sorted((r.line, r.reason) for r in rej) == want_rej
    good_lines = [ln for rec, ln in zip(recs, lines) if rec in good and rec != b"\n"]
    assert table[LINE_COL].to_pylist() == good_lines
    assert table.num_rows + len(rej) == len(recs) - 1  # every record is a row or a reject (blank line is neither)
    assert table.schema.field("pitch").type == pa.float64() and table.schema.field("image").type == pa.string()
    assert "two\nlines" in table["image"].to_pylist()
    raw = {r.reason: r.raw for r in rej}
    assert raw["expected 4 fields, got 2"] == "1,2" and raw["undecodable bytes in image (not UTF-8)"].startswith(
        "1,2,3"
    )


def test_string_column_stays_string_and_types_do_not_depend_on_block(tmp_path):
    # 'image' looks numeric at first, then is text; pitch is integer at first, then fractional
    recs = [f"{i},1,2,{i}\n".encode() for i in range(200)] + [b"1.5,1,2,name.jpg\n"]
    path = tmp_path / "t.csv"
    build(path, recs)
    for block in (64, 1 << 24):
        table, rej = collect(path, block_size=block)
        assert table["pitch"].type == pa.float64()
        if block == 64:  # image inferred as int64 from the first block: the text row is a reject naming that
            assert [r.line for r in rej] == [202] and "inferred from the first rows" in rej[0].reason
        else:
            assert not rej and table["image"].to_pylist()[-1] == "name.jpg"
            assert table["pitch"].to_pylist()[-1] == 1.5


def test_duplicate_columns_are_an_error(tmp_path):
    p = tmp_path / "d.csv"
    p.write_bytes(b"yaw,pitch,yaw,roll,extra\n10,1,20,3,999\n")
    with pytest.raises(HpeError, match=r"d.csv: line 1: duplicate column name\(s\) 'yaw'"):
        open_table(p)
    t = pa.table([pa.array([1.0]), pa.array([2.0])], names=["yaw", "yaw"])
    pq.write_table(t, tmp_path / "d.parquet")
    with pytest.raises(HpeError, match="duplicate column"):
        open_table(tmp_path / "d.parquet")


def test_batches_raises_at_first_bad_row(tmp_path):
    p = tmp_path / "t.csv"
    build(p, [b"1,2,3,a\n", b"1,2\n", b"x,2,3,b\n"])
    with pytest.raises(HpeError, match=r"t.csv: line 3: expected 4 fields, got 2"):
        list(open_table(p).batches())


def test_encodings(tmp_path):
    p = tmp_path / "bom.csv"
    p.write_bytes(b"\xef\xbb\xbfpitch,yaw,roll\n1,2,3\n")
    assert read_table(p).columns.tolist() == ["pitch", "yaw", "roll"]
    p = tmp_path / "u16.csv"
    p.write_bytes("pitch,yaw,roll\n1,2,3\n".encode("utf-16"))
    with pytest.raises(HpeError, match="UTF-16"):
        open_table(p)
    p = tmp_path / "crlf.csv"
    p.write_bytes(b"pitch,yaw,roll\r\n1,2,3\r\n\r\n4,x,6\r\n7,8,9\r\n")
    table, rej = collect(p, block_size=8)
    assert table[LINE_COL].to_pylist() == [2, 5] and [(r.line, r.reason) for r in rej] == [
        (4, "non-numeric value in yaw")
    ]


def test_sniffed_by_content(tmp_path):
    df = pd.DataFrame({"pitch": [1.0], "yaw": [2.0], "roll": [3.0]})
    df.to_parquet(tmp_path / "p.csv")  # a Parquet file with a .csv name
    assert read_table(tmp_path / "p.csv")["yaw"].tolist() == [2.0]
    df.to_csv(tmp_path / "c.parquet", index=False)
    assert read_table(tmp_path / "c.parquet")["yaw"].tolist() == [2.0]
    df.to_pickle(tmp_path / "x.csv")
    with pytest.raises(HpeError, match="pickle"):
        open_table(tmp_path / "x.csv")


def test_parquet_lines_and_batches(tmp_path):
    n = 1000
    pq.write_table(
        pa.table({"pitch": np.arange(n, dtype=float), "yaw": np.zeros(n), "roll": np.zeros(n)}),
        tmp_path / "p.parquet",
        row_group_size=300,
    )
    src = open_table(tmp_path / "p.parquet", batch_size=128, with_lines=True)
    lines = np.concatenate([b.column(LINE_COL).to_numpy() for b in src.batches()])
    assert np.array_equal(lines, np.arange(1, n + 1))  # Parquet rows are 1-based rows
    assert LINE_COL not in open_table(tmp_path / "p.parquet").columns


def _peak_traced(fn):
    import tracemalloc

    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_rows(tmp_path):
    """Peak Python-traced memory of a full CSV pass is about the same at 20k and 80k rows (bounded blocks)."""
    rng = np.random.default_rng(1)
    peaks = []
    for n in (20_000, 80_000):
        p = tmp_path / f"m{n}.csv"
        pd.DataFrame(rng.normal(size=(n, 3)), columns=["pitch", "yaw", "roll"]).to_csv(p, index=False)

        def run():
            for _ in open_table(p, batch_size=4096, block_size=1 << 16).batches():
                pass

        peaks.append(_peak_traced(run))
    assert peaks[1] < 1.5 * peaks[0] + (1 << 20)
