"""Fuzzing scene files and command lines (hypothesis, bounded by max_examples).

Every input ends in a clean refusal naming what is wrong, or in a run with a documented
status (docs/promises.md): never a traceback, NaN presented as a result, or code that came
from the input.
"""
import ast
import math
import re

import pytest
from hypothesis import HealthCheck, event, given, settings, strategies as st

from derivation.codegen import generate_module
from derivation.model import build_model
from derivation.scene import SceneError, parse_scene
from tswm_runtime.cli import main
from tswm_runtime.results.result import STATUS_NAMES

from test_injection import PAPER, toml_string

SOURCE = "fuzz.toml"
FAST = settings(max_examples=250, deadline=None, suppress_health_check=list(HealthCheck))
SLOW = settings(max_examples=10, deadline=None, suppress_health_check=list(HealthCheck))
CLI = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
UNITS = ["m", "mm", "kg", "N", "kN", "deg", "rad", "m/s", "s", "ms", "N/m", "furlong", "", "%"]


def _lines() -> list[tuple[str, str, int]]:
    """(table, key, line index) of every ``key = value`` line of the paper scene."""
    table, out = "", []
    for index, line in enumerate(PAPER.splitlines()):
        header = re.match(r"\[([\w.]+)\]", line)
        if header:
            table = header.group(1)
        elif re.match(r"\w+ = ", line):
            out.append((table, line.split(" = ")[0], index))
    return out


LINES = _lines()


def toml_float(x: float) -> str:
    return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf") if math.isinf(x) else repr(x)


numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(toml_float),
                    st.integers(-2**70, 2**70).map(str),
                    st.sampled_from(["0", "-0.0", "1e-320", "1e-310", "1e308", "5e-324", "-1"]))
quantities = st.builds(lambda x, u: toml_string(f"{x:g} {u}".strip()),
                       st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(UNITS))
scalars = st.one_of(numbers, quantities, st.text(max_size=40).map(toml_string), st.booleans().map(str).map(str.lower))
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=3).map(lambda xs: "[" + ", ".join(xs) + "]"),
    st.builds(lambda v, f: f"{{ value = {v}, free = {f} }}", inner, st.sampled_from(["true", "false", "1"]))),
    max_leaves=6)


def mutate(line_no: int, value: str | None) -> str:
    lines = PAPER.splitlines()
    lines[line_no] = "" if value is None else lines[line_no].split(" = ")[0] + " = " + value
    return "\n".join(lines) + "\n"


def assert_clean_refusal(error: SceneError, named: tuple[str, ...] = ()) -> None:
    message = str(error)
    assert message.startswith(f"{SOURCE}: ") and len(message) < 1500, message
    if named:
        assert any(n in message for n in named), (named, message)


@FAST
@given(st.sampled_from(LINES), st.one_of(st.none(), values))
def test_mutated_scene_is_accepted_or_refused_naming_the_key(line, value):
    table, key, index = line
    try:
        scene = parse_scene(mutate(index, value), SOURCE)
    except SceneError as error:
        syntax = "not a valid UTF-8 TOML" in str(error) or "nested too deeply" in str(error)
        assert_clean_refusal(error, () if syntax else tuple(n for n in (key, table) if n))
        return
    for p in scene.params():
        assert math.isfinite(p.value), p
    assert all(math.isfinite(v) for v in (scene.run.t_end, scene.run.rtol, scene.run.atol, scene.run.x1))


@FAST
@given(st.one_of(st.text(max_size=300), st.binary(max_size=300).map(lambda b: b.decode("latin-1")),
                 st.builds(lambda a, b: PAPER[:a] + b + PAPER[a:], st.integers(0, len(PAPER)), st.text(max_size=20))))
def test_arbitrary_text_is_accepted_or_refused_cleanly(text):
    try:
        parse_scene(text, SOURCE)
    except SceneError as error:
        assert_clean_refusal(error)


@SLOW
@given(st.text(max_size=200), st.sampled_from([(t, k, i) for t, k, i in LINES if t in ("drive", "friction", "wedge",
                                                                                      "reference")]),
       st.one_of(st.none(), st.sampled_from(["1e-310", "1e-200", "1e-12", "0.5", "3", "1e6", "1e200", "1e300"])))
def test_generated_code_holds_scene_text_only_as_data(description, line, value):
    table, key, index = line
    text = PAPER if value is None else mutate(index, value)
    text = re.sub(r"^description = .*$", lambda _: f"description = {toml_string(description)}", text, flags=re.M)
    try:
        scene = parse_scene(text, SOURCE)
        source = generate_module(build_model(scene))
    except SceneError as error:   # GenerationError is one: a folded number that is not finite, key named
        assert_clean_refusal(error, (key, table, "description"))
        event("refused")
        return
    event("generated")
    tree = ast.parse(source)
    assigned = {t.id: node.value for node in tree.body if isinstance(node, ast.Assign)
                for t in node.targets if isinstance(t, ast.Name)}
    assert ast.literal_eval(assigned["DESCRIPTION"]) == scene.description
    names = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name)}
    assert not names & {"inf", "nan", "os", "sys", "__import__", "exec", "eval", "open"}


OPTION_VALUES = {
    "--t-end": ["0.01", "0", "-1", "nan", "inf", "1e300", "x", "1e-300"],
    "--rtol": ["1e-6", "0", "1", "1e-300", "nan", "-1e-6"],
    "--atol": ["1e-9", "0", "1e-300", "1e300", "inf", "2"],
    "--points": ["11", "0", "-5", "1e8", "100000000", str(2**70), "x"],
    "--max-steps": ["5", "0", "-1", str(2**70), "1.5", "2000"],
    "--max-events": ["1", "0", "1000000000", str(2**64), "3"],
    "--method": ["dopri5", "rosenbrock23", "rk4", ""],
    "--set": ["F2=-1000", "F2=nan", "F2=1e400", "F2=-5 kN", "F2=-5 kg", "Fx=1", "F2", "m2=0", "m2=-1",
              "m2=1e-300", "m2=1e300", "F2=="],
}
SWEEP_VALUES = {
    "--grid": ["F2=-15000:-1000:3", "F2=1:2:0", "F2=1:2:100000000", f"F2=1:2:{2**70}", "F2=a:b:c", "x=1:2:2",
               "F2=nan:1:2", "m2=100:300:2", "F2=1:2:-3"],
    "--chunk-size": ["1", "2", "0", "-1", str(2**70)],
    "--samples": ["3", "0", "-2", str(10**9)],
    "--range": ["F2=-5000:-1000", "F2=5:1", "F2=inf:1", "m2"],
    "--seed": ["0", "-1", str(2**80)],
}


def command_lines(command: str, table: dict) -> st.SearchStrategy:
    option = st.sampled_from(sorted(table)).flatmap(lambda o: st.sampled_from(table[o]).map(lambda v: [o, v]))
    return st.lists(option, max_size=4).map(lambda pairs: [command, "paper", *[x for p in pairs for x in p]])


def run_cli(argv, capsys, record: bool = True) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as stop:      # argparse's own refusals (an option's type or choices): exit 2
        code = stop.code
    captured = capsys.readouterr()
    if record:
        event(f"exit {code}")
    return code, captured.out, captured.err


def assert_documented_outcome(command, code, out, err) -> None:
    assert code in (0, 1, 2), code
    assert "Traceback" not in out + err
    if code == 2:
        assert err.startswith(f"tswm {command}: error: ") or "tswm " in err and "error:" in err, err
        assert len(err) < 3000
        return
    if command == "simulate":
        status = re.search(r"status: ([\w-]+):", out).group(1)
        assert status in STATUS_NAMES.values()
        assert (code == 0) == (status == "finished")
        if status == "finished":
            for line in out.splitlines():
                if line.strip().startswith(("S1 max", "S2 max", "KD1")):
                    assert "nan" not in line.lower() and "inf" not in line.lower(), line
    else:
        statuses = re.search(r"status: (.*)", out).group(1)
        assert all(part.rsplit(" ", 1)[0] in STATUS_NAMES.values() for part in statuses.split(", ")), statuses


@CLI
@given(command_lines("simulate", OPTION_VALUES))
def test_simulate_command_lines(capsys, argv):
    argv = argv + ([] if "--t-end" in argv else ["--t-end", "0.05"])
    code, out, err = run_cli(argv, capsys)
    assert_documented_outcome("simulate", code, out, err)


@CLI
@given(command_lines("sweep", {**SWEEP_VALUES, **{k: OPTION_VALUES[k] for k in ("--t-end", "--atol", "--max-steps")}}))
def test_sweep_command_lines(capsys, argv):
    argv = argv + ["--no-progress"] + ([] if "--t-end" in argv else ["--t-end", "0.05"])
    if "--grid" not in argv and "--samples" not in argv:
        argv += ["--grid", "F2=-15000:-1000:3"]
    code, out, err = run_cli(argv, capsys)
    assert_documented_outcome("sweep", code, out, err)


@pytest.mark.parametrize("argv", [["simulate"], ["sweep"], ["nonsense"], ["derive", "paper", "--pdf", "--latex"],
                                  ["simulate", "paper", "--points"], []])
def test_malformed_command_lines_exit_2(argv, capsys):
    code, out, err = run_cli(argv, capsys, record=False)
    assert code == 2 and "error:" in err and "Traceback" not in err
