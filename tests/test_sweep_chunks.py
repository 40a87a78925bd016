"""Sweep chunks prove what they hold: truncated, swapped, foreign and stale chunks are
recomputed (or reported), an interrupted sweep resumes, and the final table always equals
an uninterrupted run's."""
import shutil
import types

import numpy as np
import pandas as pd
import pytest

from tswm_runtime.sweeps import chunks
from tswm_runtime.sweeps import rows as sweep_rows
from tswm_runtime.cli import main
from tswm_runtime.model.contract import load_module
from tswm_runtime.sweeps.sweep import grid_cases, parse_grid, read_table, sweep

SETTINGS = {"v1": 2.0}


@pytest.fixture(scope="module")
def paper():
    return load_module("paper")


@pytest.fixture(scope="module")
def cases(paper):
    return grid_cases(paper, parse_grid(["F2=-15000:-1000:6"], paper))


@pytest.fixture(scope="module")
def reference(paper, cases):
    """The uninterrupted, in-memory sweep."""
    return sweep(paper, cases, SETTINGS, chunk_size=2).table


def chunk_files(directory):
    return sorted((directory / "chunks").glob("chunk-*.parquet"))


def test_chunks_carry_their_key(paper, cases, tmp_path):
    sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    import pyarrow.parquet as pq

    for index, path in enumerate(chunk_files(tmp_path)):
        key = __import__("json").loads(pq.read_schema(path).metadata[chunks.METADATA_KEY])
        assert key["index"] == index and key["rows"] == 2 and key["scene"] == "paper"
        assert key["model_digest"] == chunks.model_digest(paper) and len(key["model_digest"]) == 64
        assert key["settings"]["v1"] == 2.0 and key["runtime_version"]


def test_truncated_chunk_is_recomputed(paper, cases, reference, tmp_path):
    sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    victim = chunk_files(tmp_path)[1]
    victim.write_bytes(victim.read_bytes()[:100])
    again = sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    assert again.computed == [1] and again.skipped == [0, 2]
    assert again.rejected[0][0] == 1 and "unreadable" in again.rejected[0][1]
    assert any(victim.name in w and "recomputing" in w for w in again.warnings)
    pd.testing.assert_frame_equal(again.table, reference)
    pd.testing.assert_frame_equal(read_table(tmp_path / "paper-sweep.parquet"), reference)
    third = sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)   # the rewritten chunk is good
    assert third.computed == [] and third.rejected == []


def test_chunk_copied_over_another_is_recomputed(paper, cases, reference, tmp_path):
    sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    first, second, _ = chunk_files(tmp_path)
    shutil.copyfile(first, second)
    again = sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    assert again.computed == [1] and "index" in again.rejected[0][1]
    pd.testing.assert_frame_equal(again.table, reference)
    assert again.table["F2"].is_unique


def test_chunk_with_right_key_but_wrong_rows_is_recomputed(paper, cases, reference, tmp_path):
    """A forged chunk: the right key, other parameter rows."""
    out = sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    path = chunk_files(tmp_path)[2]
    import json

    import pyarrow.parquet as pq

    key = json.loads(pq.read_schema(path).metadata[chunks.METADATA_KEY])
    chunks.write_chunk(path, out.rows.slice(0, 2), key)
    again = sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    assert again.computed == [2] and "parameter rows differ" in again.rejected[0][1]
    pd.testing.assert_frame_equal(again.table, reference)


def test_chunk_without_key_is_recomputed(paper, cases, reference, tmp_path):
    sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    path = chunk_files(tmp_path)[0]
    pd.read_parquet(path).to_parquet(path, index=False)        # a plain parquet file, as an older tswm wrote
    again = sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    assert again.computed == [0] and "no tswm chunk key" in again.rejected[0][1]
    pd.testing.assert_frame_equal(again.table, reference)


def test_changed_model_reuses_nothing_and_stale_chunks_are_reported_and_pruned(paper, cases, reference, tmp_path):
    sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    old = {p.name for p in chunk_files(tmp_path)}
    source = (tmp_path / "paper_v2.py")
    lines = open(paper.__file__).read().splitlines(keepends=True)
    lines = [("# body-sha256: " + "0" * 64 + "\n") if line.startswith("# body-sha256:") else line for line in lines]
    source.write_text("".join(lines))
    changed = types.ModuleType("paper_v2")      # same compiled functions, a module file with another body digest
    changed.__dict__.update({k: v for k, v in vars(paper).items() if not k.startswith("__")})
    changed.__file__ = str(source)
    again = sweep(changed, cases, SETTINGS, output=tmp_path, chunk_size=2)
    assert again.computed == [0, 1, 2] and again.skipped == []
    assert {p.name for p in again.stale} == old and not again.pruned
    assert any("--prune" in w for w in again.warnings)
    pruned = sweep(changed, cases, SETTINGS, output=tmp_path, chunk_size=2, prune=True)
    assert pruned.computed == [] and pruned.pruned and {p.name for p in pruned.stale} == old
    assert not old & {p.name for p in chunk_files(tmp_path)} and len(chunk_files(tmp_path)) == 3
    pd.testing.assert_frame_equal(pruned.table, reference)


def test_changed_runtime_reuses_nothing(paper, cases, tmp_path, monkeypatch):
    sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    monkeypatch.setattr(chunks, "runtime_digest", lambda: "another runtime")
    again = sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    assert again.computed == [0, 1, 2] and len(again.stale) == 3


def test_ctrl_c_keeps_complete_chunks_and_the_rerun_resumes(paper, cases, reference, tmp_path, monkeypatch,
                                                              capsys):
    real = sweep_rows.case_table
    calls = []

    def interrupted_on_second(module, P, run):
        calls.append(P.shape[0])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(module, P, run)

    monkeypatch.setattr(sweep_rows, "case_table", interrupted_on_second)
    argv = ["sweep", "paper", "--grid", "F2=-15000:-1000:6", "--chunk-size", "2", "-o", str(tmp_path),
            "--no-progress"]
    assert main(argv + ["--t-end", "1"]) == 1
    err = capsys.readouterr().err
    assert "interrupted: 1 of 3 chunks are complete" in err and "rerun the same command" in err
    assert "Traceback" not in err
    assert len(chunk_files(tmp_path)) == 1 and not list((tmp_path / "chunks").glob("*.tmp"))
    assert not (tmp_path / "paper-sweep.parquet").exists()
    monkeypatch.setattr(sweep_rows, "case_table", real)
    assert main(argv + ["--t-end", "1"]) == 0
    assert "reused 1" in capsys.readouterr().out
    expected = sweep(paper, cases, {"t_end": 1.0}, chunk_size=2).table
    pd.testing.assert_frame_equal(read_table(tmp_path / "paper-sweep.parquet"), expected)


def test_cli_reports_rejected_chunks_on_stderr(tmp_path, capsys):
    argv = ["sweep", "paper", "--grid", "F2=-15000:-1000:4", "--chunk-size", "2", "-o", str(tmp_path),
            "--no-progress"]
    assert main(argv) == 0
    victim = chunk_files(tmp_path)[0]
    victim.write_bytes(b"garbage")
    capsys.readouterr()
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "tswm sweep: warning: chunk 0" in captured.err and "recomputing" in captured.err
    assert "rejected on disk" in captured.out and "Traceback" not in captured.err
    assert np.isfinite(read_table(tmp_path / "paper-sweep.parquet")["F2"]).all()


def test_cli_prune_removes_stale_files(tmp_path, capsys):
    base = ["sweep", "paper", "--chunk-size", "2", "-o", str(tmp_path), "--no-progress"]
    assert main([*base, "--grid", "F2=-15000:-1000:4"]) == 0
    leftover = tmp_path / "chunks" / ".chunk-00000-x.parquet.abc.tmp"    # what a SIGKILL mid-write leaves
    leftover.write_bytes(b"half")
    capsys.readouterr()
    assert main([*base, "--grid", "F2=-15000:-1000:6"]) == 0     # another grid: the old chunks are stale
    err = capsys.readouterr().err
    assert "3 files in" in err and "--prune" in err
    assert main([*base, "--grid", "F2=-15000:-1000:6", "--prune"]) == 0
    assert "pruned 3 stale files" in capsys.readouterr().err
    assert len(chunk_files(tmp_path)) == 3 and not leftover.exists()


def _module_at(paper, path, source: str):
    """``paper``'s compiled functions in a module whose file is ``path``, holding ``source``."""
    path.write_text(source)
    module = types.ModuleType(path.stem)
    module.__dict__.update({k: v for k, v in vars(paper).items() if not k.startswith("__")})
    module.__file__ = str(path)
    return module


def _edited_body(paper) -> str:
    """paper's source with one line of its body changed and its header (body-sha256 included) kept."""
    source = open(paper.__file__).read()
    edited = source.replace("\nimport math\n", "\nimport math  # edited by hand\n", 1)
    assert edited != source and edited.splitlines()[:5] == source.splitlines()[:5]
    return edited


def test_hand_edited_body_with_its_old_header_reuses_nothing(paper, cases, reference, tmp_path):
    """The key hashes the module's file as it is, not the body digest its header states: a body
    edited by hand under an unchanged header (same '# body-sha256:' line) is recomputed."""
    path = tmp_path / "paper_copy.py"
    sweep(_module_at(paper, path, open(paper.__file__).read()), cases, SETTINGS, output=tmp_path, chunk_size=2)
    again = sweep(_module_at(paper, path, _edited_body(paper)), cases, SETTINGS, output=tmp_path, chunk_size=2)
    assert again.computed == [0, 1, 2] and again.skipped == [] and len(again.stale) == 3
    pd.testing.assert_frame_equal(again.table, reference)


def test_chunk_with_an_altered_result_column_is_recomputed_with_a_warning(paper, cases, reference, tmp_path):
    """A result value changed in place (key and parameter rows intact, schema metadata kept): the
    columns' checksum no longer matches, so the chunk is recomputed and the warning names the file."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    path = chunk_files(tmp_path)[1]
    arrow = pq.read_table(path)
    s1m = arrow.column("S1m").to_numpy().copy()
    s1m[0] *= 2.0
    altered = arrow.set_column(arrow.schema.get_field_index("S1m"), "S1m", pa.array(s1m))
    pq.write_table(altered.replace_schema_metadata(arrow.schema.metadata), path)
    assert pq.read_schema(path).metadata[chunks.METADATA_KEY] == arrow.schema.metadata[chunks.METADATA_KEY]
    again = sweep(paper, cases, SETTINGS, output=tmp_path, chunk_size=2)
    assert again.computed == [1] and again.skipped == [0, 2] and "checksum" in again.rejected[0][1]
    assert any(str(path) in w and "checksum" in w and "recomputing" in w for w in again.warnings)
    pd.testing.assert_frame_equal(again.table, reference)


def test_simulate_warns_when_a_body_no_longer_matches_its_header(paper, tmp_path, capsys, monkeypatch):
    from tswm_runtime.model import scenes

    path = tmp_path / "paper_copy.py"
    monkeypatch.setattr(scenes, "load_model", lambda spec: _module_at(paper, path, _edited_body(paper)))
    assert main(["simulate", "paper", "--t-end", "0.01"]) == 0
    err = capsys.readouterr().err
    assert f"warning: {path}: its body no longer matches its '# body-sha256:' header" in err, err
    monkeypatch.setattr(scenes, "load_model", lambda spec: _module_at(paper, path, open(paper.__file__).read()))
    assert main(["simulate", "paper", "--t-end", "0.01"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_column_checksum_is_the_values_not_their_chunking(paper, cases):
    """The checksum reads the columns' buffers: the same rows split into other chunks (or sliced)
    give the same digest, one changed number or one changed character another."""
    import pyarrow as pa

    from tswm_runtime.sweeps import columns

    rows = sweep(paper, cases, SETTINGS, chunk_size=2).rows
    whole = rows.combine_chunks()
    assert rows.column("status").num_chunks == 3 and whole.column("status").num_chunks == 1
    assert columns.digest(rows) == columns.digest(whole)
    assert columns.digest(rows.slice(1, 3)) == columns.digest(whole.slice(1, 3)) != columns.digest(whole.slice(0, 3))
    s1m = columns.numbers_of(rows.column("S1m")).copy()
    s1m[4] = np.nextafter(s1m[4], np.inf)
    changed = rows.set_column(rows.column_names.index("S1m"), "S1m", columns.numbers(s1m))
    assert columns.digest(changed) != columns.digest(rows)
    regimes = rows.column("regimes").to_pylist()
    regimes[5] = regimes[5] + "S"
    retyped = rows.set_column(rows.column_names.index("regimes"), "regimes", pa.array(regimes))
    assert columns.digest(retyped) != columns.digest(rows)
    moved = list(regimes)   # the same characters, one moved from a row to the next: other lengths
    moved[4], moved[5] = regimes[4] + regimes[5][:1], regimes[5][1:]
    shifted = rows.set_column(rows.column_names.index("regimes"), "regimes", pa.array(moved))
    assert columns.digest(shifted) != columns.digest(retyped)
