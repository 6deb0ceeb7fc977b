"""Wait-map files: one ``.npz`` per map holding the arrays plus a ``meta.json`` entry.

``meta.json`` (UTF-8 JSON inside the archive) records ``format`` (:data:`FORMAT_VERSION`), the grid
(``Grid.to_dict``), every MDP parameter (``MdpParams.to_dict``, including the threshold preset, the
wait definition and the LoWC-probability floor ``p_min``),
the conditioning turn rate, solver statistics, and ``content_hash`` = SHA-256 over the metadata
(without the hash) and every array's dtype, shape and bytes. :func:`load` re-computes the hash, so
a corrupt, truncated or edited file fails with one-line :class:`~daa_sil.errors.FileFormatError`;
it also checks that the values are physical (``wait_s`` in [0, H] s, probabilities in [0, 1], no
NaN), so a file written by a buggy tool with a matching hash is still refused.
Writes are atomic (``daa_sil.files.atomic_path``).

A family of maps (one directory with its index) is :mod:`daa_sil.waitmap.family_files`.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import zipfile
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, UsageError
from daa_sil.files import atomic_path, to_jsonable
from .grid import grid_from_dict
from .lookup import FIELDS, WaitMap
from .model import FORMAT_VERSION, MdpParams

ARRAYS = ("wait_s", "p_lowc", "t_lowc", "q_wait", "lowc")
#: first bytes of a zip archive (an .npz is one); anything else is not a wait map
_ZIP_MAGIC = b"PK\x03\x04"


def _content_hash(meta: dict, arrays: dict) -> str:
    h = hashlib.sha256()
    m = {k: v for k, v in meta.items() if k != "content_hash"}
    h.update(json.dumps(to_jsonable(m), sort_keys=True).encode())
    for name in ARRAYS:
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _meta(wm: WaitMap) -> dict:
    return {"format": FORMAT_VERSION, "grid": wm.grid.to_dict(), "params": wm.params.to_dict(),
            "preset": wm.params.preset, "wait_definition": wm.params.wait_definition, "p_min": wm.params.p_min,
            "turn_rate_deg": float(wm.turn_rate_deg), "stats": wm.stats,
            "arrays": list(ARRAYS), "units": {"wait_s": "s", "p_lowc": "1", "t_lowc": "s",
                                               "q_wait": "reward", "lowc": "bool"}}


def map_filename(turn_rate_deg: float) -> str:
    """File name of the map for one conditioning turn rate, e.g. ``waitmap_turn+2.5.npz``."""
    r = round(float(turn_rate_deg), 1) + 0.0  # + 0.0 turns -0.0 into 0.0: one file for "zero"
    return f"waitmap_turn{r:+.1f}.npz"


def save(wm: WaitMap, path: "str | os.PathLike", overwrite: bool = False) -> Path:
    """Write one map atomically; returns the path. Sets ``wm.content_hash``."""
    arrays = {n: np.ascontiguousarray(getattr(wm, n)) for n in ARRAYS}
    meta = _meta(wm)
    meta["content_hash"] = wm.content_hash = _content_hash(meta, arrays)
    path = Path(path)
    with atomic_path(path, overwrite=overwrite) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, meta_json=np.array(json.dumps(to_jsonable(meta), sort_keys=True)), **arrays)
    return path


def load(path: "str | os.PathLike", expected_hash: "str | None" = None) -> WaitMap:
    """Read and verify one map file; raises FileFormatError naming the file on any problem.

    Without ``expected_hash`` the SHA-256 content hash is recomputed over the metadata and every
    array. With it (the hash a checked family index records for this file), the file must declare
    that hash, and its bytes are verified by the CRC-32 the zip format keeps for every member
    (checked by :mod:`zipfile` as each array is read to its end) instead of re-hashing."""
    path = Path(path)
    if not path.is_file():
        raise UsageError(f"wait map {path} does not exist")
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read wait map: {exc.strerror or exc}") from None
    if head != _ZIP_MAGIC:
        what = "empty file" if not head else "not a zip archive"
        raise FileFormatError(f"{path}: not a daa-sil wait map ({what}; expected an .npz written by "
                              f"'daa-sil waitmap build')")
    try:
        data, extrema = read_arrays(path)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as exc:
        raise FileFormatError(f"{path}: not a readable wait-map .npz ({type(exc).__name__}: "
                              f"{str(exc).splitlines()[0] if str(exc) else 'corrupt'})") from None
    if "meta_json" not in data:
        raise FileFormatError(f"{path}: no meta_json entry; not a daa-sil wait map")
    try:
        meta = json.loads(str(data["meta_json"]))
    except ValueError:
        raise FileFormatError(f"{path}: metadata is not valid JSON") from None
    fmt = meta.get("format") if isinstance(meta, dict) else None
    if fmt != FORMAT_VERSION:
        hint = " (rebuild it with 'daa-sil waitmap build')" if str(fmt).startswith("daa-sil-waitmap/") else ""
        raise FileFormatError(f"{path}: unsupported wait-map format {fmt!r}; this version reads {FORMAT_VERSION!r}{hint}")
    missing = [n for n in ARRAYS if n not in data]
    if missing:
        raise FileFormatError(f"{path}: missing arrays {missing}")
    if expected_hash is not None:
        if meta.get("content_hash") != expected_hash:
            raise FileFormatError(f"{path}: content hash {str(meta.get('content_hash'))[:12]}... is not the "
                                  f"{expected_hash[:12]}... its family index records")
    elif _content_hash(meta, data) != meta.get("content_hash"):
        raise FileFormatError(f"{path}: content hash mismatch (file corrupt or edited)")
    try:
        grid = grid_from_dict(meta["grid"])
        params = MdpParams.from_dict(meta["params"])
    except (KeyError, TypeError, UsageError) as exc:
        raise FileFormatError(f"{path}: bad metadata ({exc})") from None
    if any(data[n].shape != grid.shape for n in ARRAYS):
        raise FileFormatError(f"{path}: array shapes do not match the grid {grid.shape}")
    _check_values(path, data, params.horizon, extrema)
    return WaitMap(grid=grid, params=params, turn_rate_deg=float(meta["turn_rate_deg"]),
                   stats=meta.get("stats", {}), content_hash=meta["content_hash"],
                   **{n: data[n] for n in ARRAYS})


#: bytes of each member read at a time by :func:`read_arrays` (a multiple of every dtype's size)
READ_CHUNK = 1 << 18


def read_arrays(path: "str | os.PathLike") -> tuple[dict, dict]:
    """``(arrays, extrema)``: every array of an ``.npz`` as ``np.load`` gives it, with each zip member's
    CRC-32 checked, and ``{name: (min, max)}`` of the arrays read side by side (NaN if any is NaN).

    The interpolated fields (:data:`daa_sil.waitmap.lookup.FIELDS`), when all are float32 in C order
    and of one shape (as ``save`` writes them), are read chunk by chunk straight into one
    ``shape + (4,)`` float32 array, the layout :class:`WaitMap` keeps them in, and returned as its
    views: no second copy of the largest arrays (93 MB for the SIL's default family), one write pass
    over them, and their extrema taken from the chunks while they are in cache (the value checks then
    need no pass of their own). Anything else is read by numpy as it stands. Raises what ``np.load``
    raises on a bad file (ValueError, OSError, EOFError, BadZipFile)."""
    with zipfile.ZipFile(path) as zf:
        members = {i.filename[:-4]: i for i in zf.infolist() if i.filename.endswith(".npy")}
        data: dict = {}
        extrema: dict = {}
        if all(n in members for n in FIELDS):
            got = _read_side_by_side(zf, [members[n] for n in FIELDS])
            if got is not None:
                fields, lo, hi = got
                data.update({n: fields[..., i] for i, n in enumerate(FIELDS)})
                extrema.update({n: (lo[i], hi[i]) for i, n in enumerate(FIELDS)})
        for name, info in members.items():
            if name not in data:
                with zf.open(info) as fh:
                    array_header(fh, info)
                with zf.open(info) as fh:
                    data[name] = np.lib.format.read_array(fh, allow_pickle=False)
                    fh.read()  # to the member's end: zipfile checks its CRC-32 there
    return data, extrema


def array_header(fh, info: zipfile.ZipInfo) -> "tuple | None":
    """``(shape, fortran_order, dtype)`` of the ``.npy`` member ``info`` open as ``fh``, left at the start
    of its data; None for a format version other than 1.0 and 2.0. ValueError if the header claims more
    data than the member holds: a forged shape must not make the reader allocate it."""
    version = np.lib.format.read_magic(fh)
    read = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}.get(version)
    if read is None:
        return None
    shape, fortran, dtype = read(fh)
    if dtype.itemsize * math.prod(shape) > info.file_size - fh.tell():
        raise ValueError(f"{info.filename}: its array header claims {shape} of {dtype}, more than it holds")
    return shape, fortran, dtype


def _read_side_by_side(zf: zipfile.ZipFile, infos: list) -> "tuple[np.ndarray, list, list] | None":
    """Members ``infos`` (float32 arrays of one shape, C order) interleaved into one ``shape + (k,)``
    float32 array, with each member's min and max (float32; NaN if it has a NaN); None (nothing read
    into it) if they are not such arrays."""
    handles = [zf.open(i) for i in infos]
    try:
        shapes = []
        for info, fh in zip(infos, handles):
            header = array_header(fh, info)
            if header is None:
                return None
            shape, fortran, dtype = header
            if fortran or dtype != np.dtype("<f4") or (shapes and shape != shapes[0]):
                return None
            shapes.append(shape)
        shape = shapes[0]
        out = np.empty(tuple(shape) + (len(infos),), np.float32)
        flat = out.reshape(-1, len(infos))
        count = flat.shape[0]
        lo, hi = [np.float32(np.inf)] * len(infos), [np.float32(-np.inf)] * len(infos)
        step = READ_CHUNK // 4
        for j in range(0, count, step):
            k = min(step, count - j)
            for i, fh in enumerate(handles):
                chunk = fh.read(4 * k)
                if len(chunk) != 4 * k:
                    raise EOFError(f"{infos[i].filename}: array data ends early")
                v = np.frombuffer(chunk, np.float32)
                flat[j:j + k, i] = v
                lo[i], hi[i] = np.minimum(lo[i], v.min()), np.maximum(hi[i], v.max())  # (both propagate NaN)
        for fh in handles:
            fh.read()  # to the member's end: zipfile checks its CRC-32 there
        return out, lo, hi
    finally:
        for fh in handles:
            fh.close()


def _check_values(path: Path, data: dict, horizon: float, extrema: "dict | None" = None) -> None:
    """Refuse maps whose values cannot be right (NaN, negative waits, probabilities outside [0, 1]).
    ``extrema``: ``{name: (min, max)}`` of arrays already known (:func:`read_arrays`): an array whose
    extrema pass is not read again; the rule is the same, compared in the array's own dtype."""
    extrema = extrema or {}
    for name, lo, hi in (("wait_s", 0.0, horizon), ("p_lowc", 0.0, 1.0), ("t_lowc", 0.0, horizon)):
        a = np.asarray(data[name])
        if a.dtype.kind != "f":
            raise FileFormatError(f"{path}: array {name} has dtype {a.dtype}, expected floating point")
        if name in extrema and a.size:
            mn, mx = extrema[name]
            t = a.dtype.type  # (the bounds rounded to a's dtype, as the array comparison below rounds them)
            if bool(mn >= t(lo - 1e-9)) and bool(mx <= t(hi + 1e-9)):  # (False for a NaN)
                continue
        bad = ~((a >= lo - 1e-9) & (a <= hi + 1e-9))  # also catches NaN
        if bad.any():
            v = a[bad].flat[0]
            raise FileFormatError(f"{path}: {int(bad.sum())} values of {name} outside [{lo:g}, {hi:g}] "
                                  f"(e.g. {float(v)!r}); the map is invalid")
    q = extrema.get("q_wait")
    if not (q is not None and data["q_wait"].size and np.isfinite(q[0]) and np.isfinite(q[1])) \
            and not np.isfinite(data["q_wait"]).all():
        raise FileFormatError(f"{path}: array q_wait has non-finite values; the map is invalid")
    if data["lowc"].dtype != np.bool_:
        raise FileFormatError(f"{path}: array lowc has dtype {data['lowc'].dtype}, expected bool")


def read_meta(path: "str | os.PathLike") -> dict:
    """The ``meta_json`` entry of a map file, read without its arrays (the zip directory and one small
    member, CRC-checked). FileFormatError if the file is not a wait map."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as zf, zf.open("meta_json.npy") as fh:
            meta = json.loads(str(np.lib.format.read_array(fh, allow_pickle=False)))
    except FileNotFoundError:
        raise FileFormatError(f"{path}: the wait map is missing") from None
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise FileFormatError(f"{path}: not a readable wait-map .npz ({type(exc).__name__}: "
                              f"{str(exc).splitlines()[0] if str(exc) else 'corrupt'})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_VERSION:
        raise FileFormatError(f"{path}: not a {FORMAT_VERSION} wait map")
    return meta
