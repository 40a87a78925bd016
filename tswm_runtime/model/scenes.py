"""Which model a scene reference names: a shipped scene name, a scene file (.toml, generated into
the user cache on first use by derivation.model_cache) or a generated module's .py path. The CLI
and the Python API resolve scenes here, so both accept the same references and refuse bad ones
with the same message."""
from __future__ import annotations

import pkgutil
import re
from pathlib import Path
from types import ModuleType

import generated
from tswm_runtime.model.contract import ContractError, load_module


class SceneReferenceError(ValueError):
    """A scene reference that names no usable model; the message names it and what would work."""


def shipped_scenes() -> list[str]:
    """Scene names of the generated modules shipped in ``generated/``."""
    return sorted(m.name.replace("_", "-") for m in pkgutil.iter_modules(generated.__path__))


def _shipped_chain(name: str) -> Path | None:
    """generated/'s module of a shipped chain scene of that name (its header says so), else None."""
    if not re.fullmatch(r"[a-z0-9][a-z0-9-]*", name):
        return None
    path = Path(generated.__path__[0]) / f"{name.replace('-', '_')}.py"
    if not path.is_file():
        return None
    with path.open(encoding="utf-8") as file:
        return path if "from chain scene" in file.readline() else None


def is_chain(scene: str | Path) -> bool:
    """Whether ``scene`` is a chain scene file (a .toml with [[stage]] tables, read without SymPy) or a
    shipped chain scene's name."""
    import tomllib

    if Path(str(scene)).suffix != ".toml":
        return _shipped_chain(str(scene)) is not None
    try:
        return "stage" in tomllib.loads(Path(scene).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False   # the scene reader reports it


def load_chain_model(scene: str | Path) -> ModuleType:
    """The generated module of a chain scene file, made into the user cache on first use (SymPy), or a
    shipped chain's from generated/."""
    from tswm_runtime.jit import coldstart

    if _shipped_chain(str(scene)) is not None:
        spec = str(scene)
    else:
        from derivation.model_cache import module_for_chain

        spec = str(module_for_chain(scene))
    coldstart.announce((), spec)   # numba compiles the module's entry functions on import, if not cached
    module = load_module(spec)
    coldstart.done()
    return module


def model_spec(scene: str | Path) -> str:
    """A shipped scene name or a generated module's .py path, as ``load_module`` takes it; a scene
    file (.toml) is generated into the user cache first (this imports derivation/ and SymPy)."""
    scene = str(scene)
    if Path(scene).suffix == ".toml":
        from derivation.model_cache import module_for_scene

        return str(module_for_scene(scene))
    if Path(scene).suffix != ".py" and ("/" in scene or "\\" in scene or Path(scene).suffix):
        raise SceneReferenceError(f"scene {scene!r}: expected a shipped scene name, a scene file (.toml) or a "
                                  "generated module (.py)")
    return scene


def load_model(scene: str | Path | ModuleType) -> ModuleType:
    """The generated module that ``scene`` names (a module is returned as it is)."""
    if isinstance(scene, ModuleType):
        return scene
    spec = model_spec(scene)
    if spec.endswith(".py") and not Path(spec).is_file():
        raise SceneReferenceError(f"scene {spec!r}: no such file")
    try:
        return load_module(spec)
    except ModuleNotFoundError as error:
        if not (error.name or "").startswith("generated."):
            raise
        raise SceneReferenceError(f"scene {spec!r}: no generated module (shipped: {', '.join(shipped_scenes())}); "
                                  "run `tswm generate SCENE` or pass a scene file (.toml) or a module's .py "
                                  "path") from None
    except ContractError as error:
        raise SceneReferenceError(f"scene {spec!r}: {error}") from None
