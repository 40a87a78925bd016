"""One --grid syntax for `tswm sweep` of a scene and of a chain (tswm_runtime/sweeps/grid.py): ranges, lists
and single values, units where the quantity has them, one limit, errors naming the item."""
from __future__ import annotations

import pytest

from tswm_runtime.cli import main
from tswm_runtime.model.contract import load_module
from tswm_runtime.sweeps import chain, sweep


@pytest.fixture(scope="module")
def paper():
    return load_module("paper")


@pytest.fixture(scope="module")
def mov():
    return load_module("mov")


def test_a_scene_grid_takes_lists_with_units(paper):
    grid = sweep.parse_grid(["F2=-15 kN,-5000,0 kN", "m2=0.2 t:300:3"], paper)
    assert grid["F2"].tolist() == [-15000.0, -5000.0, 0.0] and grid["m2"].tolist() == [200.0, 250.0, 300.0]


def test_a_chain_grid_takes_ranges_lists_and_single_values_of_any_value_with_units(mov):
    grid = chain.parse_grid(["voltage=0.8:1.0:3", "mu_1=0.05", "mu_2=0.1, 0.15", "force_2=-5 kN,-254"], mov)
    assert grid == {"voltage": [0.8, 0.9, 1.0], "mu_1": [0.05], "mu_2": [0.1, 0.15], "force_2": [-5000.0, -254.0]}


@pytest.mark.parametrize("scene_item, chain_item, message", [
    ("F2=1:2:0", "voltage=1:2:0", "count 0 must be in [1, 1e+07]"),
    ("F2=1:2:20000000", "voltage=1:2:20000000", "count 20000000 must be in [1, 1e+07]"),
    ("F2=1:2:2.5", "voltage=1:2:2.5", "count '2.5' is not an integer"),
    ("F2=1:2", "voltage=1:2", "expected NAME=START:STOP:COUNT, NAME=V1,V2,... or NAME=VALUE"),
    ("F2=1,,2", "voltage=1,,2", "an empty value"),
    ("F2=1,inf", "voltage=1,inf", "'inf' is not finite"),
])
def test_both_commands_refuse_a_bad_item_alike(paper, mov, scene_item, chain_item, message):
    with pytest.raises(sweep.SweepInputError) as scene_error:
        sweep.parse_grid([scene_item], paper)
    with pytest.raises(chain.ChainSweepError) as chain_error:
        chain.parse_grid([chain_item], mov)
    for error, item in ((scene_error, scene_item), (chain_error, chain_item)):
        assert str(error.value).startswith(f"--grid {item!r}: ") and message in str(error.value), str(error.value)


def test_one_limit_on_the_whole_grid(paper, mov):
    """Each axis within its count, but 4000 x 4000 = 1.6e7 cases: refused by both, before anything is built."""
    for error, parse in ((sweep.SweepInputError, lambda: sweep.parse_grid(["F2=1:2:4000", "m2=1:2:4000"], paper)),
                         (chain.ChainSweepError, lambda: chain.parse_grid(["mu_1=0.1:0.2:4000", "mu_2=0.1:0.2:4000"], mov))):
        with pytest.raises(error, match=r"--grid: 16000000 cases \(4000 x 4000\), more than the 1e\+07 one sweep runs"):
            parse()


def test_names_and_units_are_checked_per_command(paper, mov):
    with pytest.raises(sweep.SweepInputError, match=r"--grid 'F2=1 kg': parameter F2 = '1 kg': 'kg' is a mass unit"):
        sweep.parse_grid(["F2=1 kg"], paper)
    with pytest.raises(chain.ChainSweepError, match=r"--grid 'force_2=1 kg': parameter force_2 = '1 kg': 'kg' is a "
                       "mass unit"):
        chain.parse_grid(["force_2=1 kg"], mov)
    with pytest.raises(chain.ChainSweepError, match=r"--grid 'mu_3': chain scene 'mov' has no such value \(values: "
                       r"lead_angle_1, .*, mu_2, .*, switch_delay, voltage\)"):
        chain.parse_grid(["mu_3=0.1"], mov)


@pytest.mark.parametrize("scene", ["paper", "mov"])
def test_tswm_sweep_names_the_bad_item_with_exit_2(scene, capsys):
    name = "F2" if scene == "paper" else "voltage"
    assert main(["sweep", scene, "--no-progress", "--grid", f"{name}=1:2:0"]) == 2
    assert f"--grid '{name}=1:2:0': count 0 must be in [1, 1e+07]" in capsys.readouterr().err
