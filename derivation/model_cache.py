"""Generated modules of scene files, kept in a user cache: a scene file runs as it is.

``module_for_scene(path)`` derives and generates the module of a scene file into
``$TSWM_CACHE`` (default ``$XDG_CACHE_HOME/tswm`` or ``~/.cache/tswm``), under a name
keyed by the scene file's and the generator's sha256, and reuses it while both are
unchanged; ``module_for_chain(path)`` does the same for a chain scene ([[stage]] tables). generated/ (the shipped scenes) is never touched.
"""
from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

from derivation.codegen import body_is_intact, generator_digest, module_name, write_module
from derivation.model import build_model
from derivation.scene import load_scene
from tswm_common.files import write_atomic

LOG = logging.getLogger("tswm.derive")   # WARNING: printed to stderr without logging configuration


def _say_deriving(source, target: Path) -> None:
    """Say, before SymPy starts, that the scene's model is being derived and where it will be kept."""
    LOG.warning("tswm: deriving the model of %s with SymPy and generating its module into %s, once; later "
                "runs load it from there", source, target.parent)


def cache_dir() -> Path:
    """Where generated modules of scene files live."""
    if os.environ.get("TSWM_CACHE"):
        return Path(os.environ["TSWM_CACHE"]) / "models"
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "tswm" / "models"


def module_for_scene(path: str | os.PathLike) -> Path:
    """The generated module (.py) of the scene file at ``path``: from the cache, or made now."""
    scene = load_scene(Path(path))
    key = hashlib.sha256(f"{scene.digest} {generator_digest()}".encode()).hexdigest()[:16]
    directory = cache_dir() / f"{module_name(scene.name)}_{key}"
    target = directory / f"{module_name(scene.name)}.py"
    if target.exists() and body_is_intact(target.read_text()):
        return target
    _say_deriving(path, target)
    return write_module(build_model(scene), directory, force=True)


def module_for_chain(path: str | os.PathLike) -> Path:
    """The generated module (.py) of the chain scene file at ``path`` (or a shipped chain's name): from the
    cache, or made now."""
    from derivation.chain.scene import load_chain

    return module_for_chain_scene(load_chain(path if isinstance(path, str) else Path(path)))


def module_for_chain_scene(chain) -> Path:
    """The generated module (.py) of a chain scene (a ChainScene, e.g. a sweep's variant with its own
    digest): from the cache, or made now."""
    from derivation.chain.codegen import generate_chain_module, generator_digest as chain_digest

    key = hashlib.sha256(f"{chain.digest} {chain_digest()}".encode()).hexdigest()[:16]
    directory = cache_dir() / f"{module_name(chain.name)}_{key}"
    target = directory / f"{module_name(chain.name)}.py"
    if target.exists() and body_is_intact(target.read_text()):
        return target
    _say_deriving(f"chain scene '{chain.name}'", target)
    return write_atomic(target, generate_chain_module(chain))
