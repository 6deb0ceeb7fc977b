"""Wait-map files: one ``.npz`` per map holding the arrays plus a ``meta.json`` entry.

``meta.json`` (UTF-8 JSON inside the archive) records ``format`` (:data:`FORMAT_VERSION`), the grid
(``Grid.to_dict``), every MDP parameter (``MdpParams.to_dict``, including the threshold preset, the
wait definition and the LoWC-probability floor ``p_min``),
the conditioning turn rate, solver statistics, and ``content_hash`` = SHA-256 over the metadata
(without the hash) and every array's dtype, shape and bytes. :func:`load` re-computes the hash, so
a corrupt, truncated or edited file fails with one-line :class:`~daa_sil.errors.FileFormatError`;
it also checks that the values are physical (``wait_s`` in [0, H] s, probabilities in [0, 1], no
NaN), so a file written by a buggy tool with a matching hash is still refused.
Writes are atomic (``daa_sil.files.atomic_path``). A family directory also has ``family.json``
listing its map files by turn rate.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from pathlib import Path

import numpy as np

from ..errors import FileFormatError, UsageError
from daa_sil.files import atomic_path, atomic_write_json, to_jsonable
from .grid import grid_from_dict
from .lookup import WaitMap, WaitMapFamily
from .model import MdpParams

FORMAT_VERSION = "daa-sil-waitmap/2"
ARRAYS = ("wait_s", "p_lowc", "t_lowc", "q_wait", "lowc")
FAMILY_INDEX = "family.json"
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


def load(path: "str | os.PathLike") -> WaitMap:
    """Read and verify one map file; raises FileFormatError naming the file on any problem."""
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
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
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
    if _content_hash(meta, data) != meta.get("content_hash"):
        raise FileFormatError(f"{path}: content hash mismatch (file corrupt or edited)")
    try:
        grid = grid_from_dict(meta["grid"])
        params = MdpParams.from_dict(meta["params"])
    except (KeyError, TypeError, UsageError) as exc:
        raise FileFormatError(f"{path}: bad metadata ({exc})") from None
    if any(data[n].shape != grid.shape for n in ARRAYS):
        raise FileFormatError(f"{path}: array shapes do not match the grid {grid.shape}")
    _check_values(path, data, params.horizon)
    return WaitMap(grid=grid, params=params, turn_rate_deg=float(meta["turn_rate_deg"]),
                   stats=meta.get("stats", {}), content_hash=meta["content_hash"],
                   **{n: data[n] for n in ARRAYS})


def _check_values(path: Path, data: dict, horizon: float) -> None:
    """Refuse maps whose values cannot be right (NaN, negative waits, probabilities outside [0, 1])."""
    for name, lo, hi in (("wait_s", 0.0, horizon), ("p_lowc", 0.0, 1.0), ("t_lowc", 0.0, horizon)):
        a = np.asarray(data[name])
        if a.dtype.kind != "f":
            raise FileFormatError(f"{path}: array {name} has dtype {a.dtype}, expected floating point")
        bad = ~((a >= lo - 1e-9) & (a <= hi + 1e-9))  # also catches NaN
        if bad.any():
            v = a[bad].flat[0]
            raise FileFormatError(f"{path}: {int(bad.sum())} values of {name} outside [{lo:g}, {hi:g}] "
                                  f"(e.g. {float(v)!r}); the map is invalid")
    if not np.isfinite(data["q_wait"]).all():
        raise FileFormatError(f"{path}: array q_wait has non-finite values; the map is invalid")
    if data["lowc"].dtype != np.bool_:
        raise FileFormatError(f"{path}: array lowc has dtype {data['lowc'].dtype}, expected bool")


def save_family(fam: WaitMapFamily, directory: "str | os.PathLike", overwrite: bool = False,
                family_hash: str = "") -> list[Path]:
    """Write every map plus ``family.json`` into ``directory``; returns the map paths."""
    d = Path(directory)
    names = [map_filename(m.turn_rate_deg) for m in fam.maps]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise UsageError(f"two maps of the family would share the file name {dup}; turn rates must differ "
                         f"by at least 0.1 deg/s")
    targets = [d / n for n in names] + [d / FAMILY_INDEX]
    if not overwrite:
        clash = [p for p in targets if p.exists()]
        if clash:
            from ..errors import OutputError

            raise OutputError(f"{clash[0]} exists; refusing to overwrite (use --force or another --out)")
    paths = [save(m, d / map_filename(m.turn_rate_deg), overwrite=True) for m in fam.maps]
    atomic_write_json(d / FAMILY_INDEX, {"format": FORMAT_VERSION, "family_hash": family_hash,
                                         "maps": [{"turn_rate_deg": m.turn_rate_deg, "file": p.name,
                                                   "content_hash": m.content_hash}
                                                  for m, p in zip(fam.maps, paths)]})
    return paths


def load_family(directory: "str | os.PathLike") -> WaitMapFamily:
    """Load a family directory (``family.json`` if present, else every ``waitmap_turn*.npz``)."""
    d = Path(directory)
    if not d.is_dir():
        raise UsageError(f"wait-map family directory {d} does not exist")
    idx = d / FAMILY_INDEX
    if idx.is_file():
        try:
            info = json.loads(idx.read_text())
            files = [d / e["file"] for e in info["maps"]]
        except (ValueError, KeyError, TypeError):
            raise FileFormatError(f"{idx}: not a valid wait-map family index") from None
    else:
        files = sorted(d.glob("waitmap_turn*.npz"))
    if not files:
        raise FileFormatError(f"{d}: no wait maps found")
    maps = sorted((load(f) for f in files), key=lambda m: m.turn_rate_deg)
    g0 = maps[0].grid.to_dict()["axes"]
    if any(m.grid.to_dict()["axes"] != g0 for m in maps):
        raise FileFormatError(f"{d}: maps on different grids cannot form one family")
    return WaitMapFamily(maps)

