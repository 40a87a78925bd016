"""Values echoed in messages cannot drive the terminal: control characters (C0, DEL, C1), bidi
overrides and line separators arrive escaped, each value on the message's one line."""
import re
import unicodedata

import pytest

from derivation.scene import SceneError, parse_scene
from tswm_common.text import printable
from tswm_runtime.cli import main
from tswm_runtime.simulation.simulate import SimulationInputError, simulate

from test_injection import PAPER, toml_string

ESC = "\x1b[31m"


def unsafe(text: str) -> list[str]:
    """The characters of ``text`` a terminal acts on (control, format, separators), by Unicode's
    own categories: an expectation independent of printable()."""
    return [c for c in text if unicodedata.category(c) in ("Cc", "Cf", "Zl", "Zp") and c != "\n"]


@pytest.mark.parametrize("raw, shown", [
    (ESC + "red", r"\x1b[31mred"),
    ("bell\x07", r"bell\x07"),
    ("two\r\nlines", r"two\r\nlines"),
    ("del\x7f c1\x85 csi\x9b", r"del\x7f c1\x85 csi\x9b"),
    ("abc\u202edcba\u2066x\u2069", r"abc\u202edcba\u2066x\u2069"),
    ("line\u2028para\u2029", r"line\u2028para\u2029"),
    ("zero\u200bwidth", r"zero\u200bwidth"),
    ("é ü 中 \\ 'q'", "é ü 中 \\ 'q'"),
])
def test_printable_escapes_what_a_terminal_acts_on(raw, shown):
    assert printable(raw) == shown


def test_printable_keeps_a_long_value_short():
    assert printable("x" * 1000) == "x" * 200 + "... (1000 characters)"


def _scene(**keys) -> str:
    text = PAPER
    for key, value in keys.items():
        text, n = re.subn(rf"(?m)^{key} = .*$", lambda _: f"{key} = {value}", text)
        assert n == 1, key
    return text


@pytest.mark.parametrize("text, shown", [
    (_scene(name=toml_string(ESC + "red")), r'name = "\x1b[31mred"'),
    (_scene(m2=toml_string("200 \x1b[2J\x07kg")), r"unknown unit '\x1b[2J\x07kg'"),
    (_scene(m1=toml_string("1\u202ekg")), r"unknown unit '\u202ekg'"),
    (PAPER.replace("[wedge]", "[wedge]\n" + toml_string("m\x1b]0;owned\x07\n2") + " = 1", 1),
     r"wedge.m\x1b]0;owned\x07\n2: unknown key"),
])
def test_scene_values_and_keys_appear_escaped(text, shown, tmp_path, capsys):
    with pytest.raises(SceneError) as error:
        parse_scene(text, "s.toml")
    assert shown in str(error.value) and not unsafe(str(error.value)), str(error.value)
    path = tmp_path / "s.toml"
    path.write_text(text)
    assert main(["derive", str(path)]) == 2
    err = capsys.readouterr().err
    assert shown in err and not unsafe(err) and err.count("\n") == 1, err


def test_command_line_values_appear_escaped(capsys, tmp_path):
    assert main(["simulate", "paper", "--set", f"F2=5 {ESC}kN"]) == 2
    err = capsys.readouterr().err
    assert r"F2 = '5 \x1b[31mkN'" in err and not unsafe(err) and err.count("\n") == 1, err
    target = tmp_path / f"file{ESC}\n"
    target.write_text("")
    assert main(["simulate", "paper", "-o", str(target)]) == 2
    err = capsys.readouterr().err
    assert r"file\x1b[31m\n: exists and is not a directory" in err and not unsafe(err), err
    with pytest.raises(SimulationInputError) as error:
        simulate("paper", {"m2": f"1 {ESC}kg"})
    assert not unsafe(str(error.value))
