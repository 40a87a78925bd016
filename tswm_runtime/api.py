"""The Python API: what the ``tswm`` command does, as functions that take what it takes.

``simulate``, ``sweep`` and ``fit`` take a scene as the CLI does (a shipped scene name, a
scene file ``.toml`` or a generated module's ``.py`` path, or the module), parameter values
as numbers in SI or strings with a unit ("-5 kN"), grid, range and bound specs as dicts
({"F2": "-15 kN:-5 kN:11"}) or the CLI's strings ("F2=-15000:-5000:11"), and the CLI's run
settings as keywords; ``derive`` takes a shipped scene name or a scene file. Bad input raises
a ValueError whose message names the input and its value, the message the CLI prints.

Each function imports its work when called: ``import tswm_runtime`` loads neither numba's
kernels nor SymPy. See docs/api.md.
"""
from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType

from tswm_runtime.sweeps import DEFAULT_CHUNK, DEFAULT_WAIT_FOR_WORKERS


def _settings(t_end, rtol, atol, method, max_steps, max_events, points=None) -> dict:
    """The run settings given (None: the scene's); t_end may carry a time unit ("500 ms")."""
    if isinstance(t_end, str):
        from tswm_common import units
        from tswm_runtime.simulation.simulate import SimulationInputError

        try:
            t_end = units.to_si(t_end, "time")
        except units.UnitError as error:
            raise SimulationInputError(f"t_end = {t_end!r}: {error}") from None
    given = {"t_end": t_end, "rtol": rtol, "atol": atol, "method": method, "max_steps": max_steps,
             "max_events": max_events, "points": points}
    return {key: value for key, value in given.items() if value is not None}


def _model(scene):
    """The generated module that ``scene`` names (``scenes.load_model``); if numba has not cached
    it, the compile is announced first (``coldstart``), as the CLI does."""
    from types import ModuleType

    from tswm_runtime.jit import coldstart
    from tswm_runtime.model.scenes import load_model, model_spec

    if isinstance(scene, ModuleType):
        return scene
    spec = model_spec(scene)
    coldstart.announce((), spec)
    module = load_model(spec)
    coldstart.done()
    return module


def simulate(scene, params: dict | None = None, *, t_end=None, rtol=None, atol=None, method=None,
             points=None, max_steps=None, max_events=None, output=None, plot: bool = True):
    """One run of ``scene`` (``tswm simulate``): ``params`` {name: value} sets free parameters
    (``--set``); ``output``: a directory for SCENE.csv, .npz, -summary.json and (with ``plot``)
    .png. Returns the ``Result`` (arrays, phases, events, maxima, status; ``to_dict``). A chain scene
    ([[stage]] tables) returns a ``ChainResult`` (per stage regimes, switch times, force maxima); its
    ``params`` are any of its values (the module's PARAM_NAMES) and ``voltage``; no output files yet."""
    from tswm_runtime.model.scenes import is_chain
    from tswm_runtime.simulation.simulate import simulate as run

    if not isinstance(scene, ModuleType) and is_chain(scene):
        return _chain(scene, params, _settings(t_end, rtol, atol, method, max_steps, max_events, points), output)
    module = _model(scene)
    result = run(module, params, **_settings(t_end, rtol, atol, method, max_steps, max_events, points))
    if output is not None:
        from tswm_runtime.results.export import write_outputs

        write_outputs(result, module, output, plot=plot)
    return result


def _chain(scene, params, settings: dict, output):
    from tswm_runtime.model.scenes import load_chain_model
    from tswm_runtime.simulation.chain import simulate_chain
    from tswm_runtime.simulation.simulate import METHODS, SimulationInputError

    if output is not None:
        raise SimulationInputError("output: a chain scene takes no output directory yet")
    method = settings.pop("method", "dopri5")
    if method not in METHODS:
        raise SimulationInputError(f"method = {method!r}: must be one of {', '.join(METHODS)}")
    return simulate_chain(load_chain_model(scene), params, method=METHODS[method], **settings)


def sweep(scene, grid=None, *, samples: int | None = None, ranges=None, seed: int = 0, output=None,
          chunk_size: int = DEFAULT_CHUNK, client=None, wait_for_workers: float = DEFAULT_WAIT_FOR_WORKERS,
          large: bool = False,
          prune: bool = False, progress: bool = False, t_end=None, rtol=None, atol=None, method=None, max_steps=None, max_events=None):
    """``scene`` over a ``grid`` ({name: "START:STOP:COUNT" or a value}) or ``samples`` seeded
    random cases in ``ranges`` ({name: "LO:HI" or (lo, hi)}) (``tswm sweep``). ``output``: a
    directory for the chunks and SCENE-sweep.parquet, .csv and .json (resumable); ``client``: a
    dask.distributed Client to run the chunks on (``--scheduler``; docs/cluster.md), ``wait_for_workers``
    the seconds it may have no worker (``--wait-for-workers``); a lost cluster raises
    ``SweepClusterLost`` with the chunks kept. Returns the ``SweepOutcome``;
    its ``table`` is a pandas DataFrame, one row per case (columns: tswm_runtime/sweeps/sweep.py)."""
    from tswm_runtime.sweeps.sweep import sweep as run, sweep_cases

    module = _model(scene)
    P = sweep_cases(module, grid, samples=samples, ranges=ranges, seed=seed, chunk_size=chunk_size, large=large)
    return run(module, P, _settings(t_end, rtol, atol, method, max_steps, max_events), output=output,
               chunk_size=chunk_size, client=client, progress=progress, prune=prune,
               wait_for_workers=wait_for_workers)


def fit(scene, measured, free, *, starts: int = 4, sampler: str = "sobol", seed: int = 0, magnitude: bool = False,
        confidence: float = 0.95, grid_points: int | None = None, output=None, plot: bool = True,
        progress: bool = False, t_end=None, rtol=None, atol=None, method=None, max_steps=None, max_events=None,
        points=None, noise=None, profile_points: int | None = None):
    """Fit the ``free`` parameters ({name: "LO:HI" or (lo, hi)}, or "NAME[=LO:HI]" strings) of
    ``scene`` to the ``measured`` table, a CSV or Parquet file: one written by ``tswm simulate -o``
    or ``tswm sweep -o`` as it is, or one of docs/fit.md (``tswm fit``). ``output``: a directory
    for fit-report.md, fit.json and (with ``plot``) misfit.png and profile.png. ``noise``: the
    measurement noise of every measured quantity ({quantity: sigma} or "QUANTITY=SIGMA" strings;
    default: estimated from the residuals); ``profile_points``: each profile's grid. Returns the
    ``FitResult``."""
    from tswm_runtime.fitting.fit import FitInputError, fit as run
    from tswm_runtime.fitting.report import write_outputs
    from tswm_runtime.sweeps.sweep import SweepInputError, spec_items

    if not isinstance(measured, (str, os.PathLike)):
        raise FitInputError(f"measured = {type(measured).__name__}: expected the path of a .csv or .parquet file")
    module = _model(scene)
    try:
        items = spec_items(free, "--free")
    except SweepInputError as error:
        raise FitInputError(str(error)) from None
    result = run(module, measured, items, overrides=_settings(t_end, rtol, atol, method, max_steps, max_events,
                                                               points),
                 starts=starts, sampler=sampler, seed=seed, magnitude=magnitude, confidence=confidence,
                 grid_points=grid_points, progress=progress, misfit=plot, noise=noise,
                 profile_points=profile_points)
    if output is not None:
        write_outputs(result, output, plot=plot)
    return result


def derive(scene: str | Path, *, latex=None, markdown=None, pdf=None):
    """Derive ``scene``'s model (``tswm derive``; imports SymPy): returns the model (modes,
    states, laws, parameters) and writes the derivation document as ``markdown``, ``latex`` and
    a ``pdf`` (a path, or True: named after the LaTeX file, else SCENE-derivation.pdf)."""
    from derivation.document import write_documents
    from derivation.model import build_model
    from derivation.scene import load_scene

    model = build_model(load_scene(scene))
    write_documents(model, latex=latex, markdown=markdown, pdf=pdf)
    return model
