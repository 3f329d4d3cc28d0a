"""Provenance: what a result was made from, so that it is never reused for anything else.

In: a :class:`~volec.capture.Capture`, a config dataclass, the records of upstream stages,
the names of the volec modules that compute a result, files. Out: JSON-able records and short
digests, and :func:`differences`, which names what differs between a recorded provenance and
the one a run wants (an empty list: the result may be reused).

A stage record (``sfm/summary.json``, ``dense.json``, ``masking.json``, ``result.json``)
carries a ``provenance`` entry made by :func:`stage_provenance`:

- ``capture``: the capture's identity (:func:`capture_identity`): every frame's name, image
  size and a digest of its image and mask bytes, digests of the poses and intrinsics, and
  whether the poses are metric;
- ``upstream``: the digest of each upstream stage's record (:func:`record_digest`);
- ``config``: the stage's config;
- ``volec_version`` and ``source_digest``: the package version and a digest of the source of
  the modules that compute the stage (the module and every volec module it imports, directly or
  not), so a code change makes a different record and cached numbers are recomputed.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import json
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from volec import __version__

if TYPE_CHECKING:
    from volec.capture import Capture

DIGEST_CHARS = 16
"""Hex characters kept of a sha256 (64 bits: collisions are no concern here)."""


def bytes_digest(data: bytes) -> str:
    """Short sha256 hex digest of ``data``."""
    return hashlib.sha256(data).hexdigest()[:DIGEST_CHARS]


def file_digest(path: Path) -> str:
    """Short sha256 hex digest of a file's bytes (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:DIGEST_CHARS]


def json_data(value: Any) -> Any:
    """``value`` (a dataclass, dict, list, numpy value...) as plain JSON data, the way it
    reads back from a file (tuples become lists)."""
    if is_dataclass(value) and not isinstance(value, type):
        value = asdict(value)
    return json.loads(json.dumps(value, default=_plain))


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON data")


def record_digest(record: dict[str, Any]) -> str:
    """Digest of a record's JSON content (key order does not matter)."""
    return bytes_digest(json.dumps(json_data(record), sort_keys=True).encode())


# ----------------------------------------------------------------------------- source


_PACKAGE_ROOT = Path(__file__).resolve().parent


def _module_file(name: str) -> Path | None:
    """The source file of the volec module ``name`` (found on disk, nothing is imported), or
    None when ``name`` is not a volec module (e.g. a class imported from one)."""
    parts = name.split(".")
    if parts[0] != "volec":
        return None
    base = _PACKAGE_ROOT.joinpath(*parts[1:])
    for path in (base / "__init__.py", base.with_suffix(".py")):
        if path.is_file():
            return path
    return None


def _imported_volec_modules(name: str, path: Path) -> set[str]:
    """The volec modules that the module ``name`` (at ``path``) imports anywhere in its code
    (lazy imports inside functions included), and the packages that hold them."""
    found: set[str] = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == "volec"}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parent = ".".join(parts[: len(parts) - node.level + 1])
                base = f"{parent}.{base}" if base else parent
            if base.split(".")[0] != "volec":
                continue
            found.add(base)
            # ``from volec.synth import generate`` imports a module, not a name
            found |= {f"{base}.{a.name}" for a in node.names
                      if _module_file(f"{base}.{a.name}") is not None}
    with_parents = set(found)
    for module in found:
        parts = module.split(".")
        with_parents |= {".".join(parts[:i]) for i in range(1, len(parts))}
    return with_parents


@functools.cache
def module_closure(name: str) -> tuple[str, ...]:
    """``name`` and every volec module it imports, directly or through others, sorted."""
    seen: set[str] = set()
    todo = [name]
    while todo:
        module = todo.pop()
        if module in seen:
            continue
        path = _module_file(module)
        if path is None or path.suffix != ".py":
            continue
        seen.add(module)
        todo.extend(_imported_volec_modules(module, path) - seen)
    return tuple(sorted(seen))


@functools.cache
def source_digest(*modules: str) -> str:
    """Digest of the code of ``modules`` and of every volec module they import: it changes
    whenever code that can change their results changes (not when only docstrings or comments
    do)."""
    h = hashlib.sha256()
    closure = sorted({m for name in modules for m in module_closure(name)})
    if not closure:
        raise ValueError(f"no source found for {modules}")
    for module in closure:
        h.update(module.encode() + b"\0" + _code_of(_module_file(module)) + b"\0")
    return h.hexdigest()[:DIGEST_CHARS]


def _code_of(path: Path) -> bytes:
    """What in a source file can change results: its syntax tree without prose (comments are
    not in it; every statement that is only a string is dropped: docstrings of modules,
    classes and functions, and those under a dataclass's fields), so editing prose does not
    invalidate cached results."""
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        for field in ("body", "orelse", "finalbody"):
            body = getattr(node, field, None)
            if not isinstance(body, list) or not body or not isinstance(body[0], ast.stmt):
                continue
            kept = [s for s in body if not _is_prose(s)]
            setattr(node, field, kept or [ast.Pass()])
    return ast.dump(tree).encode()


def _is_prose(statement: ast.stmt) -> bool:
    """True for a statement that is only a string literal (it does nothing)."""
    return (isinstance(statement, ast.Expr) and isinstance(statement.value, ast.Constant)
            and isinstance(statement.value.value, str))


def module_digest(name: str) -> str:
    """Digest of one module's code alone (not of what it imports; docstrings and comments
    left out, as in :func:`source_digest`)."""
    path = _module_file(name)
    if path is None:
        raise ValueError(f"no source found for {name}")
    return bytes_digest(_code_of(path))


@functools.cache
def package_digest() -> str:
    """Digest of every source file of the volec package: the state of the code as a whole."""
    h = hashlib.sha256()
    for path in sorted(_PACKAGE_ROOT.rglob("*.py")):
        h.update(path.relative_to(_PACKAGE_ROOT).as_posix().encode() + b"\0" + path.read_bytes())
    return h.hexdigest()[:DIGEST_CHARS]


def code_identity(*modules: str) -> dict[str, str]:
    """``{"volec_version", "source_digest"}`` for results computed by ``modules``."""
    return {"volec_version": __version__, "source_digest": source_digest(*modules)}


# ----------------------------------------------------------------------------- capture


def capture_identity(capture: Capture) -> dict[str, Any]:
    """What makes a capture this capture: per frame its name, image size, and digests of its
    image and mask files; digests of all poses, of when the frames were taken
    (:attr:`~volec.capture.Capture.elapsed_shares`, which the AR drift model weighs) and of all
    intrinsics; whether it is metric; and one ``digest`` over all of it. Where the capture was
    read from (``root``) is recorded but is not part of its identity: a moved capture is the
    same capture."""
    frames = []
    for f in capture.frames:
        image = f.content_digest or file_digest(f.image_path)
        mask = None
        if f.mask_path is not None:
            mask = f.mask_digest or file_digest(f.mask_path)
        frames.append({"name": f.name, "size": [f.intrinsics.width, f.intrinsics.height],
                       "image": image, "mask": mask})
    poses = np.stack([f.T_world_from_cam for f in capture.frames]).astype(np.float64)
    intrinsics = [json_data(f.intrinsics) for f in capture.frames]
    identity = {
        "frames": frames,
        "poses": bytes_digest(np.ascontiguousarray(poses).tobytes()),
        "times": bytes_digest(np.ascontiguousarray(capture.elapsed_shares).tobytes()),
        "intrinsics": record_digest({"all": intrinsics}),
        "metric": capture.metric,
        "metres_per_unit": capture.metres_per_unit,
    }
    identity["digest"] = record_digest(identity)
    identity["root"] = str(capture.root)
    return identity


def _capture_differences(recorded: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    if recorded.get("digest") == wanted.get("digest"):
        return []
    old = {f["name"]: f for f in recorded.get("frames", [])}
    new = {f["name"]: f for f in wanted.get("frames", [])}
    if list(old) != list(new):
        gone, added = sorted(set(old) - set(new)), sorted(set(new) - set(old))
        detail = [f"{len(old)} frames recorded, {len(new)} now"]
        if gone:
            detail.append(f"not in this capture: {_first(gone)}")
        if added:
            detail.append(f"new: {_first(added)}")
        if not gone and not added:
            detail.append("the same frames in another order")
        return [f"another capture: the frames differ ({'; '.join(detail)})"]
    out = []
    for key, what in (("image", "images"), ("mask", "masks"), ("size", "image sizes")):
        changed = [name for name in new if old[name].get(key) != new[name].get(key)]
        if changed:
            out.append(f"the {what} of {len(changed)} frames differ ({_first(changed)})")
    if recorded.get("poses") != wanted.get("poses"):
        out.append("the camera poses differ")
    if recorded.get("times") != wanted.get("times"):
        out.append("the frames' times in the recording differ")
    if recorded.get("intrinsics") != wanted.get("intrinsics"):
        out.append("the camera intrinsics differ")
    for key in ("metric", "metres_per_unit"):
        if recorded.get(key) != wanted.get(key):
            out.append(f"the capture's scale differs ({key} {recorded.get(key)} recorded, "
                       f"{wanted.get(key)} now)")
    return out or ["another capture (its identity digest differs)"]


def _first(names: list[str], n: int = 3) -> str:
    return ", ".join(names[:n]) + (f" and {len(names) - n} more" if len(names) > n else "")


# ----------------------------------------------------------------------------- records

#: What each upstream digest of a record stands for, in messages.
UPSTREAM_NAMES = {"sfm": "SfM result", "dense": "dense cloud", "masking": "masked cloud",
                  "checkpoint": "completion checkpoint"}


def stage_provenance(capture: Capture | dict[str, Any], cfg: Any,
                     upstream: dict[str, str], modules: tuple[str, ...]) -> dict[str, Any]:
    """The ``provenance`` entry of a stage record: the capture's identity (or the identity
    itself, when already computed), the upstream records' digests, the config and the code."""
    identity = capture if isinstance(capture, dict) else capture_identity(capture)
    return {"capture": identity, "upstream": dict(upstream), "config": json_data(cfg),
            **code_identity(*modules)}


def differences(recorded: dict[str, Any] | None, wanted: dict[str, Any]) -> list[str]:
    """What differs between a recorded provenance and the wanted one, in words; empty when
    a result with ``recorded`` provenance is what ``wanted`` would compute."""
    if not recorded:
        return ["it records no provenance (made by an older volec)"]
    out = _capture_differences(recorded.get("capture") or {}, wanted["capture"])
    for stage, digest in wanted["upstream"].items():
        if recorded.get("upstream", {}).get(stage) != digest:
            out.append(f"it was made from another {UPSTREAM_NAMES.get(stage, stage)}")
    old_cfg, new_cfg = recorded.get("config") or {}, wanted["config"]
    changed = sorted(k for k in set(old_cfg) | set(new_cfg) if old_cfg.get(k) != new_cfg.get(k))
    if changed:
        out.append(f"other settings ({', '.join(changed)} differ)")
    if recorded.get("volec_version") != wanted["volec_version"]:
        out.append(f"another volec version ({recorded.get('volec_version')} recorded, "
                   f"{wanted['volec_version']} now)")
    elif recorded.get("source_digest") != wanted["source_digest"]:
        out.append("volec's code has changed since (source digest "
                   f"{recorded.get('source_digest')} recorded, {wanted['source_digest']} now)")
    return out


def file_problems(record: dict[str, Any], folder: Path, record_name: str) -> list[str]:
    """The files a record lists (``files``: name -> digest, relative to ``folder``) that are
    missing or were changed after the record was written."""
    out = []
    for name, digest in (record.get("files") or {}).items():
        path = Path(folder) / name
        if not path.is_file():
            out.append(f"{name} is missing")
        elif file_digest(path) != digest:
            out.append(f"{name} was changed after {record_name} was written")
    if "files" not in record:
        out.append(f"{record_name} lists no files (made by an older volec)")
    return out
