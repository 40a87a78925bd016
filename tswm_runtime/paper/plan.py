"""What ``tswm paper`` runs, named before anything heavy is imported (the CLI says it within a
second of starting): the readings' scenes, and the stages of the job with their estimated
seconds, from which its progress bar tells the time remaining.

The compile stages take their seconds from ``jit/compile_times.json``; the others were
measured on a warm cache on 2 cores (``tswm paper``, stage by stage).
"""
from __future__ import annotations

SCENES = {"consistent": "paper", "literal": "paper-literal", "runup": "paper-runup",
          "lostmotion": "paper-lostmotion"}   # reading key -> its shipped scene

KERNELS, MODELS, BATCH = ("the integration kernels", "the models and the dopri5 step (second process)",
                          "the sweep kernel")
FIT, RUNS, FIGURES, DOCUMENT, WRITE = (f"fit L of {SCENES['lostmotion']} to Table 3", "the readings' runs and checks",
                                       "figures", "derivation document (second process)", "write the report")
WARM = {KERNELS: 1.5, MODELS: 0.5, BATCH: 0.2, FIT: 7.0, RUNS: 2.0, FIGURES: 4.0, WRITE: 0.5}
DERIVATION_S = 11.0   # the second process's derivation document: SymPy and pdflatex


def estimates(compile_s: dict[str, float], derivation: bool) -> dict[str, float]:
    """The stages in order with their seconds: ``compile_s`` gives the compile seconds of
    KERNELS, MODELS and BATCH where they are cold. The second process compiles the models and
    then writes the document while this one compiles the kernels: the stages that wait for it
    are estimated at what is left of it by then."""
    seconds = {KERNELS: compile_s.get(KERNELS, WARM[KERNELS])}
    models = compile_s.get(MODELS, WARM[MODELS])
    seconds[MODELS] = max(models - seconds[KERNELS], WARM[MODELS])
    seconds.update({BATCH: compile_s.get(BATCH, WARM[BATCH]), FIT: WARM[FIT], RUNS: WARM[RUNS],
                    FIGURES: WARM[FIGURES]})
    seconds[DOCUMENT] = max(models + DERIVATION_S - sum(seconds.values()), 0.1) if derivation else 0.0
    seconds[WRITE] = WARM[WRITE]
    return seconds
