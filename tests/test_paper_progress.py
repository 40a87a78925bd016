"""`tswm paper` on first contact: it says what it does before any heavy work, and its progress
bar moves through every stage, compiling included."""
import io
import os
import subprocess
import sys
import warnings

import pytest

from tswm_runtime.cli import paper as cli_paper
from tswm_runtime.common.progress import INSIDE, Stages
from tswm_runtime.jit import coldstart
from tswm_runtime.paper import plan
from tswm_runtime.paper.background import Background, BackgroundError

# Stops the command where it first imports numba (the start of all heavy work: numba's cache
# check, the kernels, the models) and says so on stderr after whatever the command said before.
STOP_AT_NUMBA = """
import sys
class StopAtNumba:
    def find_spec(self, name, path=None, target=None):
        if name == "numba":
            sys.stderr.write("<numba imported>\\n")
            sys.stderr.flush()
            raise SystemExit(3)
sys.meta_path.insert(0, StopAtNumba())
from tswm_runtime.cli import main
sys.exit(main(["paper", "-o", sys.argv[1]]))
"""


def test_first_line_comes_before_numba_is_imported(tmp_path):
    run = subprocess.run([sys.executable, "-c", STOP_AT_NUMBA, str(tmp_path / "report")], capture_output=True,
                         text=True)
    assert run.returncode == 3, run.stderr
    lines = run.stderr.splitlines()
    assert "<numba imported>" in lines, run.stderr
    said = lines[:lines.index("<numba imported>")]
    assert said and said[0].startswith("tswm paper: the paper's cases in four readings"), run.stderr


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_stages_move_with_the_clock_inside_a_stage():
    clock, wall, out = Clock(), Clock(), io.StringIO()
    stages = Stages({"compile": 10.0, "wait": 4.0, "run": 2.0}, desc="job", file=out, clock=clock, wait_clock=wall)
    stages.begin("compile")
    clock.now += 4.0
    stages.tick()
    assert stages.position == pytest.approx(4.0)           # no call from the stage: the clock moved it
    clock.now += 100.0
    stages.tick()
    assert stages.position == pytest.approx(INSIDE * 10.0)  # never past the stage before it ends
    stages.begin("wait", waiting=True)
    assert stages.position == pytest.approx(10.0)
    clock.now += 3.0                                        # this process's CPU time: not a waiting stage's clock
    stages.tick()
    assert stages.position == pytest.approx(10.0)
    wall.now += 1.0
    stages.tick()
    assert stages.position == pytest.approx(11.0)
    stages.begin("run")
    clock.now += 1.0
    stages.tick()
    assert stages.position == pytest.approx(15.0)
    stages.close()
    assert stages.position == pytest.approx(16.0)
    text = out.getvalue()
    assert text.index("compile") < text.index("wait") < text.index("run") and "100%" in text


def test_stages_summing_past_the_rounded_total_end_at_100_percent_without_a_warning():
    """Estimates of 0.04 s each sum to 0.12 s; the bar's total is rounded to 0.1 s, and ending the stages must not
    move it past that (tqdm warns "clamping frac" and shows a negative remaining time)."""
    out = io.StringIO()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        stages = Stages({"a": 0.04, "b": 0.04, "c": 0.04}, desc="job", file=out, clock=Clock(), wait_clock=Clock())
        for name in "abc":
            stages.begin(name)
        stages.close()
    assert stages.position == pytest.approx(0.1) and "<-" not in out.getvalue()


def test_estimates_follow_what_is_cold():
    warm = plan.estimates({}, derivation=True)
    cold = plan.estimates({plan.KERNELS: 40.0, plan.MODELS: 16.0, plan.BATCH: 3.0}, derivation=True)
    assert list(warm) == list(cold) == [plan.KERNELS, plan.BATCH, plan.MODELS, plan.FIT, plan.RUNS, plan.FIGURES,
                                        plan.DOCUMENT, plan.WRITE]
    assert cold[plan.KERNELS] == 40.0 and cold[plan.BATCH] == 3.0
    assert cold[plan.MODELS] == plan.WARM[plan.MODELS]   # compiled meanwhile by the second process
    longer = plan.estimates({plan.KERNELS: 20.0, plan.MODELS: 30.0, plan.BATCH: 3.0}, derivation=True)
    assert longer[plan.MODELS] == 7.0   # what is left of the second process's part when this one is done
    assert warm[plan.KERNELS] == plan.WARM[plan.KERNELS]
    assert plan.estimates({}, derivation=False)[plan.DOCUMENT] == 0.0


def test_cold_parts_name_what_compiles(monkeypatch):
    monkeypatch.setattr(coldstart, "check", lambda groups=(), model=None: (list(groups), model) if groups or model
                        else None)
    seconds, text = cli_paper._cold_parts()
    assert text.startswith("compiling the integration kernels")
    assert all(f"`{scene}`" in text for scene in plan.SCENES.values())
    first, second = plan.first_process_scenes(), plan.BACKGROUND_SCENES
    assert sorted([*first, *second]) == sorted(plan.SCENES.values()) and first and second
    segment = coldstart.estimate(["segment"], None)   # in the group "integrate", compiled by the second process
    assert seconds[plan.KERNELS] == pytest.approx(coldstart.estimate(["integrate"], None) - segment
                                                  + sum(coldstart.estimate((), m) for m in first))
    assert seconds[plan.MODELS] == pytest.approx(segment + coldstart.estimate(["dopri5"], None)
                                                 + sum(coldstart.estimate((), m) for m in second))
    assert seconds[plan.BATCH] == coldstart.estimate(["batch"], None)
    monkeypatch.setattr(coldstart, "check", lambda groups=(), model=None: None)
    assert cli_paper._cold_parts() == ({}, None)


def test_second_process_failure_is_an_error_naming_it(tmp_path):
    background = Background(tmp_path, ["no-such-scene"], derivation=False)
    try:
        with pytest.raises(BackgroundError, match="no_such_scene"):
            background.models()
    finally:
        background.stop()


def test_cli_exits_1_naming_the_second_process_when_it_fails(tmp_path, monkeypatch, capsys):
    from tswm_runtime.cli import main

    monkeypatch.setattr(plan, "SCENES", {**plan.SCENES, "broken": "no-such-scene"})
    monkeypatch.setattr(plan, "BACKGROUND_SCENES", (*plan.BACKGROUND_SCENES, "no-such-scene"))
    assert main(["paper", "-o", str(tmp_path), "--no-derivation", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "tswm paper: error: the second process" in err and "no_such_scene" in err


# The first process's share of a cold compile, with numba's jit off (nothing compiles): which kernel
# modules it imports.
FIRST_PART = """
import sys
from tswm_runtime.cli import paper
paper._compile_first_part()
print(" ".join(sorted(m for m in sys.modules if m.startswith("tswm_runtime.hybrid."))))
"""


def test_first_process_compiles_the_entry_without_the_segment_kernel():
    """The first process compiles the machine's entry (integrate_at) before it waits for the second,
    which compiles the segment kernel meanwhile: importing entry must not import the segment kernel
    (it would compile it here too, or wait for it)."""
    run = subprocess.run([sys.executable, "-c", FIRST_PART], capture_output=True, text=True,
                         env={**os.environ, "NUMBA_DISABLE_JIT": "1"})
    assert run.returncode == 0, run.stderr
    imported = run.stdout.split()
    assert "tswm_runtime.hybrid.entry" in imported and "tswm_runtime.hybrid.machine" in imported
    assert "tswm_runtime.hybrid.segments" not in imported
