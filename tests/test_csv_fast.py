"""The CSV fast path (pyarrow's reader, :func:`quadsim.logs.csvfile._fast_columns`) gives the
same numbers as the plain parser, and hands every file it does not read plainly back to it."""

import gzip

import numpy as np
import pytest

from quadsim.logs import csvfile
from quadsim.logs.csvfile import read_log_columns

pytest.importorskip("pyarrow")

HEADER = "t,x,y,z,rotor_1,cmd_1,vbat"


def _rows(n=300, seed=4):
    """Rows of decimals written as a logger does: various widths, exponents, signs."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.002 + 1.7e3
    cols = [rng.normal(0, 1, n), rng.normal(0, 1e-5, n), rng.uniform(-3e4, 3e4, n),
            rng.uniform(1000, 2600, n), rng.uniform(0, 1, n), 4.2 - 1e-3 * rng.random(n)]
    lines = []
    for k in range(n):
        cells = [repr(float(t[k]))] + [
            (f"{v:.17g}" if k % 3 == 0 else f"{v:.6e}" if k % 3 == 1 else repr(float(v)))
            for v in (c[k] for c in cols)]
        lines.append(",".join(cells))
    return lines


def _plain(path, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(csvfile, "_fast_columns", lambda raw: None)
        return read_log_columns(path)


@pytest.mark.parametrize("form", ["csv", "gz", "bom_crlf"])
def test_fast_equals_plain(tmp_path, monkeypatch, form):
    text = "\n".join([HEADER, *_rows()]) + "\n"
    if form == "bom_crlf":
        data = ("\ufeff" + text.replace("\n", "\r\n")).encode()
    else:
        data = text.encode()
    path = tmp_path / ("log.csv.gz" if form == "gz" else "log.csv")
    path.write_bytes(gzip.compress(data) if form == "gz" else data)
    raw = gzip.decompress(path.read_bytes()) if form == "gz" else path.read_bytes()
    assert csvfile._fast_columns(raw) is not None       # the fast path is the one taken
    fast, plain = read_log_columns(path), _plain(path, monkeypatch)
    assert list(fast) == list(plain) == HEADER.split(",")
    for name in plain:
        assert fast[name].dtype == np.float64 and fast[name].flags.writeable
        assert np.array_equal(fast[name], plain[name])            # bit for bit
        assert np.array_equal(fast[name].view(np.int64), plain[name].view(np.int64))


@pytest.mark.parametrize("cell", ["nan", "", " 1.5", "1_000", "inf", "abc"])
def test_other_cells_go_to_the_plain_parser(tmp_path, monkeypatch, cell):
    rows = _rows(20)
    rows[7] = cell + rows[7][rows[7].index(","):]
    path = tmp_path / "log.csv"
    path.write_text("\n".join([HEADER, *rows]) + "\n")
    assert csvfile._fast_columns(path.read_bytes()) is None
    if cell == "abc":
        with pytest.raises(Exception, match="line 9: 'abc' is not a number"):
            read_log_columns(path)
        return
    fast, plain = read_log_columns(path), _plain(path, monkeypatch)
    for name in plain:
        assert np.array_equal(fast[name], plain[name], equal_nan=True)
    assert np.isnan(fast["t"][7]) == (cell in ("nan", ""))


def test_problems_worded_by_the_plain_parser(tmp_path):
    path = tmp_path / "log.csv"
    rows = _rows(10)
    rows[3] += ",1"
    path.write_text("\n".join([HEADER, *rows]) + "\n")
    with pytest.raises(Exception, match="line 5: 8 fields, header has 7"):
        read_log_columns(path)
    path.write_text("t,x,t\n1,2,3\n")
    with pytest.raises(Exception, match="t: column appears more than once"):
        read_log_columns(path)
    path.write_text(HEADER + "\n")
    with pytest.raises(Exception, match="no data rows"):
        read_log_columns(path)


def test_a_chunked_column_is_read_as_to_numpy_reads_it():
    """:func:`quadsim.logs.csvfile._float_column` (the value buffers copied, no pandas) on
    a column of several chunks, one of them a slice (its buffer offset): the numbers of
    pyarrow's ``to_numpy``, bit for bit, in a new writable array."""
    import pyarrow as pa

    rng = np.random.default_rng(1)
    parts = [rng.normal(size=n) for n in (5, 1, 9)]
    column = pa.chunked_array([pa.array(parts[0]), pa.array(parts[1]),
                               pa.array(np.concatenate([[7.0, 8.0], parts[2]])).slice(2)])
    out = csvfile._float_column(column)
    assert out.flags.writeable and out.dtype == np.float64
    assert np.array_equal(out.view(np.int64), np.asarray(column.to_numpy()).view(np.int64))
    assert np.array_equal(out, np.concatenate(parts))
