"""Shared fixtures: generate a model module from scene text, as a user's new scene would be.

A whole run on pytest-xdist workers first fills numba's cache once (``pytest_configure``):
each worker imports the kernels and every test module while it collects, and with a cold cache
every worker compiled the same integration kernels (about 100 s of CPU each), shipped models and
the tests' own compiled code (``integration.single`` and the closed-form models of
``test_integrators``, 33 s of CPU each, measured in one process at a load of 5).
"""
from __future__ import annotations

import fcntl
import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from derivation.codegen import write_module
from derivation.model import build_model
from derivation.scene import parse_scene
from tswm_runtime.model.contract import load_module

# CLI commands run by the tests compile what they miss in the foreground, as the API does: no
# background compiles outliving a test (tests/test_warmup.py sets the other modes itself).
os.environ["TSWM_COLD_START"] = "foreground"

ROOT = Path(__file__).parents[1]
GENERATED = ROOT / "generated"
KERNELS = ("import sys; from tswm_runtime.startup.warmup import compile_into_cache; "
           "compile_into_cache(sys.argv[1:], None)")
IMPORTS = ("import importlib, sys; sys.path.insert(0, 'tests'); "
           "[importlib.import_module(name) for name in sys.argv[1:]]")
# What the test modules compile when they are imported (cached): the one-segment kernel of tests and tools,
# and through test_integrators its closed-form models; the kernels' check below stands for them all.
# test_integrators by the name pytest imports it under (tests/ first on sys.path, as pytest's rootdir
# import puts it): numba's cached code names its module, and a cache written under one name fails to
# load under the other.
TESTS_COMPILE = ("tswm_runtime.integration.single", "test_integrators")


def _whole_run_on_workers(config) -> bool:
    """The controller of an xdist run over the configured testpaths (not a run of a few files)."""
    return (not hasattr(config, "workerinput") and config.getoption("dist", "no") != "no"
            and config.args_source == pytest.Config.ArgsSource.TESTPATHS)


def pytest_configure(config):
    """Compile what numba's cache misses once, before the workers start: the kernels in one
    process, the shipped models in another, the tests' own compiled code in a third (the two
    cores share them), then every worker loads them."""
    if not _whole_run_on_workers(config):
        return
    from tswm_runtime.jit import coldstart
    from tswm_runtime.jit.cache_guard import kernel_digest

    groups = coldstart.cold_groups(list(coldstart.GROUPS))
    sources = [coldstart.model_source(path.stem) for path in sorted(GENERATED.glob("[!_]*.py"))]
    models = [module for source, module in filter(None, sources) if coldstart.model_cold(source, module)]
    single = coldstart.is_cached(coldstart.RUNTIME / "integration" / "single.py", "integrate_segment",
                                 "tswm_runtime.integration.single", True, kernel_digest())
    tests = () if single else TESTS_COMPILE
    commands = [[sys.executable, "-c", code, *names]
                for code, names in ((KERNELS, groups), (IMPORTS, models), (IMPORTS, tests)) if names]
    jobs = [subprocess.Popen(argv, cwd=ROOT, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
            for argv in commands]
    for job in jobs:
        output = job.communicate()[0]
        if job.returncode:   # the workers compile what is still missing; the tests report the error
            print(f"conftest: compiling into numba's cache failed (exit {job.returncode}):\n{output}", file=sys.stderr)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """A test that builds its own chain module (``chain_module``: a SymPy derivation and a compile of
    4 to 10 s per chain structure) is heavy: CI runs it after the default set. Tryfirst, so that
    ``-m`` sees the mark."""
    for item in items:
        if "chain_module" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.heavy)


@pytest.fixture(scope="session")
def module_once(tmp_path_factory):
    """module_once(text, write) -> the module that ``write(folder)`` writes for ``text`` into an
    empty folder and returns the path of, imported; one per text and test run. The folder is the
    run's, named by the digest of ``text``, so every xdist worker finds it: the first writes the
    module and compiles it into numba's cache beside it, holding the folder's lock; another waits
    and loads the compiled code instead of compiling it again."""
    base = tmp_path_factory.getbasetemp()
    directory = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "models"
    directory.mkdir(exist_ok=True)
    loaded = {}

    def load(text: str, write):
        if text not in loaded:
            folder = directory / hashlib.sha256(text.encode()).hexdigest()[:16]
            folder.mkdir(exist_ok=True)
            with open(folder / "lock", "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                written = folder / "module"
                if not written.exists():
                    written.write_text(write(folder).name)
                loaded[text] = load_module(folder / written.read_text())
        return loaded[text]
    return load


@pytest.fixture(scope="session")
def scene_module(module_once):
    """scene_module(toml_text) -> the generated, imported module (compiled once per test run)."""
    return lambda text: module_once(text, lambda folder: write_module(build_model(parse_scene(text, "test scene")),
                                                                      folder))


@pytest.fixture(scope="session")
def chain_module(module_once):
    """chain_module(toml_text) -> the chain module of the text's scene: one generated and compiled module per
    chain structure (its source but for the scene's name, values and run: tests/chains.py ``structure``),
    shared by every text of that structure, with the text's own constants (its values as PARAM_DEFAULTS,
    its motor table, its run, its name) in place of the first text's."""
    from derivation.chain.codegen import generate_chain_module
    from derivation.chain.scene import parse_chain
    from tests.chains import structure, with_constants

    def load(text):
        source = generate_chain_module(parse_chain(text, "test chain"))
        key, own = structure(source)

        def write(folder):
            path = folder / f"chain_{key[:16]}.py"
            path.write_text(source)
            return path
        return with_constants(module_once(key, write), own)
    return load
