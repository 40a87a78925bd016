"""Files of a simulation: CSV of the output points, npz of everything, JSON summary, PNG.

Every file is built in memory first (text, ``io.BytesIO``) and then written with
``write_atomic``, so a reader never sees a half-written file. The npz holds only plain
and structured numpy arrays: ``numpy.load(path, allow_pickle=False)`` reads it.
"""
from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from types import ModuleType

import numpy as np

from tswm_common.files import write_atomic
from tswm_runtime.results.result import SERIES, Result
SCALARS = ("S1_max", "t_S1_max", "S2_max", "t_S2_max", "t_stop", "n_steps", "n_rejected", "nfev", "njev")


def csv_header(series=SERIES) -> list[str]:
    """Column names with their units, e.g. ``t [s]``; mode and regime are names."""
    return [f"{name} [{unit}]" for name, unit in series] + ["mode", "regime"]


def csv_text(result: Result, mode_regime) -> str:
    """The output points as CSV: one header row (units in the names), floats round-trip exact.

    ``mode_regime`` gives the regime of each mode index (the module's ``MODE_REGIME``).
    ``pandas.read_csv`` and ``numpy.genfromtxt(..., delimiter=',', names=True)`` read it.
    """
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(csv_header(result.series))
    columns = [getattr(result, name) for name, _ in result.series]
    for row, mode in enumerate(result.mode):
        writer.writerow([repr(float(column[row])) for column in columns]
                        + [result.mode_names[mode], mode_regime[mode]])
    return buffer.getvalue()


def _text_array(values, minimum: int = 1) -> np.ndarray:
    """Strings as a fixed-width unicode array (never an object array)."""
    values = list(values)
    width = max([minimum, *(len(v) for v in values)])
    return np.array(values, dtype=f"U{width}")


def events_array(result: Result) -> np.ndarray:
    """The event log as a structured array: t, guard, kind, from_mode, to_mode ('' when the
    run stopped there), x1, v1."""
    events = result.events
    width = max([1, *(len(s) for e in events for s in (e.guard, e.kind, e.from_mode, e.to_mode or ""))])
    dtype = [("t", "f8"), ("guard", f"U{width}"), ("kind", f"U{width}"), ("from_mode", f"U{width}"),
             ("to_mode", f"U{width}"), ("x1", "f8"), ("v1", "f8")]
    return np.array([(e.t, e.guard, e.kind, e.from_mode, e.to_mode or "", e.x1, e.v1) for e in events],
                    dtype=dtype)


def phases_array(result: Result) -> np.ndarray:
    """The phases as a structured array: mode, regime, t_start, t_end."""
    width = max([1, *(len(s) for ph in result.phases for s in (ph.mode, ph.regime))])
    dtype = [("mode", f"U{width}"), ("regime", f"U{width}"), ("t_start", "f8"), ("t_end", "f8")]
    return np.array([(ph.mode, ph.regime, ph.t_start, ph.t_end) for ph in result.phases], dtype=dtype)


def npz_bytes(result: Result, module: ModuleType) -> bytes:
    """Everything in one compressed npz: the series, mode (index) with mode_names and
    mode_regime, events and phases (structured), params, scalars (0-d arrays), status,
    message, settings (as JSON text). KD1, KD2 only when the scene has them."""
    arrays: dict[str, np.ndarray] = {name: np.asarray(getattr(result, name), dtype=np.float64)
                                     for name, _ in result.series}
    arrays["mode"] = np.asarray(result.mode, dtype=np.int64)
    arrays["mode_names"] = _text_array(result.mode_names)
    arrays["mode_regime"] = _text_array(module.MODE_REGIME)
    arrays["events"] = events_array(result)
    arrays["phases"] = phases_array(result)
    arrays["param_names"] = _text_array(result.params)
    arrays["param_values"] = np.array(list(result.params.values()), dtype=np.float64)
    arrays["param_units"] = _text_array(module.PARAM_UNITS)
    for name in SCALARS:
        arrays[name] = np.array(getattr(result, name))
    for name in ("KD1", "KD2"):
        if getattr(result, name) is not None:
            arrays[name] = np.array(float(getattr(result, name)))
    for name in ("scene", "status", "message"):
        arrays[name] = np.array(getattr(result, name))
    arrays["settings_json"] = np.array(json.dumps(jsonable(result.settings), allow_nan=False))
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


def jsonable(value):
    """``value`` with numpy scalars as Python numbers and inf/nan as the strings 'inf',
    '-inf', 'nan' (strict JSON has no such numbers)."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return value


def summary(result: Result, wall_time: float | None = None) -> dict:
    """``Result.to_dict`` made strict-JSON ready (inf as 'inf'), with the wall time if given."""
    data = result.to_dict()
    if wall_time is not None:
        data["wall_time_s"] = wall_time
    return jsonable(data)


def summary_json(result: Result, wall_time: float | None = None) -> str:
    """``summary`` as strict JSON text (no NaN/Infinity literals)."""
    return json.dumps(summary(result, wall_time), indent=2, allow_nan=False) + "\n"


def output_paths(out_dir: str | Path, scene: str) -> dict[str, Path]:
    """Where ``write_outputs`` puts each file: DIR/<scene>.csv, .npz, -summary.json, .png."""
    out_dir = Path(out_dir)
    return {"csv": out_dir / f"{scene}.csv", "npz": out_dir / f"{scene}.npz",
            "json": out_dir / f"{scene}-summary.json", "png": out_dir / f"{scene}.png"}


def write_outputs(result: Result, module: ModuleType, out_dir: str | Path, *, plot: bool = True,
                  wall_time: float | None = None) -> list[Path]:
    """Write the CSV, npz, summary JSON and (with ``plot``) PNG of a run; return the paths."""
    paths = output_paths(out_dir, result.scene)
    written = [write_atomic(paths["csv"], csv_text(result, module.MODE_REGIME)),
               write_atomic(paths["npz"], npz_bytes(result, module)),
               write_atomic(paths["json"], summary_json(result, wall_time))]
    if plot:
        from tswm_runtime.results.plot import png_bytes

        written.append(write_atomic(paths["png"], png_bytes(result, module)))
    return written
