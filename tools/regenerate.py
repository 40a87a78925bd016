"""Regenerate generated/ for every shipped scene (run after changing derivation/)."""
from pathlib import Path

from derivation.codegen import write_module
from derivation.model import build_model
from derivation.scene import load_scene, shipped_scenes

GENERATED = Path(__file__).resolve().parents[1] / "generated"

if __name__ == "__main__":
    for name in shipped_scenes():
        print(f"wrote {write_module(build_model(load_scene(name)), GENERATED)}")
