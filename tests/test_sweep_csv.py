"""The sweep's CSV writer (``sweeps.csvtext``) against pandas' ``to_csv``, which it replaces:
the same bytes for every kind of cell a sweep table holds."""
import numpy as np
import pandas as pd

from tswm_runtime.model.contract import load_module
from tswm_runtime.sweeps.csvtext import csv_text
from tswm_runtime.sweeps.sweep import grid_cases, sweep, written_names


def test_odd_cells_are_written_as_pandas_writes_them():
    """Zeros of both signs, infinities, NaN, the ends of float64, repeated values; text with
    commas, quotes, line breaks, non-ASCII and nothing; integers and booleans."""
    rng = np.random.default_rng(3)
    floats = [0.0, -0.0, np.nan, np.inf, -np.inf, 1e16, 1e-5, 1.5e-05, 123456789012345678.0, 0.1, 1e300, 5e-324,
              2.0**60, 0.0, -0.0, 0.1]
    table = pd.DataFrame({
        "x [m]": floats, "y": rng.normal(size=16) * 10.0 ** rng.integers(-20, 20, 16),
        "s": ["a,b", 'q"x', "", "line\nbreak", "é…", "TS", " ", "x", None, "0 1 …", "a;b", "\t", "cr\r", "", "T", "S"],
        "n": np.arange(16) - 5, "b": [True, False] * 8, 'quote "name"': np.float32(np.linspace(-1, 1, 16))})
    assert csv_text(table) == table.to_csv(index=False)


def test_a_sweep_table_is_written_as_pandas_writes_it():
    module = load_module("paper-runup")
    P = grid_cases(module, {"m2": np.linspace(100.0, 400.0, 7), "F2_after": np.linspace(-20000.0, 5000.0, 9)})
    table = sweep(module, P).table.rename(columns=written_names(module))
    assert csv_text(table) == table.to_csv(index=False)
