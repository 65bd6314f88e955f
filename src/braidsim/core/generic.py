"""Generic compiled functions: one name, one implementation per record type.

The solver is written once against generic functions such as ``contact_forces(law, p, ...)``
or ``derivatives(model, t, ...)``. Each contact law, friction law, excitation and model is a
``NamedTuple`` record class, and registers its implementation of a generic function for that
class::

    @contact_forces.register(MyLaw)
    def _my_law_forces(law, p, p_dot, v0): ...   # parameters in the declaration's order

Inside compiled code the call ``contact_forces(law, ...)`` is resolved by the *type* of
``law`` when the caller is compiled (numba's ``overload`` mechanism), so the dispatch costs
nothing at run time and the implementation is inlined into the solver. A compiled caller is
specialised, and cached on disk, for each combination of record types it is called with.

A record class is found by the first argument's class; registering a class twice for one
generic function is an error (one definition each).
"""

from __future__ import annotations

import hashlib
import inspect
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar
from typing import overload as overload_type

from llvmlite import binding as llvm_binding
from numba import njit, types
from numba.core import cgutils, compiler
from numba.core import config as numba_config
from numba.core.caching import CompileResultCacheImpl, FunctionCache, NullCache
from numba.core.codegen import JITCodeLibrary
from numba.core.dispatcher import _FunctionCompiler  # type: ignore[attr-defined]
from numba.core.imputils import impl_ret_borrowed, lower_getattr_generic
from numba.core.registry import CPUDispatcher
from numba.core.typing.templates import (
    AttributeTemplate,
    infer,
    infer_getattr,
    infer_global,
    make_overload_template,
)
from numba.extending import intrinsic, models, overload, register_model

F = TypeVar("F", bound=Callable[..., Any])


class _LinkOnlyLibrary(JITCodeLibrary):
    """The code library of a helper: LLVM IR that numba links into each caller's library,
    which optimises it with the caller's code and makes the machine code; never machine
    code of its own.

    numba turns every function it compiles into machine code, in memory and in its cache,
    so that Python can call it, after the full optimisation of its module. A helper is
    never called from Python: its callers link its IR and compile it with their own code
    (``integrate`` holds all of them). Measured on the 2-core development machine, the same
    results to the bit:

    * without the helpers' own machine code, the cold compile of ``simulate("paper-3.3",
      series=False)`` took 10.5 instead of 11.2 s of CPU (three alternated pairs, 0.66-0.73
      s less in each);
    * with numba's cheap module passes alone on a helper (the caller's full optimisation
      then inlines it where it is called and optimises it there), 0.3-0.5 s less again (two
      pairs), and the runs faster: paper-3.3 (0.5 s, best of 30 calls, three alternated
      process pairs) 1.53-1.57 instead of 1.68 ms at rtol 5.6e-9, 3.24-3.28 instead of
      3.61-3.69 ms at 3.2e-11, with Taylor steps 1.50-1.52 instead of 1.52-1.62 ms.

    The cache keeps the IR (``LINK_ONLY`` below), which a later compile links without
    making machine code either.

    ``always_inline``: the helper's functions carry LLVM's ``alwaysinline`` attribute, so
    that the caller's optimiser inlines them wherever they are called (see :func:`helper`).
    """

    def __init__(self, codegen: Any, name: str, always_inline: bool = False) -> None:
        super().__init__(codegen, name)
        self._always_inline = always_inline

    def add_ir_module(self, ir_module: Any) -> None:
        if self._always_inline:
            for fn in ir_module.functions:
                if not fn.is_declaration:
                    fn.attributes.add("alwaysinline")
        super().add_ir_module(ir_module)

    def _optimize_final_module(self) -> None:
        # numba's first, cheap module passes alone: the caller's library runs the full
        # optimisation over its own code and the helpers it links, which then inlines them
        # in their context (see the class docstring)
        try:
            mpm_cheap, mpb_cheap = self._codegen._module_pass_manager(
                loop_vectorize=self._codegen._loopvect,
                slp_vectorize=False,
                opt=self._codegen._opt_level,
                cost="cheap",
            )
        except (AttributeError, TypeError):  # an older numba, with other pass managers
            super()._optimize_final_module()
            return
        mpm_cheap.run(self._final_module, mpb_cheap)

    def _finalize_final_module(self) -> None:
        # numba's version adds the module to its execution engine and makes its machine code
        self._finalize_dynamic_globals()
        self._verify_declare_only_symbols()
        self._finalized = True

    def get_pointer_to_function(self, name: str) -> int:
        return 0  # (no code: CompiledOnly refuses calls from Python)

    @property
    def codegen(self) -> Any:
        # numba sets each compiled function's environment pointer in the execution
        # engine's copy of its module, which a link-only library has not (a helper creates
        # no Python object and reads no environment)
        return _EnvlessCodegen(self._codegen)

    def serialize_using_object_code(self) -> Any:
        # what numba's cache stores for a compiled function: here the IR for linking
        self._ensure_finalized()
        return (self.name, LINK_ONLY, self._get_module_for_linking().as_bitcode())

    @classmethod
    def from_cache(cls, codegen: Any, state: Any) -> _LinkOnlyLibrary:
        name, _, bitcode = state
        self = cls(codegen, name)
        self._final_module = llvm_binding.parse_bitcode(bitcode)
        self._finalize_final_module()
        return self


class _EnvlessCodegen:
    """numba's codegen, whose ``set_env`` does nothing (see _LinkOnlyLibrary.codegen)."""

    def __init__(self, codegen: Any) -> None:
        self._codegen = codegen

    def set_env(self, env_name: str, env: Any) -> None:
        pass

    def __getattr__(self, name: str) -> Any:
        return getattr(self._codegen, name)


LINK_ONLY = "braidsim-link-only"  # the kind of a helper's library in numba's cache


class _LinkOnlyCompiler(_FunctionCompiler):
    """numba's compiler of a dispatcher's function, handing the pipeline a
    :class:`_LinkOnlyLibrary` (numba's own ``_compile_core`` with that one argument more)."""

    always_inline = False  # (set by the dispatcher: the library's option)

    def _compile_core(self, args: Any, return_type: Any) -> Any:
        flags = compiler.Flags()
        self.targetdescr.options.parse_as_flags(flags, self.targetoptions)
        flags = self._customize_flags(flags)
        impl = self._get_implementation(args, {})
        codegen = self.targetdescr.target_context.codegen()
        cres = compiler.compile_extra(
            self.targetdescr.typing_context,
            self.targetdescr.target_context,
            impl,
            args=args,
            return_type=return_type,
            flags=flags,
            locals=self.locals,
            library=_LinkOnlyLibrary(codegen, impl.__qualname__, self.always_inline),
            pipeline_class=self.pipeline_class,
        )
        if cres.typing_error is not None:
            raise cres.typing_error
        return cres


class _LinkOnlyCacheImpl(CompileResultCacheImpl):
    """numba's cache of compile results, rebuilding a helper's library from its IR.

    Its files are named apart from those of an ordinary compile of the same function (numba
    names them by the function alone, and keys their entries by signature, not by kind): an
    :func:`inline_helper` has both, the link-only one for compiled callers and its Python
    twin."""

    def get_filename_base(self, fullname: str, abiflags: str) -> str:
        return super().get_filename_base(fullname, abiflags) + ".link"

    def rebuild(self, target_context: Any, payload: Any) -> Any:
        if payload[0][1] != LINK_ONLY:
            return super().rebuild(target_context, payload)
        # numba's rebuild asks the codegen to unserialize the library: for the span of this
        # call (under numba's compiler lock) the codegen makes a link-only one
        codegen = target_context.codegen()
        codegen.unserialize_library = lambda state: _LinkOnlyLibrary.from_cache(codegen, state)
        try:
            return super().rebuild(target_context, payload)
        finally:
            del codegen.unserialize_library


# ------------------------------------------------------------------------------------------
# A cache that sees edits of the code it compiled in, wherever that code is written
# ------------------------------------------------------------------------------------------

#: the core's own sources: every compiled function of the core may hold code of any of them
_CORE_DIR = Path(__file__).resolve().parent
_CORE_FILES: tuple[str, ...] | None = None
#: file -> blake2b of its bytes, read once per process (as the digests below)
_FILE_HASHES: dict[str, bytes] = {}
#: every generic function declared (GenericFunction appends itself)
_GENERICS: list[GenericFunction] = []
#: the digest for each set of record classes, once per process (a process compiles what it
#: loaded before any edit: numba's dispatchers keep their compiled code in memory)
_DIGESTS: dict[frozenset[type], str] = {}


def _file_hash(path: str) -> bytes:
    """blake2b of a source file's bytes (b"" where it cannot be read), read once per
    process: the core's files enter every digest, a new set of record classes reads only
    its own files."""
    known = _FILE_HASHES.get(path)
    if known is None:
        try:
            known = hashlib.blake2b(Path(path).read_bytes(), digest_size=16).digest()
        except OSError:
            known = b""
        _FILE_HASHES[path] = known
    return known


def _record_classes(numba_types: Iterable[Any], out: set[type]) -> set[type]:
    """The record classes of a signature, the records inside records (a model's laws,
    friction and excitation) included."""
    for t in numba_types:
        cls = record_class(t)
        if isinstance(t, RecordRef):
            t = t.record
        if cls is not None and cls not in out:
            out.add(cls)
        if isinstance(t, types.BaseTuple):
            _record_classes(getattr(t, "types", ()), out)
    return out


def sources_digest(numba_types: Iterable[Any]) -> str:
    """A digest of the sources a function compiled for these argument types holds: every
    file of ``braidsim.core``, and for each record class among the types (or inside them)
    the file that defines it and the files of its registered implementations, wherever
    they are (an extension outside the core, a test's model).

    numba's cache keys a compiled function by its own bytecode and checks its own file's
    time stamp only, but the solver's machine code holds the code of every helper and
    implementation it calls, from other files: after an edit of a contact law, a run loaded
    the solver compiled before it and gave the old law's results (a force scaled by 1.0001
    passed the law's test). With this digest in the key (:class:`SourceAwareCache`), the
    edited law's runs are compiled again. Content, not time stamps: a checkout that restores
    a file's content finds its compiled code again."""
    global _CORE_FILES
    classes = frozenset(_record_classes(numba_types, set()))
    known = _DIGESTS.get(classes)
    if known is not None:
        return known
    if _CORE_FILES is None:
        _CORE_FILES = tuple(sorted(str(p) for p in _CORE_DIR.rglob("*.py")))
    files = set(_CORE_FILES)
    for cls in classes:
        module = sys.modules.get(cls.__module__)
        if module is not None and getattr(module, "__file__", None):
            files.add(str(module.__file__))
        for g in _GENERICS:
            fn = g.impls.get(cls)
            if fn is not None:
                files.add(fn.__code__.co_filename)
    h = hashlib.blake2b(digest_size=16)
    for path in sorted(files):
        h.update(path.encode())
        h.update(_file_hash(path))
    digest = _DIGESTS[classes] = h.hexdigest()
    return digest


class _SourceAwareKey:
    """Mixin of numba's ``Cache``: the index key of a compiled function also holds
    :func:`sources_digest` of its argument types."""

    def _index_key(self, sig: Any, codegen: Any) -> Any:
        sig_key, magic, hashes = super()._index_key(sig, codegen)  # type: ignore[misc]
        arg_types = getattr(sig, "args", sig)
        return sig_key, magic, (*hashes, sources_digest(arg_types))


class SourceAwareCache(_SourceAwareKey, FunctionCache):
    """numba's cache of a compiled function, keyed by the sources it holds as well
    (:func:`sources_digest`)."""


class _LinkOnlyCache(_SourceAwareKey, FunctionCache):
    _impl_class = _LinkOnlyCacheImpl


def cached_njit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit(**options)`` with its disk cache keyed by the sources its code holds
    (:class:`SourceAwareCache`), for the core's compiled functions that are not helpers."""

    def deco(fn: Callable[..., Any]) -> Any:
        disp: Any = njit(**options)(fn)
        if getattr(numba_config, "DISABLE_JIT", False):
            return disp
        try:
            disp._cache = SourceAwareCache(disp.py_func)
        except RuntimeError:  # no file to cache it by (typed at a prompt): compiled per process
            pass
        return disp

    return deco


# numba's internals the link-only helpers rely on (numba 0.68); without them, plain helpers
_LINK_ONLY_OK = all(
    hasattr(c, a)
    for c, a in (
        (JITCodeLibrary, "_finalize_final_module"),
        (JITCodeLibrary, "_optimize_final_module"),
        (JITCodeLibrary, "_finalize_dynamic_globals"),
        (JITCodeLibrary, "_verify_declare_only_symbols"),
        (JITCodeLibrary, "_get_module_for_linking"),
        (_FunctionCompiler, "_compile_core"),
        (_FunctionCompiler, "_customize_flags"),
        (CompileResultCacheImpl, "rebuild"),
    )
)


class CompiledOnly(CPUDispatcher):
    """The dispatcher of a :func:`helper`: its function is compiled to be called from
    compiled code only.

    For each signature of a function it can call from Python, numba also builds a wrapper
    that unboxes the arguments from Python objects and a C callback, and lowers, optimises
    and turns both into machine code. The solver's helpers take the model by reference and
    work arrays that only the solver makes, and are never called from Python: without the
    wrappers the cold compile of ``simulate("paper-3.3", series=False)`` takes 0.7-0.9 s of
    CPU less (15.6-16.8 s against 16.5-17.6 s, three alternated pairs), with the same
    results to the bit. Nor is the function itself made into machine code
    (:class:`_LinkOnlyLibrary`). A call from Python would then jump to no code at all, so
    it raises instead; tests call a helper through a function compiled for it. (An
    :func:`inline_helper` has a twin for calls from Python instead.)
    """

    def __init__(
        self, *args: Any, always_inline: bool = False, python_twin: bool = False, **kws: Any
    ) -> None:
        super().__init__(*args, **kws)
        self._python_twin = python_twin
        self._twin: Any = None
        if _LINK_ONLY_OK:
            c: Any = self._compiler  # type: ignore[has-type]
            self._compiler = _LinkOnlyCompiler(
                c.py_func, c.targetdescr, c.targetoptions, c.locals, c.pipeline_class
            )
            self._compiler.always_inline = always_inline

    def enable_caching(self) -> None:
        if _LINK_ONLY_OK:
            self._cache = _LinkOnlyCache(self.py_func)
        else:
            super().enable_caching()

    def __call__(self, *args: Any, **kws: Any) -> Any:
        if self._python_twin:
            if self._twin is None:  # compiled (or loaded from the cache) at the first call
                cache = self._cache.__class__ is not NullCache
                options = {"error_model": "numpy", "_nrt": False}
                twin = cached_njit(**options) if cache else njit(**options)  # type: ignore[call-overload]
                self._twin = twin(self.py_func)
            return self._twin(*args, **kws)
        raise TypeError(
            f"{self.py_func.__qualname__} is compiled to be called from the solver's compiled "
            "code only; call it from a function compiled with numba"
        )


@overload_type
def helper(func: F, *, always_inline: bool = False, python_twin: bool = False) -> F: ...


@overload_type
def helper(
    func: None = None, *, always_inline: bool = False, python_twin: bool = False
) -> Callable[[F], F]: ...


def helper(func: Any = None, *, always_inline: bool = False, python_twin: bool = False) -> Any:
    """Compile ``func`` as a helper of the compiled core (``@helper`` or
    ``@helper(always_inline=True)``).

    No allocation, so compiled without numba's reference counting (NRT), whose atomic
    increment/decrement on every array argument of every call was over half the run time of
    the first kernel (paper-3.4a: 4.5 ms with it, 2.1 ms without); IEEE division (numpy's
    error model); cached on disk; callable from compiled code only (:class:`CompiledOnly`).

    ``always_inline``: the caller's LLVM optimiser inlines the helper wherever it is
    called, where its cost model would keep a call (an attribute on the helper's IR, so
    numba compiles it no more than once; numba's own ``inline="always"`` copies the
    helper's numba IR into each caller and types and lowers it again there). For the
    large functions the loop calls at every step with many arguments: a call passes each
    array as 7 words and saves the loop's live values around it. Measured on paper-3.3
    (0.5 s, best of 60 calls, alternated processes), with ``scan_step`` alone inlined,
    Taylor steps at rtol 1.8e-9 took 1.31 instead of 1.42-1.50 ms; with the five helpers
    of the step marked so, 1.19-1.22 ms, and the default integrator at rtol 5.6e-9
    1.20-1.22 instead of 1.44 ms, results bit-identical. The cold compile stayed within its
    spread (10.6-11.3 against 10.3-11.3 s, five alternated pairs): numba compiles the
    helper once either way.

    ``python_twin``: a call from Python runs an ordinary compile of the same function, made
    (or loaded from numba's cache) at the first such call, instead of raising.
    """
    if func is None:
        return lambda f: helper(f, always_inline=always_inline, python_twin=python_twin)
    if getattr(numba_config, "DISABLE_JIT", False):  # numba's switch to run plain Python
        return func
    disp = CompiledOnly(
        py_func=func,
        locals={},
        targetoptions={
            "nopython": True,
            "error_model": "numpy",
            "_nrt": False,
            "no_cpython_wrapper": True,
            "no_cfunc_wrapper": True,
        },
        always_inline=always_inline,
        python_twin=python_twin,
    )
    try:
        disp.enable_caching()
    except RuntimeError:  # no file to cache it by (typed at a prompt): compiled per process
        pass
    return disp


def inline_helper(func: F) -> F:
    """Compile ``func`` as a small helper that LLVM inlines into every compiled caller
    (:func:`helper` with ``always_inline``), callable from Python as well (its twin).

    These were numba's own inlined functions (``inline="always"``), whose numba IR numba
    copies into each caller, and types and lowers there again, at every call site; as
    helpers numba compiles each once (per argument types), and LLVM inlines them with the
    same machine code as a result (the impact tables, series, statistics and sensitivities
    of 7 scenarios with each integrator bit-identical, and the runs as fast). With these and
    the generic functions' implementations so compiled, the cold ``braidsim run paper-3.3
    --json`` took 7.5-7.7 s of CPU instead of 9.1-9.8 s (2-core development machine), with
    Taylor steps 12.2 s instead of 18.4-19.8 s."""
    return helper(func, always_inline=True, python_twin=True)


def overload_inlined(stub: Callable[..., Any], typer: Callable[..., Any]) -> None:
    """``numba.extending.overload(stub, inline="always")(typer)``, without the compile of each
    implementation on its own.

    For an overload, numba compiles the implementation as a function of its own, down to
    machine code, for every argument types it meets ("make sure that the implementation can
    be fully compiled"), and then types it once more to inline it where it is called. The
    code of the first compile is never used: an inlined overload is not called. Here the
    implementation's dispatcher is made unable to compile; numba then only types the
    implementation for inlining, which reports the same typing errors. And numba types an
    implementation anew each time a caller's type inference asks for the call's signature
    (several times per call site); the first typing for given argument types is kept.

    Measured on the cold compile of ``simulate("paper-3.3", series=False)`` (numba compile
    events, CPU): 35.0 s before, 27.9 s without the compiles alone, 19.7 s with the typing
    kept as well; the machine code is the same (results bit-identical). This relies on
    numba's overload template (``make_overload_template``, its ``_build_impl`` and
    ``generic``, a dispatcher's ``_can_compile``) as numba 0.68 defines them; a numba
    without them gets the plain overload.
    """
    opts = {"no_cpython_wrapper": True, "nopython": True}  # overload's defaults
    base = make_overload_template(stub, typer, opts, True, "always")
    if not all(hasattr(base, a) for a in ("_build_impl", "generic", "_get_jit_decorator")):
        overload(stub, inline="always")(typer)
        return

    def build_impl(self: Any, cache_key: Any, args: Any, kws: Any) -> Any:
        pyfunc = self._overload_func(*args, **kws)
        if pyfunc is None:
            self._impl_cache[cache_key] = None, None
            return None, None
        disp = self._get_jit_decorator()(**self._jit_options)(pyfunc)
        # typing for the inliner then folds the argument types only and compiles nothing
        # (``disable_compile`` refuses a dispatcher with no signature yet, hence the flag)
        disp._can_compile = False
        self._impl_cache[cache_key] = disp, args
        return disp, args

    typed: dict[Any, Any] = {}

    def generic(self: Any, args: Any, kws: Any) -> Any:
        # numba types the implementation again (its untyped passes and type inference) each
        # time the type inference of a caller asks for this call's signature: many times per
        # call site, and at every call site. The inliner reads what the last typing stored
        # for these argument types, so the first typing is kept and its signature returned.
        key = (tuple(args), tuple(sorted(kws.items())))
        if key not in typed:
            typed[key] = base.generic(self, args, kws)
        return typed[key]

    template = type(base)(base.__name__, (base,), {"_build_impl": build_impl, "generic": generic})
    infer(template)
    infer_global(stub, types.Function(template))


class RecordRef(types.Type):
    """A record (a ``NamedTuple`` of the core) passed by reference: a pointer to it.

    numba passes a record to a function it calls as one argument per field, and an array
    field as seven or nine (the carrier with its tables: about 65 values at every call of
    every helper, at every step). A reference is one pointer; reading ``ref.field`` loads that
    field alone, so code written for the record reads a reference unchanged, and a generic
    function dispatches on the record type behind it. Made by :func:`by_ref`.
    """

    def __init__(self, record: Any) -> None:
        self.record: Any = record  # the numba type of the record
        super().__init__(name=f"RecordRef({record})")

    @property
    def key(self) -> Any:
        return self.record


@register_model(RecordRef)
class _RecordRefModel(models.PrimitiveModel):
    def __init__(self, dmm: Any, fe_type: RecordRef) -> None:
        be_type = dmm.lookup(fe_type.record).get_data_type().as_pointer()
        super().__init__(dmm, fe_type, be_type)


@infer_getattr
class _RecordRefFields(AttributeTemplate):
    key = RecordRef

    def generic_resolve(self, ref: Any, attr: str) -> Any:  # type: ignore[override]
        rec = ref.record
        if attr in rec.fields:
            return rec.types[rec.fields.index(attr)]
        return None


@lower_getattr_generic(RecordRef)
def _record_ref_field(context: Any, builder: Any, typ: Any, ptr: Any, attr: str) -> Any:
    rec = typ.record
    i = rec.fields.index(attr)
    fty = rec.types[i]
    val = context.data_model_manager[fty].load_from_data_pointer(
        builder, cgutils.gep_inbounds(builder, ptr, 0, i)
    )
    return impl_ret_borrowed(context, builder, fty, val)


def _by_ref(typingctx: Any, record: Any) -> Any:
    """``by_ref(record)`` in compiled code: a :class:`RecordRef` to ``record``, valid while
    the calling function runs (the record is copied once into its stack frame; its arrays
    are borrowed, their reference counts untouched)."""
    if not isinstance(record, types.BaseNamedTuple):
        return None

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        dm = context.data_model_manager[record]
        slot = cgutils.alloca_once(builder, dm.get_data_type())
        builder.store(dm.as_data(builder, args[0]), slot)
        return slot

    return RecordRef(record)(record), codegen


by_ref: Any = intrinsic(_by_ref)


def record_class(numba_type: Any) -> Any:
    """The Python class of a record type, or of the record behind a :class:`RecordRef`."""
    if isinstance(numba_type, RecordRef):
        numba_type = numba_type.record
    return getattr(numba_type, "instance_class", None)


class GenericFunction:
    """The registry of a generic function: its implementation for each record class of its
    first argument. Compiled code calls the stub; ``py(...)`` calls it from Python."""

    def __init__(self, stub: Callable[..., Any], inline: bool = True) -> None:
        self.stub = stub
        self.name = stub.__name__
        self.__doc__ = stub.__doc__
        self.params = list(inspect.signature(stub).parameters)
        self.inline = inline
        # the implementation per record class as registered (a Python function), and the
        # helper compiled from it that compiled callers call (made at its first use)
        self.impls: dict[type, Any] = {}
        self._helpers: dict[type, Any] = {}
        _GENERICS.append(self)
        # The typing function must have the stub's own parameters (numba matches them by
        # name), so it is written out for this signature; the stub's call becomes a call of
        # the helper, through a wrapper that numba inlines (one call, cheap to inline).
        args = ", ".join(self.params)
        src = (
            f"def typer({args}):\n"
            f"    fn = helper_for(record_class({self.params[0]}))\n"
            f"    if fn is None:\n"
            f"        return None\n"
            f"    def impl({args}):\n"
            f"        return fn({args})\n"
            f"    return impl\n"
        )
        namespace: dict[str, Any] = {"helper_for": self._helper_for, "record_class": record_class}
        exec(src, namespace)  # a fixed template over the stub's parameter names
        overload_inlined(stub, namespace["typer"])

    def register(self, cls: type) -> Callable[[F], F]:
        """Decorator: ``fn`` implements this generic function for records of class ``cls``
        (its parameters in the declaration's order)."""

        def deco(fn: F) -> F:
            if cls in self.impls:
                raise TypeError(f"{self.name} is already defined for {cls.__name__}")
            self.impls[cls] = fn
            return fn

        return deco

    def _helper_for(self, cls: Any) -> Any:
        """The helper of ``cls``'s implementation (None if it has none), made at its first
        use: a dispatcher costs about 0.2 ms of every start, and a run uses few of them."""
        compiled = self._helpers.get(cls)
        if compiled is None and cls in self.impls:
            fn = self.impls[cls]
            # inlined: LLVM inlines it into every caller (inline_helper); else a call, a
            # helper that compiled code alone can call
            compiled = self._helpers[cls] = inline_helper(fn) if self.inline else helper(fn)
        return compiled

    def implementation(self, cls: type) -> Any:
        """The compiled implementation registered for ``cls``: callable from Python for an
        inlined generic function; for one declared ``inline=False`` a helper that only
        compiled code can call (:class:`CompiledOnly`)."""
        if cls not in self.impls:
            raise KeyError(f"{self.name} has no implementation for {cls.__name__}")
        return self._helper_for(cls)

    def py(self, *args: Any) -> Any:
        """Call from Python (tests, the SciPy reference backend): the implementation of the
        first argument's class, compiled (inlined generic functions only: one declared
        ``inline=False`` is a helper that only compiled code can call)."""
        return self.implementation(type(args[0]))(*args)

    def plain(self, *args: Any) -> Any:
        """Call from Python, run by the interpreter: the implementation of the first
        argument's class as written, not compiled. For generic functions whose value is a
        constant of the record class (:func:`~braidsim.core.interfaces.model_size`,
        :func:`~braidsim.core.interfaces.dissipation_index`), asked once per class before a
        run: the compiled call would first load one more library from numba's cache in every
        process, for a tuple of constants (a warm ``braidsim run`` took 0.96 times as long
        without it: 15 alternated pairs)."""
        return self.impls[type(args[0])](*args)


def generic(stub: Callable[..., Any] | None = None, *, inline: bool = True) -> Any:
    """Declare a generic function of the compiled core (see the module docstring).

    Each implementation is compiled once per argument types as an :func:`inline_helper`,
    which LLVM inlines into every caller, unless ``inline=False`` (then a :func:`helper`,
    which LLVM inlines only where its cost model finds it cheap): numba passes a record to
    a function it calls as one argument per field (the carrier's are about 65 with its
    tables), which cost more than the work of the small functions here. Measured on
    paper-3.3: 193 ns per right-hand-side evaluation with calls, 134 ns inlined. (Until
    2026-11-29 they were inlined as numba IR, typed and lowered again at every call site:
    the same machine code, and 0.7 s more of the 9.3-s cold compile of
    ``simulate("paper-3.3", series=False)``.) The solver's own helpers, which are called,
    get the model as a :class:`RecordRef` (:func:`by_ref`) instead.

    Returns the stub itself (compiled code resolves calls to it by name), carrying
    ``register``, ``implementation``, ``py`` and ``plain`` of its :class:`GenericFunction`."""
    if stub is None:
        return lambda s: generic(s, inline=inline)
    g = GenericFunction(stub, inline)
    stub.register = g.register  # type: ignore[attr-defined]
    stub.implementation = g.implementation  # type: ignore[attr-defined]
    stub.py = g.py  # type: ignore[attr-defined]
    stub.plain = g.plain  # type: ignore[attr-defined]
    stub.generic = g  # type: ignore[attr-defined]
    return stub
