"""Sweep chunk files that prove what they hold.

A chunk is a parquet file ``chunks/chunk-NNNNN-HASH.parquet``. Its key, stored inside it
(schema metadata ``tswm.chunk``) and hashed into its name, holds everything its rows depend
on: the scene, a sha256 of the model module's file as it is on disk (never the digest its
header states: a hand edit of the body changes the key), the runtime's version and a digest
of its numerical sources, the run settings, and a digest of the chunk's parameter rows.
Beside the key the file stores a sha256 of every column's values (``tswm.columns``). A
chunk is reused only when its stored key equals the expected one, its columns match their
checksum and its parameter columns equal the rows asked for; anything else (truncated,
foreign, copied over another's name, altered, from another model or runtime) is recomputed
with a warning. The checksums catch accidents (edits, corruption, stale code), not someone
who rewrites a chunk and recomputes them. Files in ``chunks/`` that no chunk of this sweep
expects are stale: reported, and removed on request (``prune``).
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from types import ModuleType

import numpy as np

from tswm_runtime.common.provenance import TSWM_VERSION as __version__
from tswm_runtime.jit.cache_guard import kernel_digest
from tswm_runtime.sweeps import columns
from tswm_common.files import write_atomic

KEY_FORMAT = 1
METADATA_KEY = b"tswm.chunk"
CHECKSUM_KEY = b"tswm.columns"
PATTERN = "chunk-*.parquet"
RUNTIME_SOURCES = ("model/modes.py", "model/checks.py", "simulation/simulate.py", "sweeps/rows.py", "sweeps/sweep.py",
                   "sweeps/chunks.py", "sweeps/columns.py")   # besides cache_guard's kernels


def model_digest(module: ModuleType) -> str:
    """sha256 of the module's file as it is on disk (``file_digest``: header and body, the code that runs)."""
    path = getattr(module, "__file__", None)
    return file_digest(Path(path)) if path else "no-file:" + getattr(module, "SCENE_DIGEST", module.__name__)


def file_digest(path: Path) -> str:
    """sha256 of a model module's file as it is on disk (never the digest its header states)."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def runtime_digest(extra: tuple[str, ...] = ()) -> str:
    """sha256 over the runtime's numerical sources and ``extra`` ones (paths under tswm_runtime/, e.g. the
    chain sweep's): a changed integrator or answer never reuses old rows."""
    h = hashlib.sha256(kernel_digest().encode())
    here = Path(__file__).parents[1]   # tswm_runtime/
    for name in (*RUNTIME_SOURCES, *extra):
        h.update(name.encode() + (here / name).read_bytes())
    return h.hexdigest()


def rows_digest(P: np.ndarray) -> str:
    P = np.ascontiguousarray(P, dtype=np.float64)
    return hashlib.sha256(repr(P.shape).encode() + P.tobytes()).hexdigest()


def chunk_key(module: ModuleType, run: dict, P: np.ndarray, index: int, runtime: str | None = None,
              params: tuple[str, ...] | None = None) -> dict:
    """Everything a chunk's rows depend on, as a JSON-able dict; ``params`` names P's columns (the
    module's PARAM_NAMES unless given)."""
    return {"format": KEY_FORMAT, "index": index, "scene": module.SCENE,
            "scene_digest": getattr(module, "SCENE_DIGEST", None), "model_digest": model_digest(module),
            "runtime_version": __version__, "runtime_digest": runtime or runtime_digest(),
            "settings": json.loads(json.dumps(run, sort_keys=True, default=str)),
            "params": list(module.PARAM_NAMES if params is None else params), "rows": int(P.shape[0]), "rows_digest": rows_digest(P)}


def chunk_name(key: dict) -> str:
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    return f"chunk-{key['index']:05d}-{digest}.parquet"


def write_chunk(path: Path, table, key: dict) -> Path:
    """The rows (a pyarrow Table) as parquet with its key and its columns' checksum in the schema
    metadata, written atomically."""
    arrow = table.replace_schema_metadata({METADATA_KEY: json.dumps(key, sort_keys=True).encode(),
                                           CHECKSUM_KEY: columns.digest(table).encode()})
    return write_atomic(path, columns.parquet(arrow))


def read_chunk(path: Path, key: dict, P: np.ndarray, names: list[str]):
    """(pyarrow Table, None) when the file holds exactly the chunk ``key`` describes, else (None, why not)."""
    import pyarrow.parquet as pq

    try:
        arrow = pq.ParquetFile(path).read()
        metadata = arrow.schema.metadata or {}
        stored = json.loads(metadata.get(METADATA_KEY, b"null"))
        checksum = metadata.get(CHECKSUM_KEY, b"").decode("ascii", "replace")
    except Exception as error:  # truncated or not parquet at all: any reader error means recompute
        return None, f"unreadable ({type(error).__name__}: {str(error)[:120]})"
    if stored is None:
        return None, "it carries no tswm chunk key (foreign or written by an older tswm)"
    if stored != key:
        diff = sorted(k for k in set(key) | set(stored) if key.get(k) != stored.get(k))
        return None, f"its key differs in {', '.join(diff)}"
    table = arrow.replace_schema_metadata(None)
    if table.column_names != names:
        return None, "its columns differ from this sweep's"
    try:
        held = columns.digest(table)
    except TypeError as error:
        return None, f"its columns differ from this sweep's ({error})"
    if checksum != held:
        return None, ("its columns do not match their checksum (altered or corrupted since it was written)"
                      if checksum else "it carries no checksum of its columns (written by an older tswm)")
    params = key["params"]
    rows = (np.column_stack([columns.numbers_of(table.column(name)) for name in params]) if params
            else np.empty((table.num_rows, 0)))
    if rows.shape != P.shape or not np.array_equal(rows, P):
        return None, "its parameter rows differ from the rows asked for"
    return table, None


def stale_files(directory: Path, expected: set[str]) -> list[Path]:
    """Chunk files (and leftover temporary files) in ``directory`` that this sweep does not expect."""
    if not directory.is_dir():
        return []
    files = [p for p in directory.iterdir() if p.is_file() and p.name not in expected
             and (p.match(PATTERN) or p.name.endswith(".tmp"))]
    return sorted(files)
