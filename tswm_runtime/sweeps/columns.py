"""A sweep's table as Arrow columns built from numpy, without pandas.

``pyarrow.array`` asks pandas about every input it is given (importing pandas cost a warm sweep
process 0.36 s of CPU), so the columns are made from their
buffers instead: numbers zero-copy from a contiguous numpy array, text as a few distinct strings
and a code per case, decoded by Arrow's C++ ``dictionary_decode``. ``digest`` checksums a table
from the same buffers, ``numbers_of`` reads a numeric column back as numpy, and ``parquet``
writes a table.
"""
from __future__ import annotations

import hashlib

import numpy as np
import pyarrow as pa

NUMBER_TYPES = {np.dtype(np.float64): pa.float64(), np.dtype(np.int64): pa.int64()}


def numbers(values: np.ndarray) -> pa.Array:
    """A float64 or int64 numpy vector as an Arrow array (zero-copy when it is contiguous)."""
    values = np.ascontiguousarray(values)
    return pa.Array.from_buffers(NUMBER_TYPES[values.dtype], values.size, [None, pa.py_buffer(values)])


def _strings(words: list[str]) -> pa.Array:
    encoded = [word.encode() for word in words]
    offsets = np.zeros(len(encoded) + 1, np.int32)
    np.cumsum([len(e) for e in encoded], out=offsets[1:])
    return pa.Array.from_buffers(pa.string(), len(words), [None, pa.py_buffer(offsets),
                                                           pa.py_buffer(b"".join(encoded))])


def texts(words: list[str], which: np.ndarray) -> pa.Array:
    """A text column whose row i is ``words[which[i]]`` (``words``: the few distinct values)."""
    codes = np.ascontiguousarray(which, dtype=np.int32)
    indices = pa.Array.from_buffers(pa.int32(), codes.size, [None, pa.py_buffer(codes)])
    return pa.DictionaryArray.from_arrays(indices, _strings(words)).dictionary_decode()


def table(columns: dict[str, pa.Array]) -> pa.Table:
    return pa.Table.from_arrays(list(columns.values()), names=list(columns))


def parquet(arrow: pa.Table) -> bytes:
    """The table as a parquet file's bytes; only the text columns dictionary-encoded (trying it on
    every column, parquet's default, took 2.3 times the CPU for a file 8 % larger)."""
    import pyarrow.parquet as pq

    text = [name for name, kind in zip(arrow.column_names, arrow.schema.types) if pa.types.is_string(kind)]
    buffer = pa.BufferOutputStream()
    pq.write_table(arrow, buffer, use_dictionary=text)
    return buffer.getvalue().to_pybytes()


def _chunks(column) -> list[pa.Array]:
    return column.chunks if isinstance(column, pa.ChunkedArray) else [column]


def _values(chunk: pa.Array) -> np.ndarray:
    """A numeric chunk's values as numpy, zero-copy."""
    dtype = next((d for d, t in NUMBER_TYPES.items() if t == chunk.type), None)
    if dtype is None:
        raise TypeError(f"a column of {chunk.type}: a sweep's numbers are float64 or int64")
    return np.frombuffer(chunk.buffers()[1], dtype)[chunk.offset:chunk.offset + len(chunk)]


def numbers_of(column) -> np.ndarray:
    """A float64 or int64 Arrow column (array or chunked, without nulls) as a numpy vector."""
    parts = [_values(chunk) for chunk in _chunks(column)]
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def _held_bytes(chunk: pa.Array) -> tuple:
    """The bytes of a chunk's values, independent of how a column is split into chunks: for
    numbers (their bytes, b''), for text (each value's length as int64, the UTF-8 characters).
    TypeError for a column no sweep writes (other types, missing values)."""
    if chunk.null_count:
        raise TypeError("a column with missing values: a sweep's columns have none")
    if not (pa.types.is_string(chunk.type) or pa.types.is_large_string(chunk.type)):
        return _values(chunk).tobytes(), b""
    width = np.int32 if pa.types.is_string(chunk.type) else np.int64
    offsets = np.frombuffer(chunk.buffers()[1], width)[chunk.offset:chunk.offset + len(chunk) + 1]
    if not len(chunk):
        return b"", b""
    characters = chunk.buffers()[2]
    return np.diff(offsets).astype(np.int64).tobytes(), b"" if characters is None else characters[int(offsets[0]):int(offsets[-1])]


def digest(arrow: pa.Table) -> str:
    """sha256 over a table's column names, types and values (text by its UTF-8 characters and the
    length of each value), from the buffers in memory."""
    h = hashlib.sha256()
    for name, column in zip(arrow.column_names, arrow.columns):
        h.update(f"{name}\x1f{column.type}\x1f".encode())
        values, characters = hashlib.sha256(), hashlib.sha256()
        for chunk in column.chunks:
            held, text = _held_bytes(chunk)
            values.update(held)
            characters.update(text)
        h.update(values.digest() + characters.digest())
    return h.hexdigest()
