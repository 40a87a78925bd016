"""Regenerate generated/ for every shipped scene and chain scene (run after changing derivation/)."""
from pathlib import Path

from derivation.chain.codegen import generate_chain_module
from derivation.chain.scene import load_chain, shipped_chains
from derivation.codegen import module_name, write_module
from derivation.model import build_model
from derivation.scene import load_scene, shipped_scenes
from tswm_common.files import write_atomic

GENERATED = Path(__file__).resolve().parents[1] / "generated"

if __name__ == "__main__":
    for name in shipped_scenes():
        print(f"wrote {write_module(build_model(load_scene(name)), GENERATED)}")
    for name in shipped_chains():
        chain = load_chain(name)
        print(f"wrote {write_atomic(GENERATED / f'{module_name(chain.name)}.py', generate_chain_module(chain))}")
