"""The user's own data (issue 11, item 7): a table of patterns in a CSV or ``.npz`` file.

    python train.py data=file data.path=my.csv 'data.inputs=[q1,dq1,ddq1]' 'data.outputs=[tau1]'

CSV: comma-separated, one header row naming the columns (names unique), then one pattern per line;
lines starting with ``#`` before the header are skipped (so ``selpres-export``'s own CSVs load as they
are). ``.npz``: one 1-D numeric array per column, named by the column; or a 2-D array ``table`` with a
string array ``columns`` naming its columns. ``data.inputs`` and ``data.outputs`` pick columns, in the
order the network reads and predicts them.

Every problem is a :class:`DataFileError` (a ConfigError: ``python train.py`` prints one line and exits 2
before writing anything) naming the file, the column and the row: a missing column (the columns the
file has are listed), a duplicate header name, a cell that is not a number, NaN or ±inf, a row with too
few or too many cells, too few rows for the held-out split or the schedule. CSV rows are named by
their line number in the file, so an editor finds them.
"""

from __future__ import annotations

import csv
import functools
import hashlib
import io
import math
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch

from selpres.errors import ConfigError, FileError, not_a_file
from selpres.storage import one_line

NPZ_TABLE, NPZ_COLUMNS = "table", "columns"


class DataFileError(FileError):
    """A data file selpres cannot train on: one line naming the file, where (column, row) and the problem."""


def _path(path: str | Path | None) -> Path:
    if not isinstance(path, (str, Path)) or not str(path) or str(path) == "???":
        raise ConfigError("data.path", path, "the CSV or .npz file to train on (data=file data.path=my.csv)")
    p = Path(path).expanduser()
    if not p.is_file():
        raise DataFileError(p, "file", f"{not_a_file(p)} (data.path must name a CSV or .npz file)")
    return p


@contextmanager
def _reading(path: Path) -> Iterator[None]:
    """An OSError while reading the data file (removed or made unreadable since it was checked) as a DataFileError
    naming it: a read failure, said as one, never as a failed write."""
    try:
        yield
    except OSError as e:
        raise DataFileError(path, "file", f"cannot be read ({e.strerror or e})") from None


def file_digest(path: str | Path) -> str:
    """sha256 of the file's bytes: a data file's identity (its path is not). A job asks three times (the
    task's record, the data's hash, the job's hash); the file is read once while it is unchanged."""
    p = _path(path)
    st = p.stat()
    return _digest(str(p.resolve()), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=16)
def _digest(path: str, mtime_ns: int, size: int) -> str:
    h = hashlib.sha256()
    with _reading(Path(path)), open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# ------------------------------------------------------------------------------------------------- CSV
def _not_text(path: Path, data: bytes, e: UnicodeDecodeError, first_line: int = 1) -> DataFileError:
    """A file that is not UTF-8 text, named by the line and byte (never by its contents)."""
    line = first_line + data.count(b"\n", 0, e.start)
    return DataFileError(
        path,
        f"line {line}",
        f"byte 0x{data[e.start]:02x} is not UTF-8 text: a CSV must be UTF-8 (a binary file is not a CSV; "
        "re-save it as UTF-8 or use a .npz)",
    )


BOM = b"\xef\xbb\xbf"  # the UTF-8 byte-order mark spreadsheets write first: not part of the first column's name


def _csv_text(path: Path) -> str:
    """The whole file as text (newlines kept as they are); DataFileError if it is not UTF-8 or holds NUL bytes."""
    with _reading(path):
        data = path.read_bytes().removeprefix(BOM)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise _not_text(path, data, e) from None
    if "\0" in text:
        line = 1 + text.count("\n", 0, text.index("\0"))
        raise DataFileError(path, f"line {line}", "holds a NUL byte: a binary file, not a CSV")
    return text


def _csv_header(path: Path) -> tuple[int, list[str]]:
    """(1-based line number of the header, its names); reads the file only up to the header."""
    with _reading(path), open(path, "rb") as f:
        for number, raw in enumerate(f, 1):
            try:
                line = (raw.removeprefix(BOM) if number == 1 else raw).decode("utf-8")
            except UnicodeDecodeError as e:
                raise _not_text(path, raw, e, number) from None
            if "\0" in line:
                raise DataFileError(path, f"line {number}", "holds a NUL byte: a binary file, not a CSV")
            if line.strip() and not line.lstrip().startswith("#"):
                return number, [c.strip() for c in next(csv.reader([line]))]
    raise DataFileError(path, "header", "no header row (the first line that is not a '#' comment names the columns)")


def _npz_columns(path: Path) -> dict[str, np.ndarray]:
    with _reading(path), open(path, "rb") as f:
        head = f.read(6)
    if not head.startswith(b"PK"):  # every zip, a .npz too, starts so; numpy would take other bytes for a pickle
        what = (
            "is empty (0 bytes)"
            if not head
            else "is a .npy array (np.save), not a .npz"
            if head == b"\x93NUMPY"
            else "is not a .npz: its first bytes are not a zip archive's"
        )
        raise DataFileError(path, "file", f"{what} (np.savez writes a .npz: one named array per column)")
    arrays = {}
    try:
        with _reading(path), np.load(path, allow_pickle=False) as z:
            for k in z.files:
                try:
                    arrays[k] = z[k]
                except ValueError as e:
                    if "allow_pickle" not in str(e):
                        raise
                    raise DataFileError(
                        path, f"array {k!r}", "holds Python objects (dtype object): a column holds numbers"
                    ) from None
    except (ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:  # cut, flipped, not a zip
        if isinstance(e, DataFileError):
            raise
        raise DataFileError(path, "file", f"not a readable .npz ({type(e).__name__}: {one_line(str(e))})") from None
    for k, v in arrays.items():
        if not isinstance(v, np.ndarray):  # a zip member that is not a .npy file: numpy hands back its bytes
            raise DataFileError(path, f"member {k!r}", "is not a .npy array (np.savez writes one per column)")
    if NPZ_TABLE in arrays:
        table, names = arrays[NPZ_TABLE], arrays.get(NPZ_COLUMNS)
        if names is None or names.ndim != 1 or table.ndim != 2 or len(names) != table.shape[1]:
            raise DataFileError(
                path,
                f"array {NPZ_TABLE!r}",
                f"a 2-D table needs a 1-D string array {NPZ_COLUMNS!r} naming each of its columns",
            )
        names = [str(n) for n in names]
        _no_duplicates(path, names)
        return {n: table[:, i] for i, n in enumerate(names)}
    for k, v in arrays.items():
        if v.ndim != 1:
            raise DataFileError(
                path,
                f"array {k!r}",
                f"has shape {v.shape}: expected one 1-D array per column (or a 2-D {NPZ_TABLE!r} with {NPZ_COLUMNS!r})",
            )
    return arrays


def _no_duplicates(path: Path, names: list[str]) -> None:
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if name in seen:
            raise DataFileError(
                path,
                f"column {name!r}",
                f"named twice in the header (columns {seen[name] + 1} and {i + 1}): every column needs its own name",
            )
        seen[name] = i


def columns(path: str | Path | None) -> tuple[str, ...]:
    """The column names a data file holds (reads only its header for a CSV)."""
    p = _path(path)
    if p.suffix.lower() == ".npz":
        return tuple(_npz_columns(p))
    _, names = _csv_header(p)
    _no_duplicates(p, names)
    return tuple(names)


def check_columns(path: str | Path | None, inputs, outputs) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(inputs, outputs) checked against the file's header: present, not empty, not overlapping."""
    have = columns(path)
    picked = {}
    for key, names in (("data.inputs", inputs), ("data.outputs", outputs)):
        if not names or not all(isinstance(n, str) for n in names):
            raise ConfigError(
                key,
                None if names is None else list(names),
                f"a non-empty list of column names of {path} (it has {list(have)})",
            )
        for n in names:
            if n not in have:
                raise DataFileError(path, f"column {n!r} ({key})", f"not in the file: its columns are {list(have)}")
        dup = sorted({n for n in names if list(names).count(n) > 1})
        if dup:
            raise ConfigError(key, list(names), f"each column once ({dup[0]!r} is listed twice)")
        picked[key] = tuple(names)
    both = sorted(set(picked["data.inputs"]) & set(picked["data.outputs"]))
    if both:
        raise ConfigError("data.outputs", list(outputs), f"columns that are not also inputs ({both[0]!r} is both)")
    return picked["data.inputs"], picked["data.outputs"]


def _parse_csv(path: Path, wanted: list[str]) -> np.ndarray:
    """The wanted columns as float64 ``[rows, len(wanted)]``; errors name the column and the line."""
    header_line, names = _csv_header(path)
    index = [names.index(n) for n in wanted]
    text = _csv_text(path)
    body = [line for line in text.splitlines()[header_line:] if line.strip()]
    if not body:
        return np.empty((0, len(wanted)))
    commas = len(names) - 1
    if all(line.count(",") == commas for line in body) and not any('"' in line for line in body):
        try:  # fast path: numpy's parser; on any complaint, the careful pass below says where
            table = np.loadtxt(body, delimiter=",", usecols=index, dtype=np.float64, ndmin=2, comments=None)
            if np.isfinite(table).all():
                return table.reshape(-1, len(wanted))
        except ValueError:
            pass
    out = np.empty((0, len(wanted)))
    values: list[list[float]] = []
    rows = csv.reader(io.StringIO(text, newline=""))
    number = 0
    while True:
        try:
            row = next(rows)
        except StopIteration:
            break
        except csv.Error as e:
            raise DataFileError(path, f"line {rows.line_num}", f"cannot be read as CSV ({e})") from None
        number = rows.line_num
        if number <= header_line or not any(cell.strip() for cell in row):
            continue
        if len(row) != len(names):
            raise DataFileError(path, f"line {number}", f"has {len(row)} cells, the header names {len(names)}")
        parsed = []
        for col, i in zip(wanted, index):
            cell = row[i].strip()
            try:
                v = float(cell)
            except ValueError:
                raise DataFileError(path, f"column {col!r}, line {number}", f"{_shown(cell)} is not a number") from None
            if not math.isfinite(v):
                raise DataFileError(
                    path,
                    f"column {col!r}, line {number}",
                    f"{_shown(cell)}: NaN and inf are not allowed (drop or repair the row)",
                )
            parsed.append(v)
        values.append(parsed)
    return np.array(values, dtype=np.float64).reshape(-1, len(wanted)) if values else out


def _shown(cell: str, limit: int = 40) -> str:
    """A cell as a message quotes it: at most ``limit`` characters (a garbage file's cell can be kilobytes)."""
    return repr(cell) if len(cell) <= limit else repr(cell[:limit]) + f"… ({len(cell):,} characters)"


def _parse_npz(path: Path, wanted: list[str]) -> np.ndarray:
    arrays = _npz_columns(path)
    length = None
    cols = []
    for name in wanted:
        a = arrays[name]
        if a.dtype.kind not in "biuf":
            raise DataFileError(path, f"column {name!r}", f"has dtype {a.dtype}: expected numbers")
        if length is not None and len(a) != length:
            raise DataFileError(path, f"column {name!r}", f"has {len(a)} rows, column {wanted[0]!r} has {length}")
        length = len(a)
        bad = np.flatnonzero(~np.isfinite(a.astype(np.float64)))
        if bad.size:
            raise DataFileError(
                path,
                f"column {name!r}, row {int(bad[0])} (0-based)",
                f"{a[bad[0]]!r}: NaN and inf are not allowed (drop or repair the row)",
            )
        cols.append(a.astype(np.float64))
    return np.stack(cols, 1)


def load_columns(path: str | Path, wanted: list[str]) -> torch.Tensor:
    """The ``wanted`` columns of a CSV or .npz data file as float64 ``[rows, len(wanted)]``."""
    p = _path(path)
    table = _parse_npz(p, wanted) if p.suffix.lower() == ".npz" else _parse_csv(p, wanted)
    if table.shape[0] == 0:
        raise DataFileError(p, "rows", "none: the file has a header but no patterns")
    return torch.from_numpy(np.ascontiguousarray(table))


# ------------------------------------------------------------------------------------------ ranges
COLLAPSE_SHARE = 0.99  # a column "collapsed by an outlier": this share of its rows ...
COLLAPSE_WIDTH = 0.01  # ... lies in this fraction of its scaled range


def row_label(path: str | Path, row: int) -> str:
    """Where data row ``row`` (0-based, in file order) is: its line in a CSV (as an editor counts), else
    its index in the .npz arrays."""
    p = Path(path)
    if p.suffix.lower() == ".npz":
        return f"row {row} (0-based)"
    header_line, _ = _csv_header(p)
    seen = -1
    for number, line in enumerate(_csv_text(p).splitlines(), 1):
        if number > header_line and line.strip():
            seen += 1
            if seen == row:
                return f"line {number}"
    return f"data row {row + 1}"


def check_ranges(
    path: str | Path, names: list[str], table: torch.Tensor, n_outputs: int, margin: float, lo: float, hi: float
) -> list[str]:
    """Refuse a column whose range cannot be scaled in float64; return warnings for columns an outlier
    collapses. ``table``: every row of the file (held-out rows too: they are scored), inputs then the
    ``n_outputs`` targets.

    Each column is mapped from [min − margin·range, max + margin·range] onto [lo, hi] (selpres.data.paper.
    Scaler): the widened range must be finite. A target's errors are reported in its own unit, as sums of
    squared errors over the rows: (range / (hi − lo))² · rows must be finite too (a 1e308 target made every
    Nm metric infinite). The row named is the one farthest from the column's median: the outlier."""
    warnings = []
    big = math.sqrt(np.finfo(np.float64).max / max(1, table.shape[0] * max(1, n_outputs)))
    for k, name in enumerate(names):
        col = table[:, k]
        v0, v1 = float(col.min()), float(col.max())
        target = k >= len(names) - n_outputs
        with np.errstate(over="ignore"):
            widened = (np.float64(v1) - np.float64(v0)) * np.float64(1 + 2 * margin)
        limit = big * (hi - lo) if target else np.finfo(np.float64).max
        if not (math.isfinite(widened) and widened <= limit):
            med = float(col.median())
            far = int(torch.argmax((col - med).abs())) if math.isfinite(med) else int(torch.argmax(col.abs()))
            what = "a target" if target else "an input"
            bound = f"at most {limit:.3g} for {what} column of {table.shape[0]:,} rows"
            raise DataFileError(
                path,
                f"column {name!r}, {row_label(path, far)}",
                f"{float(col[far])!r}: the column spans [{v0:.6g}, {v1:.6g}], a range that cannot be scaled in "
                f"float64 ({bound} with data.scaling.margin={margin:g}); drop or repair the row",
            )
        span = v1 - v0
        if span > 0 and table.shape[0] >= 100:
            q = torch.quantile(col, torch.tensor([(1 - COLLAPSE_SHARE) / 2, (1 + COLLAPSE_SHARE) / 2], dtype=col.dtype))
            width = float(q[1] - q[0]) / span
            if width < COLLAPSE_WIDTH:
                med = float(col.median())
                far = int(torch.argmax((col - med).abs()))
                warnings.append(
                    f"{path}: column {name!r}: {COLLAPSE_SHARE:.0%} of its rows lie in {width:.2g} of its range "
                    f"[{v0:.6g}, {v1:.6g}] (an outlier: {float(col[far])!r} at {row_label(path, far)}); the scaling "
                    "squeezes them into a sliver of the sigmoid's range"
                )
    return warnings
