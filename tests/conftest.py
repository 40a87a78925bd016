"""Shared fixtures: generate a model module from scene text, as a user's new scene would be."""
from __future__ import annotations

import os

import pytest

from derivation.codegen import module_name, write_module
from derivation.model import build_model
from derivation.scene import parse_scene
from tswm_runtime.model.contract import load_module

# CLI commands run by the tests compile what they miss in the foreground, as the API does: no
# background compiles outliving a test (tests/test_warmup.py sets the other modes itself).
os.environ["TSWM_COLD_START"] = "foreground"


@pytest.fixture(scope="session")
def scene_module(tmp_path_factory):
    """scene_module(toml_text) -> the generated, imported module (one per scene name)."""
    directory = tmp_path_factory.mktemp("models")
    loaded = {}

    def make(text: str):
        scene = parse_scene(text, "test scene")
        if scene.name not in loaded:
            write_module(build_model(scene), directory)
            loaded[scene.name] = load_module(directory / f"{module_name(scene.name)}.py")
        return loaded[scene.name]
    return make
