"""Table CSV logs as people save them, read in chunks (Arrow's streaming CSV reader).

* **dialect**: the field delimiter (``,`` ``;`` tab ``|``) and the decimal mark (``,``
  under a ``;`` or tab delimiter when the numbers say so) are sniffed from the first lines
  unless the mapping's ``csv:`` section states them; fields may be quoted. The dialect
  found is recorded in the provenance.
* leading ``#`` lines (one may be ``# parknss_trial {json}``), one header line, an
  optional **units row** (every field a unit or empty; ``csv.units_row`` forces it on or
  off), then one line per sample; a **trailing delimiter** on every line is ignored.
* **column names** ``t [s]`` / ``VX [km/h]``: the name without the bracket, whose unit
  is the column's own unit (as a units row's).

Numbers are parsed by Arrow block by block, so memory holds the parsed float64 columns
of the mapped channels, never the file's text. A malformed file is diagnosed line by line
(streaming): one :class:`~parknss.errors.DataError` naming the line.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parknss.data.mapping import Column, CsvOptions
from parknss.data.meta import META_KEY, parse_meta
from parknss.errors import DataError, one_line
from parknss.signals import canonical_unit

DELIMITERS = (",", ";", "\t", "|")
SNIFF_LINES = 50  # data lines looked at to find the dialect and a units row
HEAD_BYTES = 1 << 20  # the part of the file read to find the header and dialect
BLOCK_BYTES = 1 << 22  # Arrow parses the file in blocks of about this size
_BRACKET = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\])]*)[\])]\s*$")
_NUMBER = re.compile(r"^[+-]?(\d+([.,]\d*)?|[.,]\d+)([eE][+-]?\d+)?$")
_COMMA_DECIMAL = re.compile(r"^[+-]?\d*,\d+([eE][+-]?\d+)?$")
_DOT_DECIMAL = re.compile(r"^[+-]?\d*\.\d+([eE][+-]?\d+)?$")


@dataclass
class CsvTable:
    """The columns of one CSV log and how it was read.

    Attributes:
        raw: column name (as in the header, without a bracket unit) -> Column (float64
            values, or str where a column holds text).
        meta: the parknss_trial metadata, if any.
        units: column name -> its unit from a bracket or the units row ('' for none).
        dialect: delimiter, decimal mark, quoting, units row, trailing delimiter, and
            whether each was sniffed (for the provenance).
    """

    raw: dict[str, Column]
    meta: dict
    units: dict[str, str] = field(default_factory=dict)
    dialect: dict = field(default_factory=dict)


def _open_text(path: Path):
    try:
        return open(path, encoding="utf-8-sig", newline="")
    except PermissionError as exc:
        raise DataError(f"{path}: cannot read the file (permission denied)") from exc
    except OSError as exc:
        raise DataError(f"{path}: cannot read the file ({one_line(exc)})") from exc


def _head(path: Path) -> list[str]:
    f = _open_text(path)
    try:
        text = f.read(HEAD_BYTES)
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not UTF-8 text (binary or corrupt file?)") from exc
    except OSError as exc:
        raise DataError(f"{path}: cannot read the file ({one_line(exc)})") from exc
    finally:
        f.close()
    lines = text.splitlines()
    if len(text) == HEAD_BYTES and lines:
        lines = lines[:-1]  # possibly cut
    return lines


def _split(line: str, delimiter: str) -> list[str] | None:
    try:
        return next(csv.reader([line], delimiter=delimiter, strict=True))
    except (csv.Error, StopIteration):
        return None


def _sniff(lines: list[str], opts: CsvOptions) -> tuple[str, str, bool]:
    """(delimiter, decimal, sniffed) from the header and the first data lines."""
    given = opts.model_fields_set
    if "delimiter" in given:
        delimiter = opts.delimiter
    else:
        delimiter, best = ",", 0
        for d in DELIMITERS:
            counts = {len(r) for ln in lines if (r := _split(ln, d)) is not None}
            n = next(iter(counts)) if len(counts) == 1 else 0
            if n > best:
                delimiter, best = d, n
    if "decimal" in given:
        return delimiter, opts.decimal, "delimiter" not in given
    decimal = "."
    if delimiter != ",":
        fields = [x.strip() for ln in lines[1:] for x in (_split(ln, delimiter) or [])]
        comma = sum(bool(_COMMA_DECIMAL.match(x)) for x in fields)
        dot = sum(bool(_DOT_DECIMAL.match(x)) for x in fields)
        decimal = "," if comma > dot else "."
    return delimiter, decimal, True


def _numeric(x: str) -> bool:
    return bool(_NUMBER.match(x)) or x.lower() in ("nan", "inf", "-inf", "+inf")


def _is_units_row(items: list[str]) -> bool:
    """No number, and at least half of the non-empty fields a unit parknss knows."""
    items = [x for x in items if x]
    known = [x for x in items if canonical_unit(x) is not None or x == "-"]
    return bool(items) and not any(_numeric(x) for x in items) and 2 * len(known) >= len(items)


def _header_names(fields: list[str]) -> tuple[list[str], dict[str, str]]:
    names, units = [], {}
    for h in fields:
        h = h.strip()
        m = _BRACKET.match(h)
        if m is not None and m["name"] and canonical_unit(m["unit"].strip()) is not None:
            names.append(m["name"].strip())
            units[m["name"].strip()] = m["unit"].strip()
        else:
            names.append(h)
    return names, units


def read_csv_table(path: Path, opts: CsvOptions) -> CsvTable:
    """Read one table CSV log (module text); DataError naming the line on any problem."""
    lines = _head(path)
    meta: dict = {}
    k = 0
    while k < len(lines) and lines[k].startswith("#"):
        body = lines[k][1:].strip()
        if body.startswith(META_KEY):
            meta = parse_meta(body[len(META_KEY):], path)
        k += 1
    while k < len(lines) and not lines[k].strip():
        k += 1
    if k >= len(lines):
        raise DataError(f"{path}: no header line (file holds only comments or blank lines)")
    header_line = k + 1
    sample = [ln for ln in lines[k:k + SNIFF_LINES + 2] if ln.strip()]
    delimiter, decimal, sniffed = _sniff(sample, opts)
    header_fields = _split(lines[k], delimiter)
    if header_fields is None:
        raise DataError(f"{path}: line {header_line}: the header has an unclosed quote")
    names, units = _header_names(header_fields)
    body = [(n + 1, ln) for n, ln in enumerate(lines[k + 1:k + 2 + SNIFF_LINES], start=k + 1)
            if ln.strip()]
    if not body:
        raise DataError(f"{path}: no data rows below the header")
    first = [x.strip().strip("[]()") for x in _split(body[0][1], delimiter) or []]
    text_row = bool([x for x in first if x]) and not any(_numeric(x) for x in first if x)
    units_row = opts.units_row if opts.units_row is not None else _is_units_row(first)
    if text_row and not units_row and opts.units_row is None:
        raise DataError(
            f"{path}: line {body[0][0]}: a row of text under the header (a units row with "
            "units parknss does not know?); set csv.units_row: true and each channel's "
            "unit in the mapping, or remove the row"
        )
    if units_row:
        for name, u in zip(names, first, strict=False):
            if u and u != "-":
                units.setdefault(name, u)
    trailing = len(names) > 1 and names[-1] == "" and all(
        (r := _split(ln, delimiter)) is not None and r and not r[-1].strip()
        for _, ln in body[1 if units_row else 0:]
    )
    if trailing:
        names = names[:-1]
    dup = sorted({h for h in names if names.count(h) > 1})
    if dup or "" in names:
        what = f"duplicate column {dup[0]!r}" if dup else "an empty column name"
        raise DataError(f"{path}: line {header_line}: header has {what}")
    data_start = body[1][0] - 1 if units_row and len(body) > 1 else body[0][0] - 1
    if units_row and len(body) < 2:
        raise DataError(f"{path}: no data rows below the header")
    dialect = {
        "delimiter": delimiter, "decimal": decimal, "sniffed": sniffed,
        "units_row": bool(units_row), "trailing_delimiter": trailing,
        "quoted": any('"' in ln for _, ln in body),
    }
    raw = _read_columns(path, names, trailing, data_start, delimiter, decimal)
    return CsvTable(raw, meta, units, dialect)


def _locator(data_start: int):
    def locate(i: int) -> str:
        return f"line {data_start + i + 1}"

    return locate


def _read_columns(path: Path, names: list[str], trailing: bool, data_start: int,
                  delimiter: str, decimal: str) -> dict[str, Column]:
    """The data rows in blocks through Arrow; text columns kept as str."""
    import pyarrow as pa
    import pyarrow.csv as pc

    all_names = [*names, "__trailing__"] if trailing else list(names)
    read = pc.ReadOptions(skip_rows=data_start, column_names=all_names,
                          block_size=BLOCK_BYTES, encoding="utf8")
    parse = pc.ParseOptions(delimiter=delimiter, quote_char='"', newlines_in_values=False,
                            ignore_empty_lines=True)

    def convert(as_text: bool) -> pc.ConvertOptions:
        return pc.ConvertOptions(
            include_columns=names, null_values=[], strings_can_be_null=False,
            quoted_strings_can_be_null=False, decimal_point=decimal,
            column_types={n: pa.string() for n in names} if as_text else None,
        )

    pool = pa.system_memory_pool()  # freed blocks go back to the system
    n_max = _count_lines(path)  # rows <= lines: the columns are filled in place
    for as_text in (False, True):
        cols = {n: _Filler(n_max) for n in names}
        try:
            with pc.open_csv(path, read_options=read, parse_options=parse,
                             convert_options=convert(as_text), memory_pool=pool) as reader:
                for batch in reader:
                    for n, col in zip(batch.schema.names, batch.columns, strict=True):
                        cols[n].add(col)
                    del batch
        except pa.ArrowInvalid as exc:
            if "conversion error" in str(exc) and not as_text:
                continue  # text appeared in a numeric column after the first block
            _diagnose(path, len(all_names), data_start, delimiter, exc)
        except (pa.ArrowException, OSError, UnicodeDecodeError) as exc:
            raise DataError(f"{path}: not a readable CSV file ({one_line(exc)})") from exc
        break
    locate = _locator(data_start)
    out = {n: Column(cols[n].values(), locate) for n in names}
    if not len(next(iter(out.values())).values):
        raise DataError(f"{path}: no data rows below the header")
    return out


def _count_lines(path: Path, chunk: int = 1 << 24) -> int:
    """Newlines in the file (+1): an upper bound on its rows, read in binary chunks."""
    n = 1
    with open(path, "rb") as f:
        while piece := f.read(chunk):
            n += piece.count(b"\n")
    return n


class _Filler:
    """One column filled block by block: float64 into one preallocated array while every
    block is numeric; text (str objects) once a block is not."""

    def __init__(self, capacity: int) -> None:
        self.num: np.ndarray | None = np.empty(capacity, dtype=np.float64)
        self.n = 0
        self.text: list[np.ndarray] = []

    def add(self, col) -> None:
        import pyarrow as pa

        if self.num is not None and (pa.types.is_floating(col.type)
                                     or pa.types.is_integer(col.type)):
            k = len(col)
            self.num[self.n:self.n + k] = col.to_numpy(zero_copy_only=False)
            self.n += k
            return
        if self.num is not None:  # switch to text: what was numbers becomes their text
            self.text = [self.num[: self.n].astype(object)]
            self.num = None
        self.text.append(np.asarray(col.cast(pa.string()).to_pylist(), dtype=object))

    def values(self) -> np.ndarray:
        if self.num is not None:
            return self.num[: self.n]
        return np.concatenate(self.text) if self.text else np.zeros(0)


def _diagnose(path: Path, n_fields: int, data_start: int, delimiter: str, exc) -> None:
    """The first malformed line of the data, found line by line (streaming): DataError."""
    f = _open_text(path)
    last_bad = None
    try:
        for n, line in enumerate(f, start=1):
            if n <= data_start or not line.strip():
                continue
            fields = _split(line.rstrip("\r\n"), delimiter)
            if fields is None:
                raise DataError(
                    f"{path}: line {n}: unbalanced quote '\"' (a field opens a quote that "
                    "does not close on its line)"
                )
            if len(fields) != n_fields:
                last_bad = (n, len(fields))
                break
        if last_bad is not None:
            n, got = last_bad
            rest = any(ln.strip() for ln in f)
            last = not rest
            raise DataError(
                f"{path}: line {n}{' (the last)' if last else ''}: {got} fields, the "
                f"header has {n_fields} ({'truncated file?' if last else 'malformed row'})"
            )
    except UnicodeDecodeError as err:
        raise DataError(f"{path}: not UTF-8 text (binary or corrupt file?)") from err
    finally:
        f.close()
    raise DataError(f"{path}: not a readable CSV file ({one_line(exc)})") from exc
