"""Compiled fit programs kept on disk, so that a new process skips tracing them too.

JAX's persistent compilation cache (:mod:`~appearance_jax.core.compile_cache`) saves a re-run the
XLA compile, but it finds its entry by the program's StableHLO, so every process still traces
and lowers the fit's solve (model, Jacobian, LM loop and covariances) before it can look: on the
README's fit that is ~0.9 s of a ~4 s warm run. This store keeps the *loaded* executable under a
key made of what the program was traced from: the caller's content key (model name, parameter
template, free fields, metric, solver settings: :func:`~appearance_jax.fit.solve.reuse.disk_key`),
the argument shapes and dtypes, and a fingerprint of everything else a trace can depend on
(:func:`environment`): this package's files (source and data), the jax, jaxlib, numpy and
Python versions, the JAX settings that change a trace, ``XLA_FLAGS`` and the CPU. A change to any
of them is a new key; an entry is never looked up by anything weaker.

The key sees this package's files, not its objects: a function replaced at run time (a test's
monkeypatch) is invisible to it, so such code must turn the store off (below).

It is on exactly when this package's compilation cache is (same switches: ``--no-compile-cache``,
``APPEARANCE_JAX_COMPILE_CACHE=off``, :func:`~appearance_jax.core.compile_cache.disable`), in the
directory ``programs`` inside it (``~/.cache/appearance-jax/xla/programs``); a cache directory
configured for JAX itself leaves it off. Deleting the directory is always safe.

Trust: like JAX's cache, an entry is machine code that runs in this process (and its envelope is a
pickle, as in :mod:`jax.experimental.serialize_executable`), so the directory must be as trusted
as the Python environment. Entries are read only from a directory and files owned by this user
and not writable by others, and only up to :data:`MAX_ENTRY_BYTES`. An entry that fails to load
is deleted and the program compiled as usual.

Only programs whose custom calls are LAPACK's are written: XLA:CPU binds a custom call by name
when the program runs, and LAPACK's kernels are set up lazily by JAX the first time a program
using them is lowered (:func:`_prepare`). A program with a host callback (a progress printer)
points into the process that traced it and is never written.
"""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import platform
import re
import stat
import sys
from pathlib import Path

import jax
import numpy as np

from . import compile_cache

__all__ = ["MAX_ENTRY_BYTES", "MAX_BYTES", "directory", "environment", "entry_name", "load", "save", "stats"]

#: entries larger than this [bytes] are neither written nor read
MAX_ENTRY_BYTES = 512 * 1024**2
#: the store's size limit [bytes]: writing an entry removes the least recently used beyond it
MAX_BYTES = 1024**3
#: custom-call targets a stored program may contain (by prefix)
_SAFE_TARGETS = ("lapack_",)
#: JAX settings a trace depends on beyond the arguments (x64, precision, PRNG, promotion rules)
_JAX_SETTINGS = ("jax_enable_x64", "jax_default_matmul_precision", "jax_default_prng_impl",
                 "jax_threefry_partitionable", "jax_numpy_rank_promotion", "jax_numpy_dtype_promotion",
                 "jax_default_device", "jax_platforms", "jax_enable_checks")
_FORMAT = 1
_state: dict = {"env": None, "lapack": False}
_stats = {"loaded": 0, "saved": 0, "rejected": 0}


def stats() -> dict:
    """Counts in this process: entries ``loaded``, ``saved`` and ``rejected`` (failed to load)."""
    return dict(_stats)


def directory() -> Path | None:
    """Where entries live now: ``programs`` inside this package's compilation cache directory
    (JAX's cache reads and evicts only its own ``*-cache`` files there), or None while that cache
    is off or is a directory configured for JAX itself."""
    own = compile_cache.own_dir()
    return None if own is None else Path(own) / "programs"


def _package_digest() -> str:
    h = hashlib.sha256()
    root = Path(__file__).resolve().parents[1]
    for p in sorted(root.rglob("*")):
        if p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".pyo"):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo", "rb") as f:
            text = f.read(1 << 20).decode("ascii", "replace")
        flags = next((line for line in text.splitlines() if line.startswith("flags")), "")
        return hashlib.sha256(flags.encode()).hexdigest()
    except OSError:
        return platform.processor()


def environment() -> str:
    """A fingerprint of what a trace and its executable depend on besides the caller's key and
    the arguments (module docstring); computed once per process (~20 ms: it hashes the package)."""
    if _state["env"] is None:
        import jaxlib

        dev = jax.devices()[0]
        parts = (_FORMAT, _package_digest(), jax.__version__, jaxlib.__version__, np.__version__,
                 sys.version_info[:2], platform.machine(), _cpu(), dev.platform, dev.device_kind,
                 dev.client.platform_version, len(jax.devices()), os.environ.get("XLA_FLAGS", ""))
        _state["env"] = hashlib.sha256(repr(parts).encode()).hexdigest()
    settings = tuple(str(getattr(jax.config, s, None)) for s in _JAX_SETTINGS)
    return hashlib.sha256(repr((_state["env"], settings, jax.default_backend())).encode()).hexdigest()


def _encode(obj, out: list) -> None:
    """Append an unambiguous encoding of ``obj`` to ``out``; TypeError for what has none."""
    if obj is None or isinstance(obj, (bool, int, float, str, bytes, complex)):
        out.append(f"{type(obj).__name__}:{obj!r};")
    elif isinstance(obj, (tuple, list)):
        out.append(f"{type(obj).__name__}[{len(obj)}](")
        for v in obj:
            _encode(v, out)
        out.append(")")
    elif isinstance(obj, dict):
        out.append(f"dict[{len(obj)}](")
        for k in sorted(obj, key=repr):
            _encode(k, out)
            _encode(obj[k], out)
        out.append(")")
    elif isinstance(obj, (np.ndarray, np.generic, jax.Array)):
        a = np.asarray(obj)
        out.append(f"array:{a.dtype.str}:{a.shape}:{hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()};")
    elif isinstance(obj, jax.tree_util.PyTreeDef):
        text = repr(obj)
        if "..." in text or " at 0x" in text:  # a summarised array or an address: not a faithful key
            raise TypeError(f"no faithful key for {text[:80]}")
        out.append(f"treedef:{text};")
    elif hasattr(obj, "__dataclass_fields__") and getattr(type(obj), "__dataclass_params__").frozen:
        out.append(f"{type(obj).__module__}.{type(obj).__qualname__}(")
        for name in obj.__dataclass_fields__:
            out.append(f"{name}=")
            _encode(getattr(obj, name), out)
        out.append(")")
    else:
        raise TypeError(f"no key for a {type(obj).__name__}")


def entry_name(tag: str, key, args) -> str | None:
    """The entry's file name for program ``tag`` traced from content ``key`` with ``args``, or
    None when something in them has no faithful encoding (then nothing is stored)."""
    leaves, treedef = jax.tree_util.tree_flatten(args)
    out: list = [environment(), tag]
    try:
        _encode(key, out)
        _encode(treedef, out)
        for v in leaves:
            out.append(f"{np.dtype(v.dtype).str}{tuple(np.shape(v))}{getattr(v, 'weak_type', False)};")
    except TypeError:
        return None
    return f"{tag}-{hashlib.sha256(''.join(out).encode()).hexdigest()[:40]}.jaxprog"


def _private(path: Path) -> bool:
    """Owned by this user and not writable by group or others (POSIX; elsewhere: true)."""
    if not hasattr(os, "getuid"):
        return True
    st = path.stat()
    return st.st_uid == os.getuid() and not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def _prepare(targets) -> None:
    # JAX points its LAPACK custom calls at scipy's kernels when it first lowers a program that
    # uses one; a stored program skips that lowering (run without it, the call jumps to nothing).
    # JAX's own set-up function when it has one (microseconds), else lower a tiny program that
    # uses LAPACK (0.2 s: the first lowering of a process builds MLIR's context)
    if not _state["lapack"] and any(t.startswith("lapack_") for t in targets):
        try:
            from jax._src.lax import linalg

            linalg.initialize_lapack()
        except Exception:  # noqa: BLE001 - a jax without it: the public way
            jax.jit(jax.lax.linalg.cholesky).lower(np.eye(2, dtype=np.float32))
        _state["lapack"] = True


def load(name: str | None, args):
    """The stored program ``name`` (:func:`entry_name`) as a :class:`jax.stages.Compiled`, or None."""
    folder = directory()
    if name is None or folder is None:
        return None
    path = folder / name
    try:
        if not path.is_file():
            return None
        if not (_private(folder) and _private(path)) or path.stat().st_size > MAX_ENTRY_BYTES:
            return None
        with open(path, "rb") as f:
            fmt, targets, payload, out_tree = pickle.load(f)
        if fmt != _FORMAT:
            raise ValueError(f"format {fmt}")
        _prepare(targets)
        from jax.experimental import serialize_executable

        compiled = serialize_executable.deserialize_and_load(payload, jax.tree_util.tree_structure((tuple(args), {})),
                                                            out_tree)
    except Exception:  # noqa: BLE001 - any failure: compile as usual, and do not try this entry again
        _stats["rejected"] += 1
        try:
            path.unlink()
        except OSError:
            pass
        return None
    try:
        os.utime(path)  # its modification time is its last use (eviction order)
    except OSError:
        pass
    _stats["loaded"] += 1
    return compiled


def _evict(folder: Path) -> None:
    entries = []
    for p in folder.glob("*.jaxprog"):
        try:
            st = p.stat()
        except OSError:  # removed by another process meanwhile
            continue
        entries.append((st.st_mtime, st.st_size, p))
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries, key=lambda e: e[0]):
        if total <= MAX_BYTES:
            break
        try:
            p.unlink()
        except OSError:
            pass
        total -= size


def save(name: str | None, compiled) -> bool:
    """Write ``compiled`` as entry ``name``; False (nothing written) when the store is off, the
    program calls out to anything but LAPACK, or it cannot be serialised or written."""
    folder = directory()
    if name is None or folder is None:
        return False
    try:
        targets = sorted(set(re.findall(r'custom_call_target="([^"]+)"', compiled.as_text())))
        if not all(t.startswith(_SAFE_TARGETS) for t in targets):
            return False
        from jax.experimental import serialize_executable

        payload, _, out_tree = serialize_executable.serialize(compiled)
        buf = io.BytesIO()
        pickle.dump((_FORMAT, targets, payload, out_tree), buf, protocol=pickle.HIGHEST_PROTOCOL)
        if buf.tell() > MAX_ENTRY_BYTES:
            return False
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
        tmp = folder / f".{name}.{os.getpid()}.tmp"
        try:
            with open(tmp, "wb") as f:
                f.write(buf.getvalue())
            os.replace(tmp, folder / name)  # atomic: a reader sees the whole entry or none
        finally:
            tmp.unlink(missing_ok=True)  # a failed write (disk full) leaves no partial file
        _evict(folder)
    except Exception:  # noqa: BLE001 - a program that cannot be stored is compiled next time
        return False
    _stats["saved"] += 1
    return True
