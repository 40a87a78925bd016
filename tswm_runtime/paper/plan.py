"""What ``tswm paper`` runs, named before anything heavy is imported (the CLI says it within a
second of starting): the readings' scenes, and the stages of the job with their estimated
seconds, from which its progress bar tells the time remaining.

The compile stages take their seconds from ``jit/compile_times.json``; the others were
measured on a warm cache on 2 cores (``tswm paper``, stage by stage).
"""
from __future__ import annotations

SCENES = {"consistent": "paper", "literal": "paper-literal", "runup": "paper-runup",
          "lostmotion": "paper-lostmotion"}   # reading key -> its shipped scene
#: The scenes whose models the second process compiles (beside the segment kernel and the dopri5 step);
#: the first compiles the others after its kernels, so that both have about as much to compile (a cold
#: run measured, CPU: the segment kernel 32.8 s and the dopri5 step 1.6 s in the second; the mode machine
#: 20.7 s, the sweep kernel 5.7 s, states_at 2.8 s and the entry 2.5 s in the first; a model 3.6-4.8 s).
BACKGROUND_SCENES = ("paper", "paper-runup")

KERNELS, BATCH, MODELS = ("the mode machine and models", "the sweep kernel",
                          "the segment kernel, the dopri5 step and models (second process)")
FIT, RUNS, FIGURES, DOCUMENT, WRITE = (f"fit L of {SCENES['lostmotion']} to Table 3", "the readings' runs and checks",
                                       "figures", "derivation document (second process)", "write the report")
WARM = {KERNELS: 1.5, MODELS: 0.5, BATCH: 0.2, FIT: 7.0, RUNS: 2.0, FIGURES: 4.0, WRITE: 0.5}
DERIVATION_S = 11.0   # the second process's derivation document: SymPy and pdflatex


def first_process_scenes() -> list[str]:
    """The scenes whose models the first process compiles (those not in BACKGROUND_SCENES)."""
    return [scene for scene in SCENES.values() if scene not in BACKGROUND_SCENES]


def estimates(compile_s: dict[str, float], derivation: bool) -> dict[str, float]:
    """The stages in order with their seconds: ``compile_s`` gives the compile seconds of
    KERNELS, BATCH and MODELS where they are cold. The second process compiles its part (MODELS)
    and then writes the document while this one compiles the mode machine, the sweep kernel and
    its models: the stages that wait for it are estimated at what is left of it by then."""
    seconds = {KERNELS: compile_s.get(KERNELS, WARM[KERNELS]), BATCH: compile_s.get(BATCH, WARM[BATCH])}
    models = compile_s.get(MODELS, WARM[MODELS])
    seconds[MODELS] = max(models - seconds[KERNELS] - seconds[BATCH], WARM[MODELS])
    seconds.update({FIT: WARM[FIT], RUNS: WARM[RUNS], FIGURES: WARM[FIGURES]})
    seconds[DOCUMENT] = max(models + DERIVATION_S - sum(seconds.values()), 0.1) if derivation else 0.0
    seconds[WRITE] = WARM[WRITE]
    return seconds
