"""The kernels' helpers compiled as code to link, not to run: optimized and turned into machine
code once, inside the kernel that calls them.

numba finalizes the code library of every function it compiles: it links in the libraries of
all its callees, runs LLVM's module optimizer (O3) over the whole and emits machine code for
it. A helper three calls deep is therefore optimized and emitted four times, once in its own
library and once in each caller's, though only the kernel's copy ever runs. ``HelperLibrary``
finalizes a helper's library by linking its callees only; the kernel that links it optimizes
and emits the lot once. A helper whose machine code is asked for (a first-class function
value's address) is finalized in full at that moment. Measured with
``tools/measure_compile_times.py`` (docs/first-run.md).
"""
from __future__ import annotations

from numba.core import compiler
from numba.core.codegen import JITCodeLibrary


class HelperLibrary(JITCodeLibrary):
    """A helper's code library: linked into callers, optimized and compiled to machine code only
    where a caller needs its address."""

    _linked = False

    def __init__(self, codegen, name):
        super().__init__(codegen, name)
        self._environments = []   # (name, numba Environment) for when the machine code exists

    @property
    def codegen(self):
        """numba's codegen, but an environment is set only where the machine code exists (numba
        writes its address into the compiled global at once: there is none yet)."""
        return _DeferredEnvironments(self)

    def finalize(self):
        """Optimize the helper's own code (its callees are declarations yet), then link its
        callees' code in, each optimized on its own the same way; no machine code."""
        self._raise_if_finalized()
        self._optimize_final_module()
        seen = set()
        for library in self._linking_libraries:
            if library not in seen:
                seen.add(library)
                self._reload_init.update(library._reload_init)
                self._final_module.link_in(library._get_module_for_linking(), preserve=True)
        self._linking_libraries = []
        self._linked = self._finalized = True

    def get_pointer_to_function(self, name):
        """The address of ``name``: 0 if the library does not define it (a helper's absent Python
        wrapper), else after the full finalization numba would have done."""
        self._ensure_finalized()
        function = next((f for f in self._final_module.functions if f.name == name), None)
        if function is None or function.is_declaration:
            return 0
        if self._linked:
            self._linked = False
            self._optimize_final_module()
            self._final_module.verify()
            self._finalize_final_module()
            for env_name, env in self._environments:
                self._codegen.set_env(env_name, env)
        return super().get_pointer_to_function(name)


class _DeferredEnvironments:
    """A HelperLibrary's codegen as numba's compiler sees it: ``set_env`` is remembered."""

    def __init__(self, library):
        self._library = library

    def set_env(self, env_name, env):
        library = self._library
        if library._linked:
            library._environments.append((env_name, env))
        else:   # its machine code exists: set it now
            library._codegen.set_env(env_name, env)

    def __getattr__(self, name):
        return getattr(self._library._codegen, name)


class HelperCompiler(compiler.Compiler):
    """numba's pipeline, with the function's code in a ``HelperLibrary``."""

    def compile_extra(self, func):
        if self.state.library is None:
            self.state.library = HelperLibrary(self.state.targetctx.codegen(), func.__qualname__)
        return super().compile_extra(func)
