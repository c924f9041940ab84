"""Reading a CSV (``.csv``, ``.csv.gz``) or Parquet flight-log file into its columns, before
any validation of values (:mod:`quadsim.logs.flightlog` validates them).

CSV: UTF-8 text (a spreadsheet's byte-order mark is skipped), gzip allowed (detected by its
magic bytes, not by the name), one header row, comma-separated numbers; an empty cell is NaN.
Problems are one line naming the file and the CSV line (header = line 1): a row with another
number of fields than the header, text that is not a number (the column named), a column
named twice, no data rows. A file that starts with a ULog or DataFlash magic but did not
parse as one is refused as a damaged binary log, not read as text
(:func:`quadsim.logs.refuse_binary`).

Speed: where pyarrow is installed (the ``parquet`` extra), a CSV whose data rows hold only
plain decimal numbers (bytes ``0-9 . e E + -``, commas and line ends; no empty cell) is parsed
by pyarrow's CSV reader (:func:`_fast_columns`), about 2x faster than the plain parser on the
real Crazyflie logs; both convert a decimal to the nearest double, so the arrays are the same
(``tests/test_csv_fast.py``). Any other file -- and any file pyarrow refuses -- is read by the
plain parser, which also words every problem.

Parquet (optional, ``pip install -e '.[parquet]'``, pyarrow): the same column names as
float64; row k is reported as line k + 2. Example::

    >>> from quadsim.logs.csvfile import read_log_columns
    >>> columns = read_log_columns("flight.csv.gz")      # {"t": array, "x": array, ...}
"""

from __future__ import annotations

import gzip
import zlib
from pathlib import Path

import numpy as np

from ..core.errors import InputError, field_error

__all__ = ["read_log_columns"]


def _open_bytes(path: Path) -> bytes:
    """The file's bytes, gunzipped where it starts with gzip's magic bytes; a corrupt or
    truncated gzip stream is one :class:`InputError` naming the file (zlib's own error is not
    an ``OSError``)."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as exc:
            raise field_error(path, "gzip", f"corrupt data: {exc}") from None
    return raw


def _decode(path: Path, raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")  # a spreadsheet may prepend a BOM
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text (CSV) file") from None


#: the bytes a data row may hold for the fast path (:func:`_fast_columns`): plain decimal
#: numbers, commas, line ends. What pyarrow and Python's ``float`` both read as the nearest
#: double; anything else (``nan``, spaces, ``1_000``, an empty cell) goes to the plain parser.
_PLAIN = b"0123456789.eE+-,\r\n"
_BOM = b"\xef\xbb\xbf"


def _fast_columns(raw: bytes) -> dict[str, np.ndarray] | None:
    """The columns of CSV bytes ``raw`` by pyarrow's CSV reader (one thread, every column
    float64), or None where the plain parser must read them: pyarrow not installed, a header
    that is not one line of distinct ASCII names followed by at least one data row, a data
    byte outside :data:`_PLAIN`, or anything pyarrow refuses (a row of another width, a
    cell that is not a number)."""
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:
        return None
    raw = raw[len(_BOM):] if raw.startswith(_BOM) else raw
    end = raw.find(b"\n")
    if end <= 0 or not raw[:end].isascii():
        return None
    header = [h.strip() for h in raw[:end].decode("ascii").split(",")]
    body = raw[end + 1:]
    # (not body or body.isspace(): not body.strip(), without copying the body)
    if (len(set(header)) < len(header) or not all(header) or not body or body.isspace()
            or body.translate(None, _PLAIN)):
        return None
    try:
        table = pacsv.read_csv(
            pa.py_buffer(body),
            read_options=pacsv.ReadOptions(use_threads=False, column_names=header),
            convert_options=pacsv.ConvertOptions(
                column_types={h: pa.float64() for h in header}, null_values=[],
                strings_can_be_null=False, quoted_strings_can_be_null=False))
    except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError):
        return None
    if table.num_rows == 0 or any(c.null_count for c in table.columns):
        return None
    # a writable copy (pyarrow's own buffers are read-only), as the plain parser's
    return {name: _float_column(table.column(name)) for name in header}


def _float_column(column) -> np.ndarray:
    """A float64 pyarrow column without nulls (a ChunkedArray) as a new numpy array: each
    chunk's value buffer copied in (the numbers of ``column.to_numpy()``, without
    ``to_numpy``'s import of pandas, ~0.6 s of a command's CPU)."""
    out = np.empty(len(column))
    k = 0
    for chunk in column.chunks:
        n = len(chunk)
        out[k:k + n] = np.frombuffer(chunk.buffers()[1], dtype=np.float64, count=n,
                                     offset=chunk.offset * 8)
        k += n
    return out


def _parse_rows(path: Path, header: list[str], lines: list[str]) -> np.ndarray:
    """Numbers (N, C); text that is not a number is an error naming line and column.

    Every cell is read by Python's ``float`` (numpy's conversion of a ``str`` calls it), all
    cells at once when every row has the header's width and no cell is empty; otherwise row
    by row, where an empty cell is NaN and a problem names its line."""
    width = len(header)
    if all(line.count(",") == width - 1 for line in lines):
        try:
            return np.array(",".join(lines).split(","), dtype=float).reshape(len(lines), width)
        except ValueError:
            pass                # an empty cell (NaN) or text: read row by row below
    data = np.empty((len(lines), width))
    for row, line in enumerate(lines):
        cells = line.split(",")
        if len(cells) != width:
            raise InputError(f"{path}: line {row + 2}: {len(cells)} fields, header has {width}")
        try:
            data[row] = [float(c) if c.strip() else np.nan for c in cells]
        except ValueError:
            for col, cell in enumerate(cells):
                try:
                    float(cell) if cell.strip() else None
                except ValueError:
                    raise field_error(path, header[col],
                                      f"line {row + 2}: {cell.strip()!r} is not a number") from None
    return data


def _read_parquet_columns(path: Path) -> dict[str, np.ndarray]:
    """Columns of a Parquet log (optional: needs pyarrow, ``pip install -e '.[parquet]'``)."""
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise InputError(f"{path}: reading Parquet needs pyarrow "
                         "(pip install -e '.[parquet]')") from None
    try:
        table = pq.read_table(path)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: not a readable Parquet file: {' '.join(str(exc).split())}"
                         ) from None
    if table.num_rows == 0:
        raise InputError(f"{path}: no data rows")
    columns = {}
    for name in table.column_names:
        try:
            columns[name] = table.column(name).to_numpy(zero_copy_only=False).astype(float)
        except (TypeError, ValueError):
            raise field_error(path, name, "column is not numeric") from None
    return columns


def read_log_columns(path: str | Path) -> dict[str, np.ndarray]:
    """Every column of a log file as float arrays, by header name (no validation of values).

    CSV (``.csv``, ``.csv.gz``) or Parquet (``.parquet``, same column names). Problems are
    reported by CSV line number (header = line 1; for Parquet, row k is line k + 2)."""
    path = Path(path)
    if path.suffix == ".parquet":
        return _read_parquet_columns(path)
    from . import refuse_binary  # a damaged ULog/DataFlash, not a CSV

    refuse_binary(path)
    raw = _open_bytes(path)
    fast = _fast_columns(raw)
    if fast is not None:
        return fast
    text = _decode(path, raw)
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise InputError(f"{path}: empty file (expected a header row)")
    header = [h.strip() for h in lines[0].split(",")]
    duplicates = sorted({h for h in header if header.count(h) > 1})
    if duplicates:
        raise field_error(path, duplicates[0], "column appears more than once in the header")
    if len(lines) < 2:
        raise InputError(f"{path}: no data rows after the header")
    data = _parse_rows(path, header, lines[1:])
    return {name: data[:, i] for i, name in enumerate(header)}
