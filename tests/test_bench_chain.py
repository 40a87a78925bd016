"""The bench's two-stage drive train: the scipy peer (Newton per body, Coulomb per stage, written by
hand in tswm_runtime/bench/chain.py) and tswm agree on the swinging run, which changes mode at every
event; the equal-error measurement runs (slow)."""
from __future__ import annotations

import pytest

from derivation.chain.codegen import generate_chain_module
from derivation.chain.scene import parse_chain
from tswm_runtime.bench import chain as bench_chain
from tswm_runtime.model.contract import load_module

# heavy: a chain module derived and compiled for this file alone, and bench runs; CI runs it after the default set
pytestmark = pytest.mark.heavy


@pytest.fixture(scope="module")
def module(tmp_path_factory):
    path = tmp_path_factory.mktemp("bench_chain") / "bench_worm_nut_spring.py"
    path.write_text(generate_chain_module(parse_chain(bench_chain.SCENE, "bench")))
    return load_module(path)


def test_tswm_and_the_peer_swing_alike(module):
    """Seven events (turns and both stages changing flank at once where the seat balances the load), the
    same end state to 1e-8 at tight tolerances; the peer converges to its reference as rtol falls."""
    reference = bench_chain.peer_run("DOP853", bench_chain.REFERENCE_RTOL, bench_chain.REFERENCE_ATOL)
    assert reference.events == 7
    tswm = bench_chain.tswm_run(module, 1e-11, 1e-14)
    assert tswm.events == reference.events
    assert bench_chain.error(tswm, reference) < 1e-8
    errors = [bench_chain.error(bench_chain.peer_run("DOP853", r, r * 1e-3), reference) for r in (1e-6, 1e-9)]
    assert errors[1] < errors[0] < 1e-4


@pytest.mark.slow
def test_the_chain_bench_measures_a_factor(module):
    result = bench_chain.measure(module, rounds=1, log=lambda line: None)
    assert [v["level"] for v in result["verdicts"]] == list(bench_chain.LEVELS)
    assert all(v["tswm_s"] > 0 for v in result["verdicts"])


def test_a_phase_starts_with_the_step_carried_over_its_event(module):
    """Each of the swing's eight phases starts with the step the phase before proposed, not with a fresh
    initial step and its climb (79 accepted and 4 rejected steps at rtol 1e-6 then, 65 and 6 now), at the
    same error against the reference."""
    from tswm_runtime.simulation.chain import simulate_chain

    result = simulate_chain(module, rtol=1e-6, atol=1e-9, points=2)
    assert result.status == "finished" and len(result.run.phases) == 8
    assert result.n_steps <= 75
    reference = bench_chain.peer_run("DOP853", bench_chain.REFERENCE_RTOL, bench_chain.REFERENCE_ATOL)
    assert bench_chain.error(bench_chain.tswm_run(module, 1e-6, 1e-9), reference) < 2e-6
